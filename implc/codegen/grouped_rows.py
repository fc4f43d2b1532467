"""``implc_arrange_groups``: rows laid out by group as ``implc_tape_grouped`` reads them.

Given each row's group label (``labels``, each below ``bound``; ``counts``: ``bound`` zeroed int64 of
scratch), the groups in increasing label order each get consecutive places from a multiple of eight, their
rows in row order (a counting sort: stable), and the places left in a group's last block repeat its last
row: ``taken`` (the row in each place), ``place`` (each row's place), ``starts`` (each group's first place,
then the total) and ``group_labels`` (the distinct labels). Returns the group count. Two passes over the
rows and two over the labels' range (:class:`implc.surface.Grouping`; numpy's stable argsort and the
scatters after it took 18-21 ms for the 680,000 vertices of colonnade's mesh at 256³).
"""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import I64, Local, const, define, for_range, if_, load_at, store_at


def emit_arrange_groups(module: ir.Module):
    fn, b = define(module, abi.ARRANGE_GROUPS)
    labels, n, bound, counts, group_labels, starts, taken, place = fn.args
    one, seven = const(I64, 1), const(I64, 7)
    with for_range(b, n) as row:  # each label's row count
        label = load_at(b, labels, row)
        store_at(b, b.add(load_at(b, counts, label), one), counts, label)
    groups, at = Local(b, I64, const(I64, 0), "groups"), Local(b, I64, const(I64, 0), "at")
    with for_range(b, bound) as label:  # each group's first place, kept in ``counts`` for the scatter
        count = load_at(b, counts, label)
        with if_(b, b.icmp_signed(">", count, const(I64, 0))):
            store_at(b, label, group_labels, groups.get())
            store_at(b, at.get(), starts, groups.get())
            store_at(b, at.get(), counts, label)
            groups.set(b.add(groups.get(), one))
            at.set(b.add(at.get(), b.and_(b.add(count, seven), const(I64, ~7))))
    store_at(b, at.get(), starts, groups.get())
    with for_range(b, n) as row:  # the rows in row order into their groups' next places
        label = load_at(b, labels, row)
        slot = load_at(b, counts, label)
        store_at(b, row, taken, slot)
        store_at(b, slot, place, row)
        store_at(b, b.add(slot, one), counts, label)
    with for_range(b, groups.get()) as g:  # a group's last block filled with its last row
        end = load_at(b, starts, b.add(g, one))
        filled = load_at(b, counts, load_at(b, group_labels, g))
        last = load_at(b, taken, b.sub(filled, one))
        with for_range(b, end, start=filled) as slot:
            store_at(b, last, taken, slot)
    b.ret(groups.get())
