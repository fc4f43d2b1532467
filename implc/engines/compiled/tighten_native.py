"""The second look at the leaves with a surface's compiled kernels, and the drop of the leaves a look proved.

The natural enclosure keeps every leaf whose box it cannot prove empty; the surface crosses most of
them. The normals pass flags the others worth a second look, the cells the linear model at their centre
misses (:mod:`implc.engines.normals_native`), with the side F(c) lies on. :func:`emit_tighten`'s look: for each
flagged leaf one sound test, the bound of the monotonicity form on that side over the leaf's box
(``bound``, a surface's ``implc_bound_monotone``, eight leaves per call, their live-term masks joined). A
leaf is marked :data:`OUTSIDE` (:data:`INSIDE`) when the bound proves F > 0 (F < 0) on the whole box; a NaN
bound never does. A leaf the bound leaves open is split (:mod:`implc.engines.second_look_native`: the bound over
its eighths, then theirs, with the leaf's live terms) and marked when every box at the last level is
proven, unless F at one of its corners (``point``, in floating point) already lies across 0: the surface
crosses it (most leaves the bound leaves open on smooth surfaces), and splitting it would only spend time.
The tape engine's look (:mod:`implc.engines.tape.tighten_native`) marks the same way;
``implc_drop_marked`` (:mod:`implc.engines.rows_native`) then drops what a look marked.
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import (
    I32,
    I64,
    Local,
    const,
    define_internal,
    load_at,
    local_array,
    store_at,
)
from ...native import abi
from ..second_look_native import V8, Look, emit_second_look

DOUBLE = ir.DoubleType()
I8 = ir.IntType(8)


class _KernelLook(Look):
    """The second look's tests with a surface's compiled monotonicity bound and point kernels."""

    def __init__(self, b: ir.IRBuilder, bound, point, geom, depth, masks, cells):
        self.b, self.bound, self.point, self.masks, self.cells = b, bound, point, masks, cells
        self.origin = [load_at(b, geom, a) for a in range(3)]
        self.pad = [load_at(b, geom, 3 + a) for a in range(3)]
        self.h = [load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))) for a in range(3)]
        self.lo, self.hi = local_array(b, DOUBLE, 24, "lo"), local_array(b, DOUBLE, 24, "hi")  # boxes, or points
        self.values = local_array(b, DOUBLE, 8, "values")
        self.live = local_array(b, I64, 1, "live")  # the live terms: the batch's, then the open leaf's
        self.split_sides = local_array(b, DOUBLE, 8, "split_sides")  # the open leaf's side, in every lane
        self.union = Local(b, I64, 0, "union")

    def bounds(self, factor, sides):
        """The bound over the eight boxes of the cells at ``cells`` (the leaves' size times ``factor``), on
        each box's side (``sides``), with the terms at ``live``: the lanes proven (i8)."""
        b, zero = self.b, ir.Constant(V8, [0.0] * 8)
        for j in range(8):
            for a in range(3):
                step = b.fmul(self.h[a], factor)
                c = load_at(b, self.cells, 8 * a + j)
                store_at(b, b.fsub(b.fadd(self.origin[a], b.fmul(c, step)), self.pad[a]), self.lo, 3 * j + a)
                store_at(b, b.fadd(b.fadd(self.origin[a], b.fmul(b.fadd(c, const(DOUBLE, 1.0)), step)), self.pad[a]),
                         self.hi, 3 * j + a)
        b.call(self.bound, [self.lo, self.hi, sides, self.values, const(I64, 8), self.live])
        values = b.load(b.bitcast(self.values, ir.PointerType(V8)), align=8)
        above = b.fcmp_ordered(">", b.load(b.bitcast(sides, ir.PointerType(V8)), align=8), zero)
        return b.bitcast(b.select(above, b.fcmp_ordered(">", values, zero), b.fcmp_ordered("<", values, zero)), I8)

    def first(self, cells, sides):
        store_at(self.b, self.union.get(), self.live, 0)  # the live terms of the batch's leaves, joined
        return self.bounds(const(DOUBLE, 1.0), sides)

    def flagged(self, index) -> None:
        self.union.set(self.b.or_(self.union.get(), load_at(self.b, self.masks, index)))

    def batch_done(self) -> None:
        self.union.set(const(I64, 0))

    def open(self, index, side, lane) -> None:
        b = self.b
        store_at(b, load_at(b, self.masks, index), self.live, 0)  # the leaf's own live terms
        for j in range(8):
            store_at(b, side, self.split_sides, j)

    def crossed(self, leaf, side):
        b, zero = self.b, ir.Constant(V8, [0.0] * 8)
        for j in range(8):
            for a in range(3):
                corner = b.fadd(leaf[a], const(DOUBLE, float((j >> a) & 1)))
                store_at(b, b.fadd(self.origin[a], b.fmul(corner, self.h[a])), self.lo, 3 * j + a)
        b.call(self.point, [self.lo, self.values, const(I64, 8)])
        values = b.load(b.bitcast(self.values, ir.PointerType(V8)), align=8)
        above = b.fcmp_ordered(">", side, const(DOUBLE, 0.0))
        across = b.select(above, b.fcmp_ordered("<", values, zero), b.fcmp_ordered(">", values, zero))
        return b.icmp_unsigned("!=", b.bitcast(across, I8), const(I8, 0))

    def prove(self, factor, level):
        return self.bounds(factor, self.split_sides)


def emit_tighten(module: ir.Module) -> ir.Function:
    """``kernel.tighten(bound, point, geom, depth, coords, masks, flags, n)`` (internal): the second look
    (:func:`~implc.engines.second_look_native.emit_second_look`) at the flagged ones of the ``n`` leaves at
    ``coords`` (cells at ``depth``, their live-term masks at ``masks``) with the monotonicity bound."""
    p = ir.PointerType
    fn, b = define_internal(module, "implc.kernel.tighten", ir.VoidType(),
                            [p(I8), p(I8), p(DOUBLE), I64, p(I32), p(I64), p(I8), I64])
    bound_ptr, point_ptr, geom, depth, coords, masks, flags, n = fn.args
    bound = b.bitcast(bound_ptr, ir.PointerType(abi.BOUND_MONOTONE.llvm_type()))
    point = b.bitcast(point_ptr, ir.PointerType(abi.POINT.llvm_type()))
    cells = local_array(b, DOUBLE, 24, "cells")  # the boxes' cells, axis by axis (at the leaves, or below)
    emit_second_look(b, coords, flags, n, _KernelLook(b, bound, point, geom, depth, masks, cells), cells)
    b.ret_void()
    return fn
