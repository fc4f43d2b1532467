"""Unit normals at voxel centres, computed natively for a block of voxels at a time.

:func:`emit_normals_body` is the pass over any evaluator's gradients; :func:`emit_normals` over a surface's
compiled kernels (the walk's, :mod:`implc.engines.compiled.evaluator_native`). It calls the gradient over the terms live
in the voxels' cells (where masks are given), normalises in vector registers when every gradient of a
block of eight is usable, and otherwise falls back to central differences and then to a fixed direction: a
normal is never NaN, never zero.

Where ``flags`` is not NULL it also marks, with the value and gradient it has anyway, each voxel whose
cell the linear model at its centre does not cross: |F(c)| > Σ |∂F/∂xᵢ(c)|·hᵢ/2 (flag
:data:`implc.native.abi.TIGHTEN_ABOVE` where F(c) > 0, :data:`implc.native.abi.TIGHTEN_BELOW` where F(c) < 0, else 0).
Those are the cells :mod:`implc.engines.compiled.tighten_native` tries to drop; a flag is a choice of work, never a
proof.
"""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import (
    I32,
    I64,
    Local,
    at,
    const,
    define_internal,
    for_range,
    if_,
    intrinsic,
    load_at,
    local_array,
    store_at,
)
from ..compiler.llvm.vector import broadcast
from ..native import abi

DOUBLE = ir.DoubleType()
FLOAT = ir.FloatType()


def emit_normals(module: ir.Module) -> ir.Function:
    """``kernel.normals(gradient_live, point, leaf_geom, coords, masks, n, out, flags)`` (internal): the
    normals of ``n`` voxels through a surface's compiled gradient (over the live terms of ``masks``, one
    per voxel) and point kernels; ``leaf_geom``: the origin, then the voxels' size."""
    p = ir.PointerType
    fn, b = define_internal(module, "implc.kernel.normals", ir.VoidType(),
                            [p(ir.IntType(8)), p(ir.IntType(8)), p(DOUBLE), p(I32), p(I64), I64, p(FLOAT),
                             p(ir.IntType(8))])
    grad_ptr, point_ptr, geom, coords, masks, n, out, flags = fn.args
    grad_fn = b.bitcast(grad_ptr, ir.PointerType(abi.GRADIENT_LIVE.llvm_type()))
    point_fn = b.bitcast(point_ptr, ir.PointerType(abi.POINT.llvm_type()))
    emit_normals_body(b, geom, coords, masks, n, out,
                      lambda pts, values, grad, live: b.call(grad_fn, [pts, values, grad, const(I64, 8), live]),
                      lambda probe, probe_values: b.call(point_fn, [probe, probe_values, const(I64, 48)]),
                      flags)
    b.ret_void()
    return fn


def emit_normals_body(b: ir.IRBuilder, geom, coords, masks, n, out, gradient_at, values_at, flags=None):
    """The normals of ``n`` voxels at ``coords`` into ``out``, emitted at ``b``: ``gradient_at(pts, values,
    grad, live)`` emits F and its gradient at eight points (24 interleaved doubles; ``live`` the union of
    their cells' masks, all ones where ``masks`` is NULL), ``values_at(probe, probe_values)`` F at 48.
    ``flags`` (i8*, may be NULL at run time; None: not emitted): each voxel's linear-model flag."""
    module = b.module
    origin = [load_at(b, geom, a) for a in range(3)]
    h = [load_at(b, geom, 3 + a) for a in range(3)]
    maxnum = intrinsic(module, "llvm.maxnum.f64", 2)
    hmax = b.call(maxnum, [b.call(maxnum, h[:2]), h[2]])
    near_origin = b.fmul(b.fmul(hmax, hmax), const(DOUBLE, 4.0))  # r < 2 voxels: the 1/r blow-up zone
    sqrt = intrinsic(module, "llvm.sqrt.f64", 1)
    pts = local_array(b, DOUBLE, 24, "pts")
    values = local_array(b, DOUBLE, 8, "values")
    grad = local_array(b, DOUBLE, 24, "grad")
    probe = local_array(b, DOUBLE, 48 * 3, "probe")
    probe_values = local_array(b, DOUBLE, 48, "probe_values")
    need = Local(b, ir.IntType(1), 0, "need")
    zero, inf = const(DOUBLE, 0.0), const(DOUBLE, float("inf"))
    last = b.sub(n, const(I64, 1))
    blocks = b.sdiv(b.add(n, const(I64, 7)), const(I64, 8))
    has_masks = b.icmp_unsigned("!=", masks, ir.Constant(ir.PointerType(I64), None))
    masks = b.select(has_masks, masks, local_array(b, I64, 8, "no_masks"))  # read, unused, at 0..7

    def lane(j, a):
        """Index of axis ``a`` of lane ``j`` (an i64) in an interleaved block."""
        return b.add(b.mul(j, const(I64, 3)), const(I64, a))

    def usable(n2):
        return b.and_(b.fcmp_ordered(">", n2, zero), b.fcmp_ordered("<", n2, inf))

    def norm2(v):
        return b.fadd(b.fadd(b.fmul(v[0], v[0]), b.fmul(v[1], v[1])), b.fmul(v[2], v[2]))

    v24 = ir.VectorType(DOUBLE, 24)
    origin24 = ir.Constant(v24, ir.Undefined)
    h24 = ir.Constant(v24, ir.Undefined)
    for k in range(24):
        origin24 = b.insert_element(origin24, origin[k % 3], const(I32, k))
        h24 = b.insert_element(h24, h[k % 3], const(I32, k))
    or_reduce = module.globals.get("llvm.vector.reduce.or.v8i64") or ir.Function(
        module, ir.FunctionType(I64, [ir.VectorType(I64, 8)]), name="llvm.vector.reduce.or.v8i64")
    live = Local(b, I64, 0, "live")  # the terms live in any of a block's eight cells
    with for_range(b, blocks) as block:
        full = b.icmp_signed("<=", b.mul(b.add(block, const(I64, 1)), const(I64, 8)), n)
        with b.if_else(full) as (whole, tail):
            with whole:  # eight voxels: their 24 coordinates and 8 masks as vectors
                cells = b.load(b.bitcast(at(b, coords, b.mul(block, const(I64, 24))),
                                         ir.PointerType(ir.VectorType(I32, 24))), align=4)
                centres = b.fadd(origin24, b.fmul(b.fadd(b.uitofp(cells, v24), ir.Constant(v24, [0.5] * 24)), h24))
                b.store(centres, b.bitcast(pts, ir.PointerType(v24)), align=8)
                row = b.bitcast(at(b, masks, b.select(has_masks, b.mul(block, const(I64, 8)), const(I64, 0))),
                                ir.PointerType(ir.VectorType(I64, 8)))
                live.set(b.select(has_masks, b.call(or_reduce, [b.load(row, align=8)]), const(I64, -1)))
            with tail:  # lanes past the end repeat the last voxel (a loop: rare, and small code)
                union = Local(b, I64, 0, "union")
                with for_range(b, const(I64, 8)) as j:
                    slot = b.add(b.mul(block, const(I64, 8)), j)
                    idx = b.select(b.icmp_signed(">", slot, last), last, slot)
                    for a in range(3):
                        c = b.uitofp(load_at(b, coords, b.add(b.mul(idx, const(I64, 3)), const(I64, a))), DOUBLE)
                        centre = b.fadd(origin[a], b.fmul(b.fadd(c, const(DOUBLE, 0.5)), h[a]))
                        store_at(b, centre, pts, lane(j, a))
                    union.set(b.or_(union.get(), load_at(b, masks, b.select(has_masks, idx, const(I64, 0)))))
                live.set(b.select(has_masks, union.get(), const(I64, -1)))
        gradient_at(pts, values, grad, live.get())
        # the common case in vector registers: every gradient usable, a full block of 8
        v8 = ir.VectorType(DOUBLE, 8)
        rows = b.load(b.bitcast(grad, ir.PointerType(ir.VectorType(DOUBLE, 24))), align=8)
        centres = b.load(b.bitcast(pts, ir.PointerType(ir.VectorType(DOUBLE, 24))), align=8)

        def axis(vec, a):
            return b.shuffle_vector(vec, ir.Constant(vec.type, ir.Undefined),
                                    ir.Constant(ir.VectorType(I32, 8), [3 * j + a for j in range(8)]))
        g8 = [axis(rows, a) for a in range(3)]
        c8 = [axis(centres, a) for a in range(3)]
        if flags is not None:
            _store_flags(b, flags, block, n, values, g8, h)
        n2 = norm2(g8)
        good = b.and_(b.and_(b.fcmp_ordered(">", n2, ir.Constant(v8, [0.0] * 8)),
                             b.fcmp_ordered("<", n2, ir.Constant(v8, [float("inf")] * 8))),
                      b.fcmp_ordered(">=", norm2(c8), broadcast(b, near_origin, 8)))
        all_good = b.icmp_unsigned("==", b.bitcast(good, ir.IntType(8)), ir.Constant(ir.IntType(8), 0xFF))
        full = b.icmp_signed("<=", b.mul(b.add(block, const(I64, 1)), const(I64, 8)), n)
        with b.if_else(b.and_(all_good, full)) as (fast, slow):
            with fast:
                length = b.call(intrinsic(module, "llvm.sqrt.v8f64", 1, v8), [n2])
                unit = [b.fptrunc(b.fdiv(g, length), ir.VectorType(FLOAT, 8)) for g in g8]
                pair = b.shuffle_vector(unit[0], unit[1], ir.Constant(ir.VectorType(I32, 16), list(range(16))))
                third = b.shuffle_vector(unit[2], ir.Constant(unit[2].type, ir.Undefined),
                                         ir.Constant(ir.VectorType(I32, 16), list(range(8)) + [0] * 8))
                order = [8 * a + j if a < 2 else 16 + j for j in range(8) for a in range(3)]
                interleaved = b.shuffle_vector(pair, third, ir.Constant(ir.VectorType(I32, 24), order))
                target = at(b, out, b.mul(block, const(I64, 24)))
                b.store(interleaved, b.bitcast(target, ir.PointerType(ir.VectorType(FLOAT, 24))), align=4)
            with slow:  # fallbacks, lane by lane (loops: rare, and small code)
                need.set(const(ir.IntType(1), 0))
                with for_range(b, const(I64, 8)) as j:
                    g = [load_at(b, grad, lane(j, a)) for a in range(3)]
                    centre = [load_at(b, pts, lane(j, a)) for a in range(3)]
                    bad = b.or_(b.not_(usable(norm2(g))), b.fcmp_ordered("<", norm2(centre), near_origin))
                    need.set(b.or_(need.get(), bad))
                with if_(b, need.get()):  # central differences, half a voxel each way, for the whole block
                    for a in range(3):
                        for s, sign in enumerate((1.0, -1.0)):
                            with for_range(b, const(I64, 8)) as j:
                                for k in range(3):
                                    v = load_at(b, pts, lane(j, k))
                                    if k == a:
                                        v = b.fadd(v, b.fmul(h[a], const(DOUBLE, 0.5 * sign)))
                                    store_at(b, v, probe, b.add(b.mul(b.add(j, const(I64, (2 * a + s) * 8)),
                                                                      const(I64, 3)), const(I64, k)))
                    values_at(probe, probe_values)
                with for_range(b, const(I64, 8)) as j:
                    g = [Local(b, DOUBLE, load_at(b, grad, lane(j, a))) for a in range(3)]
                    centre = [load_at(b, pts, lane(j, a)) for a in range(3)]
                    r2 = norm2(centre)
                    bad = b.or_(b.not_(usable(norm2([v.get() for v in g]))), b.fcmp_ordered("<", r2, near_origin))
                    with if_(b, bad):
                        for a in range(3):
                            up = load_at(b, probe_values, b.add(j, const(I64, (2 * a) * 8)))
                            down = load_at(b, probe_values, b.add(j, const(I64, (2 * a + 1) * 8)))
                            g[a].set(b.fdiv(b.fsub(up, down), h[a]))
                    with if_(b, b.not_(usable(norm2([v.get() for v in g])))):  # flat or undefined: point outward
                        radial = usable(r2)
                        for a in range(3):
                            g[a].set(b.select(radial, centre[a], const(DOUBLE, 1.0 if a == 2 else 0.0)))
                    length = b.call(sqrt, [norm2([v.get() for v in g])])
                    index = b.add(b.mul(block, const(I64, 8)), j)
                    with if_(b, b.icmp_signed("<", index, n)):
                        for a in range(3):
                            unit = b.fptrunc(b.fdiv(g[a].get(), length), FLOAT)
                            store_at(b, unit, out, b.add(b.mul(index, const(I64, 3)), const(I64, a)))

def _store_flags(b: ir.IRBuilder, flags, block, n, values, g8, h):
    """Flag where |F(c)| > Σ |gᵢ|·hᵢ/2 (the linear model at the centre misses the cell; NaN: no flag),
    by F(c)'s side, for the block's voxels below ``n``."""
    v8 = ir.VectorType(DOUBLE, 8)
    fabs = intrinsic(b.module, "llvm.fabs.v8f64", 1, v8)
    with if_(b, b.icmp_unsigned("!=", flags, ir.Constant(flags.type, None))):
        value = b.load(b.bitcast(values, ir.PointerType(v8)), align=8)
        reach = ir.Constant(v8, [0.0] * 8)
        for a in range(3):
            reach = b.fadd(reach, b.fmul(b.call(fabs, [g8[a]]), broadcast(b, b.fmul(h[a], const(DOUBLE, 0.5)), 8)))
        i8x8 = ir.VectorType(ir.IntType(8), 8)
        side = b.select(b.fcmp_ordered(">", value, ir.Constant(v8, [0.0] * 8)),
                        ir.Constant(i8x8, [abi.TIGHTEN_ABOVE] * 8), ir.Constant(i8x8, [abi.TIGHTEN_BELOW] * 8))
        missed = b.select(b.fcmp_ordered(">", b.call(fabs, [value]), reach), side, ir.Constant(i8x8, [0] * 8))
        for j in range(8):
            index = b.add(b.mul(block, const(I64, 8)), const(I64, j))
            with if_(b, b.icmp_signed("<", index, n)):
                store_at(b, b.extract_element(missed, const(I32, j)), flags, index)
