"""The second look at the leaves, written once over an evaluator's tests (:class:`Look`): the flagged leaves
taken eight at a time, the first test over their boxes, and for a leaf it leaves open the further tests
and the split (:func:`emit_second_look`).

The normals flag the kept leaves that the linear model at their centre misses, with the side F(c) lies on
(:data:`implc.native.abi.TIGHTEN_ABOVE`: prove F > 0 on the whole box, :data:`implc.native.abi.TIGHTEN_BELOW`: F < 0). A
leaf proven is marked :data:`OUTSIDE` or :data:`INSIDE`, for ``implc_drop_marked`` to drop. The first
test runs over a batch of eight leaves' boxes. A leaf it leaves open gets the evaluator's test over a face
of it where it has one (:meth:`Look.face`); else, unless F at one of its corners (in floating point)
already lies across 0 (:meth:`Look.crossed`: the surface crosses it, so splitting it would only spend
time), it is split (:func:`emit_split`): the tests tighten as boxes shrink (the partials keep their sign on
smaller boxes, the rest of the enclosure shrinks with the box), so the leaf is split :data:`LEVELS_BELOW`
levels down and proven when every box at the last level is, the boxes a level proves dropping out. A box's
cell at k levels below the leaves is given as doubles (exact: below 2^53); the evaluator makes its box as
the subdivider would at that level (origin + i·h, h the leaves' size times 2^-k exactly, padded outward),
so the boxes cover the leaf. The evaluators: a surface's compiled monotonicity bound
(:mod:`implc.engines.compiled.tighten_native`) and the tape engine's interval gradients
(:mod:`implc.engines.tape.tighten_native`).
"""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import (
    I32,
    I64,
    Local,
    bit_intrinsic,
    const,
    for_range,
    if_,
    load_at,
    local_array,
    store_at,
    while_true,
)
from ..compiler.llvm.vector import DOUBLE, broadcast
from ..native import abi

LEVELS_BELOW = 2
"""How many levels below a flagged leaf the second look splits it to prove it empty (1 or more)."""
LANES = 8
V8 = ir.VectorType(DOUBLE, LANES)
I8 = ir.IntType(8)
OUTSIDE, INSIDE = 2, 3
"""The marks of the leaves a second look proves: F > 0 on the whole box, F < 0 (the normals' flags are
:data:`implc.native.abi.TIGHTEN_ABOVE` and :data:`implc.native.abi.TIGHTEN_BELOW`)."""


class Look:
    """What the second look asks of an evaluator: IR emitted at its builder ``b``. Boxes are given by their
    cells (``cells``: three rows of eight doubles, axis by axis) and their sides (+1.0: prove F > 0, -1.0:
    prove F < 0)."""

    batches_once = False
    """Whether the batches' tests are emitted once (see :func:`for_flagged_batches`): half the code, for an
    evaluator whose tests cost enough that knowing a full batch's count gains nothing (the tape engine's,
    whose module's first compile it shortens)."""

    def first(self, cells, sides):
        """The first test over the batch's eight boxes (the leaves'; unused lanes repeat the first): the
        lanes proven on their side (an i8 mask)."""
        raise NotImplementedError

    def flagged(self, index) -> None:
        """Leaf ``index`` (an i64) joins the batch."""

    def batch_done(self) -> None:
        """The batch is done."""

    def open(self, index, side, lane) -> None:
        """Leaf ``index``, in ``lane`` of the first test (i64 values), on ``side`` (a double), was left open
        by it: its further tests follow."""

    def face(self, leaf):
        """An i1: the leaf (three double cells) proven over a face where F is least (greatest) along its
        monotone axes; None where the evaluator has no such test."""
        return None

    def crossed(self, leaf, side):
        """An i1: F at one of the leaf's corners, in floating point, lies across 0 from ``side``."""
        raise NotImplementedError

    def prove(self, factor, level):
        """The boxes (cells at the look's ``cells``, of the leaves' size times ``factor``, ``level`` (an i64,
        1 or more) levels below the leaf) proven on the open leaf's side (an i8 mask)."""
        raise NotImplementedError

    def descend(self, level, c) -> None:
        """Before the boxes below box ``c`` (an i32) of ``level`` are proven."""


def emit_second_look(b: ir.IRBuilder, coords, flags, n, look: Look, cells) -> None:
    """Emit the second look at the flagged ones of the ``n`` leaves at ``coords`` (int32 cells), marking the
    proven ones in ``flags``; ``cells``: the (3, 8) doubles the boxes' cells are written to, which ``look``
    reads."""
    slots = local_array(b, I64, LANES, "look.slots")  # the leaf in each lane of the first test
    sides = local_array(b, DOUBLE, LANES, "look.sides")
    zero = const(DOUBLE, 0.0)

    def mark(index, side):
        store_at(b, b.select(b.fcmp_ordered(">", side, zero), const(I8, OUTSIDE), const(I8, INSIDE)), flags, index)

    def test(count):
        """The first test over ``count`` flagged leaves' boxes; the ones it leaves open tried further."""
        load_batch(b, coords, flags, slots, count, cells, sides)
        proven = b.zext(look.first(cells, sides), I32)
        with for_range(b, count) as j:
            index, side = load_at(b, slots, j), load_at(b, sides, j)
            with b.if_else(b.trunc(b.lshr(proven, b.trunc(j, I32)), ir.IntType(1))) as (yes, no):
                with yes:
                    mark(index, side)
                with no:
                    leaf = [b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE)
                            for a in range(3)]
                    look.open(index, side, j)
                    face = look.face(leaf)
                    face = ir.Constant(ir.IntType(1), 0) if face is None else face
                    with b.if_else(face) as (on_face, box):
                        with on_face:
                            mark(index, side)
                        with box:
                            with if_(b, b.not_(look.crossed(leaf, side))):
                                with if_(b, emit_split(b, leaf, cells, look.prove, look.descend)):
                                    mark(index, side)
        look.batch_done()

    for_flagged_batches(b, flags, n, slots, test, look.flagged, once=look.batches_once)


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
    opening = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 1), "split.opening")  # base[level] is new
    with while_true(b) as loop:
        with if_(b, opening.get()):  # the boxes below a new base: proven once here (one copy of the test's code)
            store_at(b, open_children(level.get()), open_, level.get())
            opening.set(ir.Constant(ir.IntType(1), 0))
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
                level.set(child)
                opening.set(ir.Constant(ir.IntType(1), 1))
        done = b.icmp_signed("==", level.get(), const(I64, 0))  # every box proven
        with if_(b, done):
            proven.set(ir.Constant(ir.IntType(1), 1))
        loop.break_if(done)
    return proven.get()


def load_batch(b: ir.IRBuilder, coords, flags, slots, count, cells, sides):
    """The batch's leaves (``count`` of them, their indices at ``slots``) into ``cells`` (axis by axis, as
    doubles) and their sides into ``sides`` (+1 where flagged :data:`implc.native.abi.TIGHTEN_ABOVE`: prove F > 0,
    else -1); unused lanes repeat the first leaf."""
    first = load_at(b, slots, 0)
    for j in range(LANES):
        index = b.select(b.icmp_signed("<", const(I64, j), count), load_at(b, slots, j), first)
        for a in range(3):
            store_at(b, b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE),
                     cells, LANES * a + j)
        above = b.icmp_unsigned("==", load_at(b, flags, index), const(I8, abi.TIGHTEN_ABOVE))
        store_at(b, b.select(above, const(DOUBLE, 1.0), const(DOUBLE, -1.0)), sides, j)


def for_flagged_batches(b: ir.IRBuilder, flags, n, slots, test, on_flagged=None, once=False):
    """Gather the leaves flagged for a second look (:data:`implc.native.abi.TIGHTEN_ABOVE` or
    :data:`~implc.native.abi.TIGHTEN_BELOW`) among the ``n`` at ``flags`` into ``slots`` (eight i64 indices) and
    call ``test(count)`` (an i64, 1 to 8) for each batch, the last maybe partial; ``on_flagged(i)`` runs for
    each flagged leaf as it joins its batch. ``test``'s code is emitted twice, for full batches (count 8,
    known to the optimiser) and for the last, or with ``once`` a single time: both branch to it, and it
    returns to the loop or past it."""
    fn = b.function
    lanes = Local(b, I64, const(I64, 0), "flagged.lanes")
    index = Local(b, I64, const(I64, 0), "flagged.index")
    final = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 0), "flagged.final")
    header, body, latch, tail, run, done = (fn.append_basic_block(f"flagged.{name}")
                                            for name in ("header", "body", "latch", "tail", "run", "done"))
    run_full = run if once else fn.append_basic_block("flagged.full")
    b.branch(header)
    b.position_at_end(header)
    i = index.get()
    b.cbranch(b.icmp_signed("<", i, n), body, tail)
    b.position_at_end(body)
    flag = load_at(b, flags, i)
    flagged = b.or_(b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_ABOVE)),
                    b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_BELOW)))
    with if_(b, flagged):
        store_at(b, i, slots, lanes.get())
        lanes.set(b.add(lanes.get(), const(I64, 1)))
        if on_flagged is not None:
            on_flagged(i)
    b.cbranch(b.icmp_signed("==", lanes.get(), const(I64, LANES)), run_full, latch)
    if not once:
        b.position_at_end(run_full)
        test(const(I64, LANES))
        lanes.set(const(I64, 0))
        b.branch(latch)
    b.position_at_end(latch)
    index.set(b.add(index.get(), const(I64, 1)))
    b.branch(header)
    b.position_at_end(tail)
    final.set(ir.Constant(ir.IntType(1), 1))
    b.cbranch(b.icmp_signed(">", lanes.get(), const(I64, 0)), run, done)
    b.position_at_end(run)
    test(lanes.get())
    lanes.set(const(I64, 0))
    b.cbranch(final.get(), done, latch)
    b.position_at_end(done)
