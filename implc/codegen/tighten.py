"""``implc_tighten``: drops, in place, the kept leaves that a tighter enclosure proves empty.

The natural enclosure keeps every leaf whose box it cannot prove empty; the surface crosses most of
them. The normals pass flags the others worth a second look, the cells the linear model at their centre
misses (:mod:`implc.codegen.normals`), with the side F(c) lies on. For each flagged leaf one sound test:
the bound of the monotonicity form on that side over the leaf's box (``bound``, a surface's
``implc_bound_monotone``, eight leaves per call, their live-term masks joined). A leaf is dropped when
the bound proves F > 0 (or F < 0) on the whole box; a NaN bound never does. A leaf the bound leaves
open is split (:mod:`implc.codegen.leaf_split`: the bound over its eighths, then theirs, with the leaf's
live terms) and dropped when every box at the last level is proven, unless F at one of its corners
(``point``, in floating point) already lies across 0: the surface crosses it (most leaves the bound
leaves open on smooth surfaces), and splitting it would only spend time. With ``bound`` NULL the leaves
come tested (the tape engine's second look, :mod:`implc.codegen.tape_tighten`, marked the proven ones with
:data:`OUTSIDE` or :data:`INSIDE`): this pass counts them and drops those marked, which
``implc_drop_marked`` (:func:`emit_drop_marked`) does alone. Where ``inside`` is not
NULL (a solid) the leaves proven below 0 are appended to it (:data:`implc.abi.INSIDE_WORDS` each,
``*inside_count`` rows already there, and updated). The survivors (coordinates, masks, normals) are
moved down in order; the new count is returned.
"""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import I32, I64, Local, bump, const, define, for_range, if_, load_at, local_array, store_at
from .leaf_split import V8, emit_split, for_flagged_batches, load_batch

DOUBLE = ir.DoubleType()
I8 = ir.IntType(8)
OUTSIDE, INSIDE = 2, 3
"""Flags this pass sets on the leaves it drops: proven F > 0, proven F < 0 (the normals' flags are
:data:`implc.abi.TIGHTEN_ABOVE` and :data:`implc.abi.TIGHTEN_BELOW`)."""


def emit_tighten(module: ir.Module):
    fn, b = define(module, abi.TIGHTEN)
    bound_ptr, point_ptr, geom, depth, coords, masks, normals, flags, n, inside, inside_count, stats = fn.args
    bound = b.bitcast(bound_ptr, ir.PointerType(abi.BOUND_MONOTONE.llvm_type()))
    point = b.bitcast(point_ptr, ir.PointerType(abi.POINT.llvm_type()))
    origin = [load_at(b, geom, a) for a in range(3)]
    pad = [load_at(b, geom, 3 + a) for a in range(3)]
    h = [load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))) for a in range(3)]
    lo, hi = local_array(b, DOUBLE, 24, "lo"), local_array(b, DOUBLE, 24, "hi")  # the boxes bound, or points
    cells = local_array(b, DOUBLE, 24, "cells")  # the boxes' cells, axis by axis (at the leaves, or below)
    side, out = local_array(b, DOUBLE, 8, "side"), local_array(b, DOUBLE, 8, "out")  # the first test's
    live = local_array(b, I64, 1, "live")
    slots = local_array(b, I64, 8, "slots")
    # the split's: side, bounds and the leaf's live terms (the first test's are read while its leaves split)
    split_side, split_out = local_array(b, DOUBLE, 8, "split_side"), local_array(b, DOUBLE, 8, "split_out")
    split_live = local_array(b, I64, 1, "split_live")
    union = Local(b, I64, 0, "union")
    zero = const(DOUBLE, 0.0)
    splat = ir.Constant(V8, [0.0] * 8)

    def mark(index, above):
        store_at(b, b.select(above, const(I8, OUTSIDE), const(I8, INSIDE)), flags, index)
        bump(b, stats, 1)

    def bounds(factor, sides, values, live_terms):
        """The bound over the eight boxes of the cells at ``cells`` (the leaves' size times ``factor``), on
        each box's side (``sides``), into ``values``."""
        for j in range(8):
            for a in range(3):
                step = b.fmul(h[a], factor)
                c = load_at(b, cells, 8 * a + j)
                store_at(b, b.fsub(b.fadd(origin[a], b.fmul(c, step)), pad[a]), lo, 3 * j + a)
                store_at(b, b.fadd(b.fadd(origin[a], b.fmul(b.fadd(c, const(DOUBLE, 1.0)), step)), pad[a]), hi,
                         3 * j + a)
        b.call(bound, [lo, hi, sides, values, const(I64, 8), live_terms])

    def prove(factor, sign):
        """The boxes (cells at ``cells``, the leaves' size times ``factor``) the bound proves on the side
        ``sign`` (i8 mask), the leaf's live terms with them."""
        for j in range(8):
            store_at(b, sign, split_side, j)
        bounds(factor, split_side, split_out, split_live)
        values = b.load(b.bitcast(split_out, ir.PointerType(V8)), align=8)
        above = b.fcmp_ordered(">", sign, zero)
        return b.bitcast(b.select(above, b.fcmp_ordered(">", values, splat), b.fcmp_ordered("<", values, splat)), I8)

    def across(leaf, sign):
        """The leaf's corners (i8 mask) where F, evaluated in floating point (``point``), lies on the other
        side of 0 than ``sign``: the surface crosses such a leaf, so no split will drop it (a choice of
        work only: a leaf not split is kept)."""
        for j in range(8):
            for a in range(3):
                store_at(b, b.fadd(origin[a], b.fmul(b.fadd(leaf[a], const(DOUBLE, float((j >> a) & 1))), h[a])),
                         lo, 3 * j + a)
        b.call(point, [lo, split_out, const(I64, 8)])
        values = b.load(b.bitcast(split_out, ir.PointerType(V8)), align=8)
        above = b.fcmp_ordered(">", sign, zero)
        return b.bitcast(b.select(above, b.fcmp_ordered("<", values, splat), b.fcmp_ordered(">", values, splat)), I8)

    def test_pending(count):
        """The bounds over ``count`` flagged leaves' boxes (unused lanes repeat the first), and the verdicts."""
        load_batch(b, coords, flags, slots, count, cells, side)
        store_at(b, union.get(), live, 0)
        bounds(const(DOUBLE, 1.0), side, out, live)
        with for_range(b, count) as j:
            index = load_at(b, slots, j)
            value, sign = load_at(b, out, j), load_at(b, side, j)
            above = b.fcmp_ordered(">", sign, zero)
            bump(b, stats, 0)
            proven = b.select(above, b.fcmp_ordered(">", value, zero), b.fcmp_ordered("<", value, zero))
            with b.if_else(proven) as (yes, no):
                with yes:
                    mark(index, above)
                with no:  # split below (the bound over its eighths, then theirs) unless a corner is across
                    store_at(b, load_at(b, masks, index), split_live, 0)
                    leaf = [b.uitofp(load_at(b, coords, b.add(b.mul(index, const(I64, 3)), const(I64, a))), DOUBLE)
                            for a in range(3)]
                    with if_(b, b.icmp_unsigned("==", across(leaf, sign), const(I8, 0))):
                        with if_(b, emit_split(b, leaf, cells, lambda factor, _level: prove(factor, sign))):
                            mark(index, above)
        union.set(const(I64, 0))

    has_bound = b.icmp_unsigned("!=", bound_ptr, ir.Constant(bound_ptr.type, None))
    with b.if_else(has_bound) as (testing, tested):
        with testing:
            for_flagged_batches(b, flags, n, slots, test_pending,
                                lambda i: union.set(b.or_(union.get(), load_at(b, masks, i))))
        with tested:
            _count_marked(b, flags, n, stats)
    b.ret(_drop_marked(b, depth, coords, masks, normals, flags, n, inside, inside_count))


def emit_drop_marked(module: ir.Module):
    """``implc_drop_marked``: the end of :func:`emit_tighten` alone, for leaves the tape engine's second
    look already marked (:mod:`implc.codegen.tape_tighten`): count them and drop the proven ones. A
    module of its own from ``implc_tighten``'s tests, so that the tape engine's voxelizations never
    compile those."""
    fn, b = define(module, abi.DROP_MARKED)
    depth, coords, masks, normals, flags, n, inside, inside_count, stats = fn.args
    _count_marked(b, flags, n, stats)
    b.ret(_drop_marked(b, depth, coords, masks, normals, flags, n, inside, inside_count))


def _count_marked(b: ir.IRBuilder, flags, n, stats):
    """stats[0] += the flagged leaves, stats[1] += those marked proven (the tape engine's look)."""
    with for_range(b, n) as i:
        flag = load_at(b, flags, i)
        with if_(b, b.and_(b.icmp_unsigned(">=", flag, const(I8, abi.TIGHTEN_ABOVE)),
                           b.icmp_unsigned("<=", flag, const(I8, abi.TIGHTEN_BELOW)))):
            bump(b, stats, 0)
        with if_(b, b.or_(b.icmp_unsigned("==", flag, const(I8, OUTSIDE)),
                          b.icmp_unsigned("==", flag, const(I8, INSIDE)))):
            bump(b, stats, 1)


def _drop_marked(b: ir.IRBuilder, depth, coords, masks, normals, flags, n, inside, inside_count):
    """The leaves marked proven dropped in place (a solid's proven-inside ones appended to ``inside``), the
    survivors moved down in order; returns their count."""
    solid = b.icmp_unsigned("!=", inside, ir.Constant(inside.type, None))
    kept = Local(b, I64, 0, "kept")
    with for_range(b, n) as i:
        flag = load_at(b, flags, i)
        with if_(b, b.and_(solid, b.icmp_unsigned("==", flag, const(I8, INSIDE)))):
            row = b.mul(b.load(inside_count), const(I64, abi.INSIDE_WORDS))
            for a in range(3):
                store_at(b, load_at(b, coords, b.add(b.mul(i, const(I64, 3)), const(I64, a))), inside,
                         b.add(row, const(I64, a)))
            store_at(b, b.trunc(depth, I32), inside, b.add(row, const(I64, 3)))
            b.store(b.add(b.load(inside_count), const(I64, 1)), inside_count)
        dropped = b.or_(b.icmp_unsigned("==", flag, const(I8, OUTSIDE)), b.icmp_unsigned("==", flag, const(I8, INSIDE)))
        with if_(b, b.not_(dropped)):
            k = kept.get()
            with if_(b, b.icmp_signed("!=", k, i)):
                for a in range(3):
                    store_at(b, load_at(b, coords, b.add(b.mul(i, const(I64, 3)), const(I64, a))), coords,
                             b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                    store_at(b, load_at(b, normals, b.add(b.mul(i, const(I64, 3)), const(I64, a))), normals,
                             b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                store_at(b, load_at(b, masks, i), masks, k)
            kept.set(b.add(k, const(I64, 1)))
    return kept.get()
