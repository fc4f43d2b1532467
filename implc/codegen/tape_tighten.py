"""``tape_tighten``: the tape engine's second look at the leaves the normals flag, below each leaf.

The normals pass flags the kept leaves whose cell the linear model at their centre misses, with the side
F(c) lies on (:mod:`implc.codegen.normals`). This pass tries to prove F on that side over each flagged
leaf's whole box with the program of the leaves' octant (simplified by every choice decided above it),
and marks the proven ones for :mod:`implc.codegen.tighten` to drop. The proof over a box, eight boxes
at a time (:func:`emit_tape_tighten`'s ``prove``):

- the enclosure of F over the box (``tape_box_gradient``), with those of its three partials;
- the monotonicity test: along each axis where a partial's enclosure is finite and keeps its sign, F is
  least (greatest) on one face, so the box shrinks to that face (to a corner where all three keep their
  sign) and ``tape_interval`` encloses F there. Sound where F is continuous on the box: never used where
  F's enclosure is undefined (NaN) or a partial's is NaN or infinite (a pole, a possible jump).

A leaf the test leaves open is split (:mod:`implc.codegen.leaf_split`), each box below it tested by its
plain enclosure first. Boxes are the subdivider's at the finer levels (origin + i·h, padded outward).
"""

from __future__ import annotations

from llvmlite import ir

from .control import I32, I64, Local, const, for_range, if_, load_at, local_array, store_at
from .leaf_split import emit_split, for_flagged_batches, load_batch
from .tape_eval import LANES, V8
from .tighten import INSIDE, OUTSIDE
from .vector import DOUBLE, VectorBuilder, broadcast

I8 = ir.IntType(8)
_P = ir.PointerType


def emit_tape_tighten(module: ir.Module, interval: ir.Function, box_gradient: ir.Function,
                      directed: bool) -> ir.Function:
    """``tape_tighten(header, program, length, output, slots, choices, geom, depth, coords, flags, n)``
    (internal): the flagged ones (:data:`implc.abi.TIGHTEN_ABOVE`, :data:`implc.abi.TIGHTEN_BELOW`) of
    the ``n`` voxels at ``coords`` (int32 cells at ``depth``) get :data:`~implc.codegen.tighten.OUTSIDE` or
    :data:`~implc.codegen.tighten.INSIDE` where F is proven on their side over the whole cell; ``choices``:
    scratch for ``tape_interval``'s choices."""
    fn = ir.Function(module, ir.FunctionType(ir.VoidType(), [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(I8),
                                                              _P(DOUBLE), I64, _P(I32), _P(I8), I64]),
                     name="implc.tape.tighten")
    fn.linkage = "internal"
    header, program, length, output, slots, choices, geom, depth, coords, flags, n = fn.args
    b = ir.IRBuilder(fn.append_basic_block("entry"))
    vb = VectorBuilder(b, LANES, directed)
    box = local_array(b, DOUBLE, 6 * LANES, "box")
    reduced = local_array(b, DOUBLE, 6 * LANES, "reduced")
    gradient = local_array(b, DOUBLE, 8 * LANES, "gradient")
    result = local_array(b, DOUBLE, 2 * LANES, "result")
    cells = local_array(b, DOUBLE, 3 * LANES, "cells")  # the boxes' cells (as doubles) at the level tested
    sides = local_array(b, DOUBLE, LANES, "sides")  # +1: prove F > 0, -1: prove F < 0
    first_sides = local_array(b, DOUBLE, LANES, "first_sides")  # the first test's, while its voxels are split
    slots_of = local_array(b, I64, LANES, "slots_of")  # the voxel in each lane of the first test
    vbox, vreduced, vgradient = (b.bitcast(p, _P(V8)) for p in (box, reduced, gradient))
    origin = [broadcast(b, load_at(b, geom, a), LANES) for a in range(3)]
    pad = [broadcast(b, load_at(b, geom, 3 + a), LANES) for a in range(3)]
    leaf_h = [load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))) for a in range(3)]
    zero, one, inf = vb.splat(0.0), vb.splat(1.0), vb.splat(float("inf"))

    def prove(factor, natural_first=False):
        """The lanes (i8 mask) whose box (cells at ``cells``, of the leaves' size times ``factor``) is
        proven on its side: by its enclosure, or by the enclosure over the face or corner its monotone axes
        give (``natural_first``: the plain enclosure first, and the rest only if it leaves a box open)."""
        vcells = b.bitcast(cells, _P(V8))
        for a in range(3):
            h = broadcast(b, b.fmul(leaf_h[a], factor), LANES)
            i = b.load(b.gep(vcells, [const(I64, a)]), align=8)
            b.store(b.fsub(b.fadd(origin[a], b.fmul(i, h)), pad[a]), b.gep(vbox, [const(I64, a)]), align=8)
            b.store(b.fadd(b.fadd(origin[a], b.fmul(b.fadd(i, one), h)), pad[a]), b.gep(vbox, [const(I64, 3 + a)]),
                    align=8)
        side = b.load(b.bitcast(sides, _P(V8)), align=8)
        above = vb.cmp(">", side, zero)
        vresult = b.bitcast(result, _P(V8))

        def on_side(lo, hi):
            return b.select(above, vb.cmp(">", lo, zero), vb.cmp("<", hi, zero))

        verdict = Local(b, I8, const(I8, 0), "verdict")
        if natural_first:
            b.call(interval, [header, program, length, output, slots, choices, box, result])
            verdict.set(b.bitcast(on_side(b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)),
                                  I8))
        with if_(b, b.icmp_unsigned("!=", verdict.get(), const(I8, 0xFF))):
            b.call(box_gradient, [header, program, length, output, slots, box, gradient])
            f_lo, f_hi = (b.load(b.gep(vgradient, [const(I64, k)]), align=8) for k in range(2))
            defined = b.not_(b.or_(vb.isnan(f_lo), vb.isnan(f_hi)))
            proven = on_side(f_lo, f_hi)
            for a in range(3):
                d_lo, d_hi = (b.load(b.gep(vgradient, [const(I64, 2 + 2 * a + k)]), align=8) for k in range(2))
                rising = b.and_(vb.cmp(">=", d_lo, zero), vb.cmp("<", d_hi, inf))
                falling = b.and_(vb.cmp("<=", d_hi, zero), vb.cmp(">", d_lo, vb.neg(inf)))
                # F is least on the lo face where it rises along a, greatest there where it falls
                to_lo = b.and_(defined, b.select(above, rising, falling))
                to_hi = b.and_(defined, b.and_(b.not_(to_lo), b.select(above, falling, rising)))
                lo = b.load(b.gep(vbox, [const(I64, a)]), align=8)
                hi = b.load(b.gep(vbox, [const(I64, 3 + a)]), align=8)
                b.store(b.select(to_hi, hi, lo), b.gep(vreduced, [const(I64, a)]), align=8)
                b.store(b.select(to_lo, lo, hi), b.gep(vreduced, [const(I64, 3 + a)]), align=8)
            b.call(interval, [header, program, length, output, slots, choices, reduced, result])
            r_lo, r_hi = b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)
            proven = b.or_(proven, b.and_(defined, on_side(r_lo, r_hi)))
            verdict.set(b.or_(verdict.get(), b.bitcast(proven, I8)))
        return verdict.get()

    def mark(index, side):
        store_at(b, b.select(b.fcmp_ordered(">", side, const(DOUBLE, 0.0)), const(I8, OUTSIDE), const(I8, INSIDE)),
                 flags, index)

    def split(index, side):
        """The voxel ``index`` split below (:func:`~implc.codegen.leaf_split.emit_split`): marked if every box
        is proven."""
        b.store(broadcast(b, side, LANES), b.bitcast(sides, _P(V8)), align=8)
        leaf = [b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE)
                for a in range(3)]
        with if_(b, emit_split(b, leaf, cells, lambda factor: prove(factor, natural_first=True))):
            mark(index, side)

    def test_pending(count):
        """The first test over ``count`` flagged voxels' own boxes (unused lanes repeat the first); the
        ones it leaves open are split."""
        load_batch(b, coords, flags, slots_of, count, cells, sides)
        proven = b.zext(prove(const(DOUBLE, 1.0)), I32)
        vsides = b.bitcast(sides, _P(V8))
        b.store(b.load(vsides, align=8), b.bitcast(first_sides, _P(V8)), align=8)  # splitting overwrites sides
        with for_range(b, count) as j:
            index, side = load_at(b, slots_of, j), load_at(b, first_sides, j)
            with b.if_else(b.trunc(b.lshr(proven, b.trunc(j, I32)), ir.IntType(1))) as (yes, no):
                with yes:
                    mark(index, side)
                with no:
                    split(index, side)

    for_flagged_batches(b, flags, n, slots_of, test_pending)
    b.ret_void()
    return fn
