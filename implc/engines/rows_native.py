"""The rows the walk writes, either engine's: ``implc_drop_marked`` drops the leaves a second look proved,
``implc_arrange_groups`` lays rows out by group as ``implc_tape_grouped`` reads them.

``implc_drop_marked`` (after the walk's second look, :mod:`implc.engines.compiled.tighten_native` or
:mod:`implc.engines.tape.tighten_native`) counts the flagged and the marked leaves and drops the marked ones;
where ``inside`` is not NULL (a solid) the leaves proven below 0 are appended to it
(:data:`implc.native.abi.INSIDE_WORDS` each, ``*inside_count`` rows already there, and updated). The survivors
(coordinates, masks, normals) are moved down in order; the new count is returned.

``implc_arrange_groups``: given each row's group label (``labels``, each below ``bound``; ``counts``: ``bound``
zeroed int64 of scratch), the groups in increasing label order each get consecutive places from a multiple of
eight, their rows in row order (a counting sort: stable), and the places left in a group's last block repeat its
last row: ``taken`` (the row in each place), ``place`` (each row's place), ``starts`` (each group's first place,
then the total) and ``group_labels`` (the distinct labels). Returns the group count. Two passes over the rows and
two over the labels' range (:class:`implc.engines.surface.Grouping`).
"""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import I32, I64, Local, const, define, for_range, if_, load_at, store_at
from ..native import abi
from ..native.jit import Source
from ..native.runtime import Library
from .second_look_native import I8, INSIDE, OUTSIDE


def emit_drop_marked(module: ir.Module):
    """``implc_drop_marked``: after the walk's second look (either evaluator's), count the flagged and the
    marked leaves and drop the marked ones (see the module)."""
    fn, b = define(module, abi.DROP_MARKED)
    depth, coords, masks, normals, flags, n, inside, inside_count, stats = fn.args
    solid = b.icmp_unsigned("!=", inside, ir.Constant(inside.type, None))
    kept = Local(b, I64, 0, "kept")
    flagged, marked = Local(b, I64, 0, "flagged"), Local(b, I64, 0, "marked")  # stats[0] and stats[1] add these
    with for_range(b, n) as i:
        flag = load_at(b, flags, i)
        is_flagged = b.and_(b.icmp_unsigned(">=", flag, const(I8, abi.TIGHTEN_ABOVE)),
                            b.icmp_unsigned("<=", flag, const(I8, abi.TIGHTEN_BELOW)))
        flagged.set(b.add(flagged.get(), b.zext(is_flagged, I64)))
        with if_(b, b.and_(solid, b.icmp_unsigned("==", flag, const(I8, INSIDE)))):
            row = b.mul(b.load(inside_count), const(I64, abi.INSIDE_WORDS))
            for a in range(3):
                store_at(b, load_at(b, coords, b.add(b.mul(i, const(I64, 3)), const(I64, a))), inside,
                         b.add(row, const(I64, a)))
            store_at(b, b.trunc(depth, I32), inside, b.add(row, const(I64, 3)))
            b.store(b.add(b.load(inside_count), const(I64, 1)), inside_count)
        dropped = b.or_(b.icmp_unsigned("==", flag, const(I8, OUTSIDE)), b.icmp_unsigned("==", flag, const(I8, INSIDE)))
        marked.set(b.add(marked.get(), b.zext(dropped, I64)))
        # every leaf is copied down to the next kept row and only a kept one advances it: no branch on the
        # marks, which fall as the surface does (k <= i: row k was read before, or is row i itself)
        k = kept.get()
        for a in range(3):
            store_at(b, load_at(b, coords, b.add(b.mul(i, const(I64, 3)), const(I64, a))), coords,
                     b.add(b.mul(k, const(I64, 3)), const(I64, a)))
            store_at(b, load_at(b, normals, b.add(b.mul(i, const(I64, 3)), const(I64, a))), normals,
                     b.add(b.mul(k, const(I64, 3)), const(I64, a)))
        store_at(b, load_at(b, masks, i), masks, k)
        kept.set(b.add(k, b.zext(b.not_(dropped), I64)))
    for word, count in enumerate((flagged, marked)):
        store_at(b, b.add(load_at(b, stats, word), count.get()), stats, word)
    b.ret(kept.get())


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


def build_rows() -> ir.Module:
    """The rows' module."""
    module = ir.Module(name="implc_rows")
    emit_drop_marked(module)
    emit_arrange_groups(module)
    return module


ROWS = Library(Source(build_rows, "implc-rows"), abi.ROWS_ENTRIES)
"""The rows' module: both engines' voxelizations use it, so the tape engine compiles it at once with itself."""
