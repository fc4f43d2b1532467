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

A leaf the test leaves open is split, eighths then their eighths (:data:`LEVELS_BELOW` levels, depth
first, the eighths a level proves dropping out), and proven when every box at the last level is: the test
tightens as boxes shrink (the partials keep their sign on smaller boxes, and the rest of the enclosure
shrinks with the box). Boxes are the subdivider's at the finer levels (origin + i·h, padded outward).
"""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import I32, I64, Local, const, for_range, if_, load_at, local_array, store_at, while_true
from .tape_eval import LANES, V8
from .tighten import INSIDE, OUTSIDE
from .vector import DOUBLE, VectorBuilder, broadcast

I8 = ir.IntType(8)
LEVELS_BELOW = 2
"""How many levels below a flagged leaf the second look splits it to prove it empty."""
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
    base = local_array(b, DOUBLE, 3 * (LEVELS_BELOW + 1), "base")  # the parent cell of each level's boxes
    open_ = local_array(b, I32, LEVELS_BELOW + 1, "open")  # each level's boxes not proven yet (bit c: box c)
    vbox, vreduced, vgradient = (b.bitcast(p, _P(V8)) for p in (box, reduced, gradient))
    origin = [broadcast(b, load_at(b, geom, a), LANES) for a in range(3)]
    pad = [broadcast(b, load_at(b, geom, 3 + a), LANES) for a in range(3)]
    leaf_h = [load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))) for a in range(3)]
    zero, one, inf = vb.splat(0.0), vb.splat(1.0), vb.splat(float("inf"))
    lanes = Local(b, I64, 0, "lanes")
    cttz = module.globals.get("llvm.cttz.i32") or ir.Function(module, ir.FunctionType(I32, [I32, ir.IntType(1)]),
                                                              name="llvm.cttz.i32")

    def prove(factor):
        """The lanes (i8 mask) whose box (cells at ``cells``, of the leaves' size times ``factor``) is
        proven on its side: its enclosure, or the enclosure over the face or corner its monotone axes give."""
        vcells = b.bitcast(cells, _P(V8))
        for a in range(3):
            h = broadcast(b, b.fmul(leaf_h[a], factor), LANES)
            i = b.load(b.gep(vcells, [const(I64, a)]), align=8)
            b.store(b.fsub(b.fadd(origin[a], b.fmul(i, h)), pad[a]), b.gep(vbox, [const(I64, a)]), align=8)
            b.store(b.fadd(b.fadd(origin[a], b.fmul(b.fadd(i, one), h)), pad[a]), b.gep(vbox, [const(I64, 3 + a)]),
                    align=8)
        b.call(box_gradient, [header, program, length, output, slots, box, gradient])
        side = b.load(b.bitcast(sides, _P(V8)), align=8)
        above = vb.cmp(">", side, zero)
        f_lo, f_hi = (b.load(b.gep(vgradient, [const(I64, k)]), align=8) for k in range(2))
        defined = b.not_(b.or_(vb.isnan(f_lo), vb.isnan(f_hi)))
        proven = b.select(above, vb.cmp(">", f_lo, zero), vb.cmp("<", f_hi, zero))
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
        vresult = b.bitcast(result, _P(V8))
        r_lo, r_hi = b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)
        proven = b.or_(proven, b.and_(defined, b.select(above, vb.cmp(">", r_lo, zero), vb.cmp("<", r_hi, zero))))
        return b.bitcast(proven, I8)

    def open_children(level):
        """The eight boxes below ``base[level]`` (``level`` an i64, 1 to LEVELS_BELOW): those not proven
        (i32 mask, bit c: box c)."""
        for a in range(3):
            parent = broadcast(b, load_at(b, base, b.add(b.mul(level, const(I64, 3)), const(I64, a))), LANES)
            bits = ir.Constant(V8, [float((c >> a) & 1) for c in range(LANES)])
            b.store(b.fadd(b.fmul(parent, vb.splat(2.0)), bits), b.gep(b.bitcast(cells, _P(V8)), [const(I64, a)]),
                    align=8)
        factor = b.fdiv(const(DOUBLE, 1.0), b.uitofp(b.shl(const(I64, 1), level), DOUBLE))  # exact: 2^-level
        return b.zext(b.xor(prove(factor), const(I8, 0xFF)), I32)

    def mark(index, side):
        store_at(b, b.select(b.fcmp_ordered(">", side, const(DOUBLE, 0.0)), const(I8, OUTSIDE), const(I8, INSIDE)),
                 flags, index)

    def split(index, side):
        """The voxel ``index`` split ``LEVELS_BELOW`` levels down, depth first: marked if every box is proven."""
        for a in range(3):
            store_at(b, b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE),
                     base, const(I64, 3 + a))
        b.store(broadcast(b, side, LANES), b.bitcast(sides, _P(V8)), align=8)
        level = Local(b, I64, 1, "level")
        store_at(b, open_children(const(I64, 1)), open_, 1)
        with while_true(b) as loop:
            k = level.get()
            remaining = load_at(b, open_, k)
            survives = b.and_(b.icmp_signed("==", k, const(I64, LEVELS_BELOW)),
                              b.icmp_unsigned("!=", remaining, const(I32, 0)))
            loop.break_if(survives)  # a box at the last level stays open: so does the voxel
            with b.if_else(b.icmp_unsigned("==", remaining, const(I32, 0))) as (up, down):
                with up:
                    level.set(b.sub(k, const(I64, 1)))
                with down:  # into the next open box
                    c = b.call(cttz, [remaining, ir.Constant(ir.IntType(1), 1)])
                    store_at(b, b.and_(remaining, b.sub(remaining, const(I32, 1))), open_, k)
                    child = b.add(k, const(I64, 1))
                    for a in range(3):
                        bit = b.uitofp(b.and_(b.lshr(c, const(I32, a)), const(I32, 1)), DOUBLE)
                        parent = load_at(b, base, b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                        store_at(b, b.fadd(b.fmul(parent, const(DOUBLE, 2.0)), bit), base,
                                 b.add(b.mul(child, const(I64, 3)), const(I64, a)))
                    store_at(b, open_children(child), open_, child)
                    level.set(child)
            with if_(b, b.icmp_signed("==", level.get(), const(I64, 0))):  # every box proven
                mark(index, side)
            loop.break_if(b.icmp_signed("==", level.get(), const(I64, 0)))

    def test_pending():
        """The first test over the pending flagged voxels' own boxes (unused lanes repeat the first); the
        ones it leaves open are split."""
        count = lanes.get()
        first = load_at(b, slots_of, 0)
        for j in range(LANES):
            index = b.select(b.icmp_signed("<", const(I64, j), count), load_at(b, slots_of, j), first)
            for a in range(3):
                store_at(b, b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE),
                         cells, LANES * a + j)
            above = b.icmp_unsigned("==", load_at(b, flags, index), const(I8, abi.TIGHTEN_ABOVE))
            store_at(b, b.select(above, const(DOUBLE, 1.0), const(DOUBLE, -1.0)), sides, j)
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
        lanes.set(const(I64, 0))

    with for_range(b, n) as i:
        flag = load_at(b, flags, i)
        flagged = b.or_(b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_ABOVE)),
                        b.icmp_unsigned("==", flag, const(I8, abi.TIGHTEN_BELOW)))
        with if_(b, flagged):
            store_at(b, i, slots_of, lanes.get())
            lanes.set(b.add(lanes.get(), const(I64, 1)))
            with if_(b, b.icmp_signed("==", lanes.get(), const(I64, LANES))):
                test_pending()
    with if_(b, b.icmp_signed(">", lanes.get(), const(I64, 0))):
        test_pending()
    b.ret_void()
    return fn
