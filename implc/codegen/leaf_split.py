"""What both second looks at the leaves share: the flagged leaves taken eight at a time
(:func:`for_flagged_batches`, :func:`load_batch`), and the split of a leaf the first test could not prove whole: its
eighths, then theirs, depth first (:func:`emit_split`).

Both second looks (:mod:`implc.codegen.tighten` with a surface's compiled bound, and the tape engine's
:mod:`implc.codegen.tape_tighten`) test a flagged leaf's box first; where that leaves it open, the tests
tighten as boxes shrink (the partials keep their sign on smaller boxes, the rest of the enclosure
shrinks with the box), so the leaf is split :data:`LEVELS_BELOW` levels down and proven when every box at
the last level is, the boxes a level proves dropping out. A box's cell at k levels below the leaves is
given as doubles (exact: below 2^53); the caller makes its box as the subdivider would at that level
(origin + i·h, h the leaves' size times 2^-k exactly, padded outward), so the boxes cover the leaf.
"""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import I32, I64, Local, bit_intrinsic, const, for_range, if_, load_at, local_array, store_at, while_true
from .vector import DOUBLE, broadcast

LEVELS_BELOW = 2
"""How many levels below a flagged leaf the second look splits it to prove it empty (1 or more)."""
LANES = 8
V8 = ir.VectorType(DOUBLE, LANES)
I8 = ir.IntType(8)


def emit_split(b: ir.IRBuilder, leaf, cells, prove, descend=None):
    """Emit the split of one leaf; returns an i1: every box at the last level proven (so the whole leaf).

    ``leaf``: its cell, three double values; ``cells``: a (3, 8) array of doubles the eight boxes' cells
    are written to, axis by axis, before each ``prove(factor, level)``, which returns the boxes proven (i8
    mask, bit c: box c), ``factor`` (a double value) being their size over the leaves' and ``level`` (an
    i64, 1 to :data:`LEVELS_BELOW`) how far below the leaf they lie. ``descend(level, c)``, where given,
    runs before the boxes below box ``c`` (an i32) of ``level`` are proven."""
    assert LEVELS_BELOW >= 1
    module = b.module
    cttz = bit_intrinsic(module, "cttz")
    base = local_array(b, DOUBLE, 3 * (LEVELS_BELOW + 1), "split.base")  # the parent cell of each level's boxes
    open_ = local_array(b, I32, LEVELS_BELOW + 1, "split.open")  # each level's boxes not proven yet
    vcells = b.bitcast(cells, ir.PointerType(V8))

    def open_children(level):
        """The eight boxes below ``base[level]`` (an i64 level, 1 to LEVELS_BELOW) not proven (i32 mask)."""
        for a in range(3):
            parent = broadcast(b, load_at(b, base, b.add(b.mul(level, const(I64, 3)), const(I64, a))), LANES)
            bits = ir.Constant(V8, [float((c >> a) & 1) for c in range(LANES)])
            b.store(b.fadd(b.fmul(parent, broadcast(b, const(DOUBLE, 2.0), LANES)), bits),
                    b.gep(vcells, [const(I64, a)]), align=8)
        factor = b.fdiv(const(DOUBLE, 1.0), b.uitofp(b.shl(const(I64, 1), level), DOUBLE))  # exact: 2^-level
        return b.zext(b.xor(prove(factor, level), const(I8, 0xFF)), I32)

    for a in range(3):
        store_at(b, leaf[a], base, 3 + a)
    proven = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 0), "split.proven")
    level = Local(b, I64, const(I64, 1), "split.level")
    store_at(b, open_children(const(I64, 1)), open_, 1)
    with while_true(b) as loop:
        k = level.get()
        remaining = load_at(b, open_, k)
        # a box at the last level stays open: so does the leaf
        loop.break_if(b.and_(b.icmp_signed("==", k, const(I64, LEVELS_BELOW)),
                             b.icmp_unsigned("!=", remaining, const(I32, 0))))
        with b.if_else(b.icmp_unsigned("==", remaining, const(I32, 0))) as (up, down):
            with up:
                level.set(b.sub(k, const(I64, 1)))
            with down:  # into the next open box
                c = b.call(cttz, [remaining, ir.Constant(ir.IntType(1), 1)])
                store_at(b, b.and_(remaining, b.sub(remaining, const(I32, 1))), open_, k)
                child = b.add(k, const(I64, 1))
                if descend is not None:
                    descend(k, c)
                for a in range(3):
                    bit = b.uitofp(b.and_(b.lshr(c, const(I32, a)), const(I32, 1)), DOUBLE)
                    parent = load_at(b, base, b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                    store_at(b, b.fadd(b.fmul(parent, const(DOUBLE, 2.0)), bit), base,
                             b.add(b.mul(child, const(I64, 3)), const(I64, a)))
                store_at(b, open_children(child), open_, child)
                level.set(child)
        done = b.icmp_signed("==", level.get(), const(I64, 0))  # every box proven
        with if_(b, done):
            proven.set(ir.Constant(ir.IntType(1), 1))
        loop.break_if(done)
    return proven.get()


def load_batch(b: ir.IRBuilder, coords, flags, slots, count, cells, sides):
    """The batch's leaves (``count`` of them, their indices at ``slots``) into ``cells`` (axis by axis, as
    doubles) and their sides into ``sides`` (+1 where flagged :data:`implc.abi.TIGHTEN_ABOVE`: prove F > 0,
    else -1); unused lanes repeat the first leaf."""
    first = load_at(b, slots, 0)
    for j in range(LANES):
        index = b.select(b.icmp_signed("<", const(I64, j), count), load_at(b, slots, j), first)
        for a in range(3):
            store_at(b, b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE),
                     cells, LANES * a + j)
        above = b.icmp_unsigned("==", load_at(b, flags, index), const(I8, abi.TIGHTEN_ABOVE))
        store_at(b, b.select(above, const(DOUBLE, 1.0), const(DOUBLE, -1.0)), sides, j)


def for_flagged_batches(b: ir.IRBuilder, flags, n, slots, test, on_flagged=None):
    """Gather the leaves flagged for a second look (:data:`implc.abi.TIGHTEN_ABOVE` or
    :data:`~implc.abi.TIGHTEN_BELOW`) among the ``n`` at ``flags`` into ``slots`` (eight i64 indices) and
    call ``test(count)`` (an i64, 1 to 8) for each batch, the last maybe partial; ``on_flagged(i)`` runs for
    each flagged leaf as it joins its batch."""
    lanes = Local(b, I64, const(I64, 0), "flagged.lanes")

    def run():
        test(lanes.get())
        lanes.set(const(I64, 0))

    with for_range(b, n) as i:
        flag = load_at(b, flags, i)
        flagged = b.or_(b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_ABOVE)),
                        b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_BELOW)))
        with if_(b, flagged):
            store_at(b, i, slots, lanes.get())
            lanes.set(b.add(lanes.get(), const(I64, 1)))
            if on_flagged is not None:
                on_flagged(i)
            with if_(b, b.icmp_signed("==", lanes.get(), const(I64, LANES))):
                run()
    with if_(b, b.icmp_signed(">", lanes.get(), const(I64, 0))):
        run()
