"""Kernel assembly: the exported, batched C-ABI functions of one surface's LLVM module.

Signatures are declared in :mod:`implc.native.abi`. Every batched kernel walks ``n`` items (``n`` a multiple of
:data:`WIDTH`) in vectors of WIDTH lanes, reading points and boxes as row-major (n, 3) float64 arrays:

- ``implc_point(pts, out, n)``: F at each point (sin, cos, exp, log and atan2 from the C library).
- ``implc_point_fast(pts, out, n)``: the same with them from :mod:`implc.compiler.llvm.elementary` (every lane
  at once, within the bounds proven there): the walk's samples, which decide nothing a bound has to.
- ``implc_gradient(pts, out_value, out_grad, n)``: F and its analytic gradient (n, 3).
- ``implc_gradient_live(pts, out_value, out_grad, n, live)``: the same over the terms live in ``live`` (an
  i64 live-term mask valid at every point, :mod:`implc.engines.compiled.gradient_native`); the gradient equals
  ``implc_gradient``'s up to rounding where the mask holds (sin, cos and atan2 come from
  :mod:`implc.compiler.llvm.elementary`: this kernel computes normals).
- ``implc_interval(lo, hi, out_lo, out_hi, n, live_in, live_out)``: an enclosure of F over each box
  [lo, hi]. ``live_in`` holds one live-term mask (:mod:`implc.engines.compiled.plan`) per group of WIDTH boxes, the
  children of one octant: terms dead there are skipped; ``live_out`` receives each box's own mask.
  Either may be NULL: everything is live, and no mask is written.
- ``implc_interval_mvf(lo, hi, out_lo, out_hi, n)``: the same, intersected with the mean-value form
  (tighter on small boxes, about five times the work), built by :func:`build_mean_value_module`.
- ``implc_interval_monotone(...)``: the same, intersected with the monotonicity form (each bound from the
  corner where F is least or greatest along the axes where the gradient's sign is known; tight on small
  boxes the surface passes near), in the same module.
- ``implc_bound_monotone(lo, hi, side, out, n, live_in)``: one bound of that form per box, the lower where
  ``side`` > 0, else the upper (NaN where it is undefined), for one evaluation of F at a corner instead
  of two; in a small module of its own (:func:`build_bound_module`), for the voxelizer.

and, for the subdivider, the same enclosures over the eight children of one octant, generated in
vector registers from the octant's cell index:

- ``implc_octant(geom, cell, level, live_in, live_out) -> i32`` (and ``implc_octant_mvf``): ``cell`` points
  to the octant's (i, j, k) (int32) one level above ``level``; child c (x bit | y bit << 1 | z bit << 2)
  is the box [o + i·h − pad, o + (i + 1)·h + pad] per axis, i = 2·cell + bit, with the origin o, the pad and
  the cell size h of ``level`` read from ``geom`` (:data:`implc.native.abi.GEOMETRY_DOUBLES`). Returns
  bit c set where child c's enclosure contains 0 (or is undefined) and bit 8 + c where it lies below 0
  (:data:`implc.native.abi.OCTANT_INSIDE_SHIFT`); writes the children's live masks to ``live_out[8]``.
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.ir import Tape
from ...compiler.llvm import elementary
from ...compiler.llvm.control import define, for_range
from ...compiler.llvm.interval_rules import emit_interval, emit_interval_outputs
from ...compiler.llvm.point import emit_point
from ...compiler.llvm.rows import load_xyz, store_lanes, store_xyz, vector_ptr
from ...compiler.llvm.vector import DOUBLE, I64, VectorBuilder, broadcast
from ...native import abi
from .gradient_native import emit_pruned_gradient
from .interval_native import emit_interval_regions
from .mean_value_native import emit_mean_value, emit_monotone_bound, emit_monotone_form
from .plan import plan_regions
from .pruned_mean_value_native import emit_pruned_mean_value, emit_pruned_monotone_bound, emit_pruned_monotone_form

WIDTH = 8
"""Default lanes per vector: eight boxes (an octant's children) per kernel step. 1, 2 and 4 are allowed
(``implc.compile(..., vector_width=1)``), to measure what the vectors bring."""
WIDTHS = (1, 2, 4, 8)

_PTR = ir.PointerType(DOUBLE)


_PI64 = ir.PointerType(I64)


def _kernel(module, entry, width):
    """A batched kernel: its function (the arrays before ``n`` marked noalias), a builder and the number
    of vector blocks, n / width."""
    fn, builder = define(module, entry)
    before = entry.param_names.index("n")
    for arg in fn.args[:before]:
        arg.add_attribute("noalias")
    blocks = builder.sdiv(fn.args[before], ir.Constant(I64, width))
    return fn, builder, blocks


def _live_masks(builder, live_in, live_out, block, masks, width):
    """Store the boxes' live masks if live_out is not NULL."""
    with builder.if_then(builder.icmp_unsigned("!=", live_out, ir.Constant(_PI64, None))):
        offset = builder.mul(block, ir.Constant(I64, width))
        ptr = builder.bitcast(builder.gep(live_out, [offset]), ir.PointerType(masks.type))
        builder.store(masks, ptr, align=8)


def _parent_mask(builder, live_in, block, width):
    """The live mask of the octant whose children these are (one per 8 boxes), or all ones where
    live_in is NULL."""
    is_null = builder.icmp_unsigned("==", live_in, ir.Constant(_PI64, None))
    with builder.goto_entry_block():
        all_live = builder.alloca(I64)
    builder.store(ir.Constant(I64, -1), all_live)
    group = builder.sdiv(builder.mul(block, ir.Constant(I64, width)), ir.Constant(I64, 8))
    ptr = builder.select(is_null, all_live, builder.gep(live_in, [group]))
    return builder.load(ptr)


def _interval_kernel(module, entry, width, directed, outline, enclose):
    """Emit the batched kernel ``entry(lo, hi, out_lo, out_hi, n, live_in, live_out)`` over ``enclose``."""
    fn, b, blocks = _kernel(module, entry, width)
    lo, hi, out_lo, out_hi, _, live_in, live_out = fn.args
    with for_range(b, blocks) as i:
        vb = VectorBuilder(b, width, directed, outline)
        f_lo, f_hi, masks = enclose(vb, load_xyz(b, lo, i, width), load_xyz(b, hi, i, width),
                                    _parent_mask(b, live_in, i, width))
        store_lanes(b, out_lo, i, f_lo, width)
        store_lanes(b, out_hi, i, f_hi, width)
        _live_masks(b, live_in, live_out, i, masks, width)
    b.ret_void()


def _octant_kernel(module, entry, width, directed, outline, enclose):
    """Emit ``entry`` (see the module docstring); ``enclose(vb, lo, hi, live_in) -> (lo, hi, masks)``."""
    i32 = ir.IntType(32)
    fn, b = define(module, entry)
    geom, cell, level, live_in, live_out = fn.args
    vb = VectorBuilder(b, width, directed, outline)
    vb.octant_lanes = True  # lane c: child first + c (first a multiple of the width)
    ivec = ir.VectorType(i32, width)

    def read(index):
        return b.load(b.gep(geom, [index if isinstance(index, ir.Value) else ir.Constant(I64, index)]))

    origin = [broadcast(b, read(a), width) for a in range(3)]
    pad = [broadcast(b, read(3 + a), width) for a in range(3)]
    h = [broadcast(b, read(b.add(b.mul(level, ir.Constant(I64, 3)), ir.Constant(I64, 6 + a))), width) for a in range(3)]
    twice = [broadcast(b, b.shl(b.load(b.gep(cell, [ir.Constant(I64, a)])), ir.Constant(i32, 1)), width)
             for a in range(3)]
    kept = ir.Constant(i32, 0)
    for first in range(0, 8, width):
        lanes = range(first, first + width)
        lo, hi = [], []
        for a in range(3):
            index = b.add(twice[a], ir.Constant(ivec, [(c >> a) & 1 for c in lanes]))
            i_lo = b.uitofp(index, vb.vtype)
            i_hi = b.uitofp(b.add(index, ir.Constant(ivec, [1] * width)), vb.vtype)
            lo.append(vb.sub(vb.add(origin[a], vb.mul(i_lo, h[a])), pad[a]))
            hi.append(vb.add(vb.add(origin[a], vb.mul(i_hi, h[a])), pad[a]))
        f_lo, f_hi, masks = enclose(vb, lo, hi, live_in)
        zero = vb.splat(0.0)
        contains = b.and_(vb.cmp("<=", f_lo, zero), vb.cmp(">=", f_hi, zero))
        bits = b.zext(b.bitcast(contains, ir.IntType(width)), i32)
        kept = b.or_(kept, b.shl(bits, ir.Constant(i32, first)))
        below = b.zext(b.bitcast(vb.cmp("<", f_hi, zero), ir.IntType(width)), i32)  # inside (NaN: never)
        kept = b.or_(kept, b.shl(below, ir.Constant(i32, first + abi.OCTANT_INSIDE_SHIFT)))
        with b.if_then(b.icmp_unsigned("!=", live_out, ir.Constant(_PI64, None))):
            ptr = b.bitcast(b.gep(live_out, [ir.Constant(I64, first)]), ir.PointerType(masks.type))
            b.store(masks, ptr, align=8)
    b.ret(kept)


def _natural(value_tape, plan):
    """The natural enclosure, pruned by the region plan where the tape has terms to prune."""

    def enclose(vb, lo, hi, live_in):
        if plan.enabled:
            return emit_interval_regions(vb, value_tape, plan, lo, hi, live_in)
        return (*emit_interval(vb, value_tape, lo, hi), broadcast(vb.b, live_in, vb.width))
    return enclose


def build_module(value_tape: Tape, gradient_tape: Tape, name: str = "surface", width: int = WIDTH,
                 directed: bool = False) -> ir.Module:
    """The LLVM module of the point, gradient and interval kernels for a surface; ``directed``: round
    interval arithmetic with AVX-512 embedded rounding (see :class:`~implc.compiler.llvm.vector.VectorBuilder`)."""
    module = ir.Module(name=name)

    fn, b, blocks = _kernel(module, abi.POINT, width)
    pts, out, _ = fn.args
    with for_range(b, blocks) as i:
        (value,) = emit_point(VectorBuilder(b, width), value_tape, load_xyz(b, pts, i, width))
        store_lanes(b, out, i, value, width)
    b.ret_void()

    fn, b, blocks = _kernel(module, abi.POINT_FAST, width)
    pts, out, _ = fn.args
    with for_range(b, blocks) as i:
        vb = VectorBuilder(b, width, outline_elementary=elementary.outlines(value_tape))
        (value,) = emit_point(vb, value_tape, load_xyz(b, pts, i, width), vector_elementary=True)
        store_lanes(b, out, i, value, width)
    b.ret_void()

    fn, b, blocks = _kernel(module, abi.GRADIENT, width)
    pts, out_value, out_grad, _ = fn.args
    with for_range(b, blocks) as i:
        value, *grad = emit_point(VectorBuilder(b, width), gradient_tape, load_xyz(b, pts, i, width))
        store_lanes(b, out_value, i, value, width)
        store_xyz(b, out_grad, i, grad, width)
    b.ret_void()

    fn, b = define(module, abi.GRADIENT_LIVE)
    pts, out_value, out_grad, n, live = fn.args
    plan = plan_regions(value_tape)
    outline = elementary.outlines(gradient_tape)
    with for_range(b, b.sdiv(n, ir.Constant(I64, width))) as i:
        vb = VectorBuilder(b, width, outline_elementary=outline)
        if plan.fold is not None:
            value, grad = emit_pruned_gradient(vb, value_tape, plan, load_xyz(b, pts, i, width), live)
        else:  # nothing to prune; normals need no more than the vector functions' 1e-15
            value, *grad = emit_point(vb, gradient_tape, load_xyz(b, pts, i, width), vector_elementary=True)
        store_lanes(b, out_value, i, value, width)
        store_xyz(b, out_grad, i, grad, width)
    b.ret_void()

    enclose = _natural(value_tape, plan)
    _interval_kernel(module, abi.INTERVAL, width, directed, outline, enclose)
    _octant_kernel(module, abi.OCTANT, width, directed, outline, enclose)
    return module


def build_mean_value_module(value_tape: Tape, gradient_tape: Tape, name: str = "surface_mvf",
                            width: int = WIDTH, directed: bool = False) -> ir.Module:
    """The LLVM module of the mean-value and monotonicity-form kernels, a module of its own: it is about three
    times the size of the others together, so it is compiled only when first used."""
    module = ir.Module(name=name)
    plan = plan_regions(value_tape)

    def enclose(vb, lo, hi, live_in):
        if plan.fold is not None:  # over the live terms only, and each child gets its own mask
            return emit_pruned_mean_value(vb, value_tape, plan, lo, hi, live_in)
        return (*emit_mean_value(vb, value_tape, gradient_tape, lo, hi), broadcast(vb.b, live_in, vb.width))

    def monotone(vb, lo, hi, live_in):
        if plan.fold is not None:
            return emit_pruned_monotone_form(vb, value_tape, plan, lo, hi, live_in)
        return (*emit_monotone_form(vb, value_tape, gradient_tape, lo, hi), broadcast(vb.b, live_in, vb.width))
    outline = elementary.outlines(gradient_tape)
    _interval_kernel(module, abi.INTERVAL_MVF, width, directed, outline, enclose)
    _octant_kernel(module, abi.OCTANT_MVF, width, directed, outline, enclose)
    _interval_kernel(module, abi.INTERVAL_MONOTONE, width, directed, outline, monotone)
    return module


def build_bound_module(value_tape: Tape, gradient_tape: Tape, name: str = "surface_bound", width: int = WIDTH,
                       directed: bool = False) -> ir.Module:
    """The LLVM module of ``implc_bound_monotone``, the one kernel the voxelizer's second look at leaves needs,
    in a module of its own: compiled on a surface's first voxelization (a fraction of the mean-value
    module's time), or never where no voxelization asks for it."""
    module = ir.Module(name=name)
    plan = plan_regions(value_tape)
    outline = elementary.outlines(gradient_tape)
    fn, b, blocks = _kernel(module, abi.BOUND_MONOTONE, width)
    lo, hi, side, out, _, live_in = fn.args
    with for_range(b, blocks) as i:
        vb = VectorBuilder(b, width, directed, outline)
        sides = b.load(vector_ptr(b, side, b.mul(i, ir.Constant(I64, width)), width), align=8)
        lo_coords, hi_coords = load_xyz(b, lo, i, width), load_xyz(b, hi, i, width)
        above = vb.cmp(">", sides, vb.splat(0.0))
        if plan.fold is not None:
            value = emit_pruned_monotone_bound(vb, value_tape, plan, lo_coords, hi_coords,
                                               _parent_mask(b, live_in, i, width), above)
        else:
            value = emit_monotone_bound(vb, value_tape, gradient_tape, lo_coords, hi_coords, above)
        store_lanes(b, out, i, value, width)
    b.ret_void()
    return module


def build_box_gradient_module(gradient_tape: Tape, name: str = "surface_box_gradient", width: int = WIDTH,
                              directed: bool = False) -> ir.Module:
    """The LLVM module of ``implc_box_gradient``: enclosures of F and of its three partials over boxes (eight
    doubles per box: F's lo, hi, then each partial's), by the interval rules over the gradient tape; in a
    module of its own, compiled on a surface's first mesh (which proves where its cells are regular)."""
    module = ir.Module(name=name)
    fn, b, blocks = _kernel(module, abi.BOX_GRADIENT, width)
    lo, hi, out, _ = fn.args
    with for_range(b, blocks) as i:
        vb = VectorBuilder(b, width, directed, elementary.outlines(gradient_tape))
        parts = emit_interval_outputs(vb, gradient_tape, load_xyz(b, lo, i, width), load_xyz(b, hi, i, width))
        rows = b.gep(out, [b.mul(i, ir.Constant(I64, 8 * width))])
        for k, value in enumerate(v for pair in parts for v in pair):  # lane j of value k: entry k of box j
            for j in range(width):
                b.store(b.extract_element(value, ir.Constant(ir.IntType(32), j)),
                        b.gep(rows, [ir.Constant(I64, 8 * j + k)]))
    b.ret_void()
    return module
