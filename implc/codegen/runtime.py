"""The generic native routines, one LLVM module shared by every surface.

- ``implc_subdivide``: Fig. 1 of the paper as a loop over an explicit stack. It calls a surface's
  octant kernel (``implc_octant``: the eight children of an octant, generated and enclosed in vector
  registers) through a function pointer (a second, finer kernel, e.g. the mean-value form, from a
  given child level on; optionally a leaf is kept only if one of its eight halves-per-axis may meet the
  surface), prunes children whose enclosure excludes 0, pushes the rest in reverse so that leaves come
  out in Morton order, and writes leaf coordinates with their live-term masks. It is resumable: when the output buffer is full or the
  cancel flag is raised it returns with its stack intact.
- ``implc_normals``: unit normals at voxel centres from a surface's gradient kernel (over the terms live
  in the voxels' cells where their masks are given), with central differences and then a fixed
  direction as fallbacks (never NaN, never zero).
- ``implc_octree_insert``: Fig. 2, insertion of Morton-ordered voxels into an index-based octree that
  starts from the previous voxel's path and ascends only to the common parent; it clears each node it
  creates, so the node array may be reserved uninitialised.
- ``implc_octree_traverse``: Fig. 6, depth-first traversal yielding the nodes of one level in order.
- ``implc_splat``: z-buffered square splats for the point renderer (nearest point wins each pixel).
"""

from __future__ import annotations

from llvmlite import ir

from .control import I32, I64, Local, const, for_range, if_, local_array, while_true
from .vector import broadcast

DOUBLE = ir.DoubleType()
FLOAT = ir.FloatType()
VOID = ir.VoidType()
I8P = ir.PointerType(ir.IntType(8))
PD = ir.PointerType(DOUBLE)
PF = ir.PointerType(FLOAT)
PI32 = ir.PointerType(I32)
PI64 = ir.PointerType(I64)

MAX_DEPTH = 21
STACK_ENTRIES = 7 * (MAX_DEPTH + 1) + 8
"""Depth-first stack bound: at most 7 pending siblings per level plus one octant's 8 children."""

GEOMETRY_DOUBLES = 6 + 3 * (MAX_DEPTH + 2)
"""Subdivision geometry: origin (3), outward pad (3), then cell size per level (3 per level, one level
past the deepest grid for leaf refinement)."""

# octree state layout (i64 words)
NODE_COUNT, DEPTH, STARTED, PREV = 0, 1, 2, 3
LEVEL_COUNTS = 8
PATH = LEVEL_COUNTS + MAX_DEPTH + 2
OCTREE_STATE_WORDS = PATH + MAX_DEPTH + 2

OCTANT_FN = ir.FunctionType(I32, [PD, PI32, I64, I64, PI64])  # implc.codegen.kernels: implc_octant
GRADIENT_FN = ir.FunctionType(VOID, [PD, PD, PD, I64, I64])  # implc_gradient_live
POINT_FN = ir.FunctionType(VOID, [PD, PD, I64])

SIGNATURES = {
    "implc_subdivide": (I64, [I8P, I8P, I64, I64, I64, PD, PI32, PI64, PI64, PI32, PI64, I64, PI64, PI32]),
    "implc_normals": (VOID, [I8P, I8P, PD, PI32, PI64, I64, PF]),
    "implc_octree_insert": (I64, [PI32, I64, PI64, PI32, I64, I64]),
    "implc_octree_traverse": (I64, [PI32, I64, I64, PI32, PI64]),
    "implc_splat": (VOID, [PI64, PI64, PI64, PD, I64, I64, PD, PI64]),
}


def _function(module, name):
    ret, args = SIGNATURES[name]
    fn = ir.Function(module, ir.FunctionType(ret, args), name=name)
    return fn, ir.IRBuilder(fn.append_basic_block("entry"))


def _at(b, ptr, index):
    return b.gep(ptr, [index if isinstance(index, ir.Value) else const(I64, index)], inbounds=True)


def _load(b, ptr, index):
    return b.load(_at(b, ptr, index))


def _store(b, value, ptr, index):
    b.store(value, _at(b, ptr, index))


def _bump(b, ptr, index, amount=1):
    slot = _at(b, ptr, index)
    b.store(b.add(b.load(slot), const(I64, amount)), slot)


def _subdivide(module):
    fn, b = _function(module, "implc_subdivide")
    box_ptr, fine_ptr, fine_level, prune, refine, geom, stack, masks, state, out, out_masks, cap, stats, cancel = fn.args
    box = b.bitcast(box_ptr, ir.PointerType(OCTANT_FN))
    fine = b.bitcast(fine_ptr, ir.PointerType(OCTANT_FN))
    depth = b.trunc(_load(b, state, 1), I32)
    size = Local(b, I64, _load(b, state, 0), "size")
    count = Local(b, I64, 0, "count")
    child_masks = local_array(b, I64, 8, "child_masks")
    sub_cell = local_array(b, I32, 3, "sub_cell")
    pruning = b.icmp_signed("!=", prune, const(I64, 0))
    refining = b.icmp_signed("!=", refine, const(I64, 0))
    null64 = ir.Constant(PI64, None)
    all_live = const(I64, -1)

    with while_true(b) as loop:
        s = size.get()
        loop.break_if(b.icmp_signed("==", s, const(I64, 0)))
        flag = b.load_atomic(cancel, "monotonic", 4)
        loop.break_if(b.icmp_signed("!=", flag, const(I32, 0)))
        top = b.mul(b.sub(s, const(I64, 1)), const(I64, 4))
        cell = [_load(b, stack, b.add(top, const(I64, a))) for a in range(3)]
        child_level = b.add(_load(b, stack, b.add(top, const(I64, 3))), const(I32, 1))
        leaf = b.icmp_signed("==", child_level, depth)
        no_room = b.icmp_signed(">", b.add(count.get(), const(I64, 8)), cap)
        loop.break_if(b.and_(leaf, no_room))
        size.set(b.sub(s, const(I64, 1)))
        parent_mask = b.select(pruning, _load(b, masks, b.sub(s, const(I64, 1))), all_live)

        level64 = b.zext(child_level, I64)
        children = [[b.add(b.shl(cell[a], const(I32, 1)), const(I32, (c >> a) & 1)) for a in range(3)]
                    for c in range(8)]
        kernel = b.select(b.icmp_signed(">=", level64, fine_level), fine, box)
        kept = b.call(kernel, [geom, _at(b, stack, top), level64, parent_mask, child_masks])
        _bump(b, stats, 0, 8)
        stat_slot = b.add(level64, const(I64, 1))

        def keep(c):
            return b.trunc(b.lshr(kept, const(I32, c)), ir.IntType(1))

        def child_mask(c):
            return b.select(pruning, _load(b, child_masks, c), all_live)

        def refined_keep(c):
            """Whether some eighth of leaf c may meet the surface (one more level, for tightness)."""
            for a in range(3):
                _store(b, children[c][a], sub_cell, a)
            sub_kept = b.call(kernel, [geom, sub_cell, b.add(level64, const(I64, 1)), child_mask(c), null64])
            _bump(b, stats, 0, 8)
            return b.icmp_unsigned("!=", sub_kept, const(I32, 0))

        ctpop = module.globals.get("llvm.ctpop.i32") or ir.Function(
            module, ir.FunctionType(I32, [I32]), name="llvm.ctpop.i32")

        def append(array, masks_array, n, c, width):
            """Write child c at slot n whether it is kept or not; the next slot is n + its keep bit
            (branch-free: which children survive is unpredictable)."""
            for a in range(3):
                _store(b, children[c][a], array, b.add(b.mul(n, const(I64, width)), const(I64, a)))
            if width == 4:
                _store(b, child_level, array, b.add(b.mul(n, const(I64, 4)), const(I64, 3)))
            _store(b, child_mask(c), masks_array, n)
            return b.add(n, b.zext(keep(c), I64))

        with b.if_else(b.and_(leaf, refining)) as (refined, plain):
            with refined:  # emit the kept leaves that pass refinement, in Morton order
                for c in range(8):
                    with if_(b, keep(c)):
                        with if_(b, refined_keep(c)):
                            n = count.get()
                            for a in range(3):
                                _store(b, children[c][a], out, b.add(b.mul(n, const(I64, 3)), const(I64, a)))
                            _store(b, child_mask(c), out_masks, n)
                            count.set(b.add(n, const(I64, 1)))
                            _bump(b, stats, stat_slot)
            with plain:
                slot = _at(b, stats, stat_slot)
                b.store(b.add(b.load(slot), b.zext(b.call(ctpop, [kept]), I64)), slot)
                with b.if_else(leaf) as (then, otherwise):
                    with then:  # kept leaves in Morton order, each with its live mask (for the normals)
                        n = count.get()
                        for c in range(8):
                            n = append(out, out_masks, n, c, 3)
                        count.set(n)
                    with otherwise:  # kept octants pushed in reverse, so child 0 is popped first
                        t = size.get()
                        for c in reversed(range(8)):
                            t = append(stack, masks, t, c, 4)
                        size.set(t)
    _store(b, size.get(), state, 0)
    b.ret(count.get())


def _normals(module):
    fn, b = _function(module, "implc_normals")
    grad_ptr, point_ptr, geom, coords, masks, n, out = fn.args
    grad_fn = b.bitcast(grad_ptr, ir.PointerType(GRADIENT_FN))
    point_fn = b.bitcast(point_ptr, ir.PointerType(POINT_FN))
    origin = [_load(b, geom, a) for a in range(3)]
    h = [_load(b, geom, 3 + a) for a in range(3)]
    hmax = b.call(_intrinsic(module, "llvm.maxnum.f64", 2), [b.call(_intrinsic(module, "llvm.maxnum.f64", 2), h[:2]), h[2]])
    near_origin = b.fmul(b.fmul(hmax, hmax), const(DOUBLE, 4.0))  # r < 2 voxels: the 1/r blow-up zone
    sqrt = _intrinsic(module, "llvm.sqrt.f64", 1)
    pts = local_array(b, DOUBLE, 24, "pts")
    values = local_array(b, DOUBLE, 8, "values")
    grad = local_array(b, DOUBLE, 24, "grad")
    probe = local_array(b, DOUBLE, 48 * 3, "probe")
    probe_values = local_array(b, DOUBLE, 48, "probe_values")
    need = Local(b, ir.IntType(1), 0, "need")
    zero, inf = const(DOUBLE, 0.0), const(DOUBLE, float("inf"))
    last = b.sub(n, const(I64, 1))
    blocks = b.sdiv(b.add(n, const(I64, 7)), const(I64, 8))
    has_masks = b.icmp_unsigned("!=", masks, ir.Constant(PI64, None))
    masks = b.select(has_masks, masks, local_array(b, I64, 8, "no_masks"))  # read, unused, at 0..7

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
                cells = b.load(b.bitcast(_at(b, coords, b.mul(block, const(I64, 24))),
                                         ir.PointerType(ir.VectorType(I32, 24))), align=4)
                centres = b.fadd(origin24, b.fmul(b.fadd(b.uitofp(cells, v24), ir.Constant(v24, [0.5] * 24)), h24))
                b.store(centres, b.bitcast(pts, ir.PointerType(v24)), align=8)
                row = b.bitcast(_at(b, masks, b.select(has_masks, b.mul(block, const(I64, 8)), const(I64, 0))),
                                ir.PointerType(ir.VectorType(I64, 8)))
                live.set(b.select(has_masks, b.call(or_reduce, [b.load(row, align=8)]), const(I64, -1)))
            with tail:  # lanes past the end repeat the last voxel
                union = const(I64, 0)
                for j in range(8):
                    idx = b.select(b.icmp_signed(">", b.add(b.mul(block, const(I64, 8)), const(I64, j)), last), last,
                                   b.add(b.mul(block, const(I64, 8)), const(I64, j)))
                    for a in range(3):
                        c = b.uitofp(_load(b, coords, b.add(b.mul(idx, const(I64, 3)), const(I64, a))), DOUBLE)
                        centre = b.fadd(origin[a], b.fmul(b.fadd(c, const(DOUBLE, 0.5)), h[a]))
                        _store(b, centre, pts, 3 * j + a)
                    union = b.or_(union, _load(b, masks, b.select(has_masks, idx, const(I64, 0))))
                live.set(b.select(has_masks, union, const(I64, -1)))
        b.call(grad_fn, [pts, values, grad, const(I64, 8), live.get()])
        # the common case in vector registers: every gradient usable, a full block of 8
        v8 = ir.VectorType(DOUBLE, 8)
        rows = b.load(b.bitcast(grad, ir.PointerType(ir.VectorType(DOUBLE, 24))), align=8)
        centres = b.load(b.bitcast(pts, ir.PointerType(ir.VectorType(DOUBLE, 24))), align=8)

        def axis(vec, a):
            return b.shuffle_vector(vec, ir.Constant(vec.type, ir.Undefined),
                                    ir.Constant(ir.VectorType(I32, 8), [3 * j + a for j in range(8)]))
        g8 = [axis(rows, a) for a in range(3)]
        c8 = [axis(centres, a) for a in range(3)]
        n2 = norm2(g8)
        good = b.and_(b.and_(b.fcmp_ordered(">", n2, ir.Constant(v8, [0.0] * 8)),
                             b.fcmp_ordered("<", n2, ir.Constant(v8, [float("inf")] * 8))),
                      b.fcmp_ordered(">=", norm2(c8), broadcast(b, near_origin, 8)))
        all_good = b.icmp_unsigned("==", b.bitcast(good, ir.IntType(8)), ir.Constant(ir.IntType(8), 0xFF))
        full = b.icmp_signed("<=", b.mul(b.add(block, const(I64, 1)), const(I64, 8)), n)
        with b.if_else(b.and_(all_good, full)) as (fast, slow):
            with fast:
                length = b.call(_intrinsic(module, "llvm.sqrt.v8f64", 1, v8), [n2])
                unit = [b.fptrunc(b.fdiv(g, length), ir.VectorType(FLOAT, 8)) for g in g8]
                pair = b.shuffle_vector(unit[0], unit[1], ir.Constant(ir.VectorType(I32, 16), list(range(16))))
                third = b.shuffle_vector(unit[2], ir.Constant(unit[2].type, ir.Undefined),
                                         ir.Constant(ir.VectorType(I32, 16), list(range(8)) + [0] * 8))
                order = [8 * a + j if a < 2 else 16 + j for j in range(8) for a in range(3)]
                interleaved = b.shuffle_vector(pair, third, ir.Constant(ir.VectorType(I32, 24), order))
                target = _at(b, out, b.mul(block, const(I64, 24)))
                b.store(interleaved, b.bitcast(target, ir.PointerType(ir.VectorType(FLOAT, 24))), align=4)
            with slow:  # fallbacks, lane by lane
                need.set(const(ir.IntType(1), 0))
                for j in range(8):
                    g = [_load(b, grad, 3 * j + a) for a in range(3)]
                    centre = [_load(b, pts, 3 * j + a) for a in range(3)]
                    bad = b.or_(b.not_(usable(norm2(g))), b.fcmp_ordered("<", norm2(centre), near_origin))
                    need.set(b.or_(need.get(), bad))
                with if_(b, need.get()):  # central differences, half a voxel each way, for the whole block
                    for a in range(3):
                        for s, sign in enumerate((1.0, -1.0)):
                            for j in range(8):
                                for k in range(3):
                                    v = _load(b, pts, 3 * j + k)
                                    if k == a:
                                        v = b.fadd(v, b.fmul(h[a], const(DOUBLE, 0.5 * sign)))
                                    _store(b, v, probe, ((2 * a + s) * 8 + j) * 3 + k)
                    b.call(point_fn, [probe, probe_values, const(I64, 48)])
                for j in range(8):
                    g = [Local(b, DOUBLE, _load(b, grad, 3 * j + a)) for a in range(3)]
                    centre = [_load(b, pts, 3 * j + a) for a in range(3)]
                    r2 = norm2(centre)
                    bad = b.or_(b.not_(usable(norm2([v.get() for v in g]))), b.fcmp_ordered("<", r2, near_origin))
                    with if_(b, bad):
                        for a in range(3):
                            up = _load(b, probe_values, (2 * a) * 8 + j)
                            down = _load(b, probe_values, (2 * a + 1) * 8 + j)
                            g[a].set(b.fdiv(b.fsub(up, down), h[a]))
                    with if_(b, b.not_(usable(norm2([v.get() for v in g])))):  # flat or undefined: point outward
                        radial = usable(r2)
                        for a in range(3):
                            g[a].set(b.select(radial, centre[a], const(DOUBLE, 1.0 if a == 2 else 0.0)))
                    length = b.call(sqrt, [norm2([v.get() for v in g])])
                    index = b.add(b.mul(block, const(I64, 8)), const(I64, j))
                    with if_(b, b.icmp_signed("<", index, n)):
                        for a in range(3):
                            unit = b.fptrunc(b.fdiv(g[a].get(), length), FLOAT)
                            _store(b, unit, out, b.add(b.mul(index, const(I64, 3)), const(I64, a)))
    b.ret_void()


def _intrinsic(module, name, arity, type_=DOUBLE):
    fn = module.globals.get(name)
    if fn is None:
        fn = ir.Function(module, ir.FunctionType(type_, [type_] * arity), name=name)
    return fn


def _child_index(b, xyz, bit):
    """Child slot (x bit | y bit << 1 | z bit << 2) of coordinates xyz at bit position ``bit``."""
    slot = const(I32, 0)
    for a in range(3):
        slot = b.or_(slot, b.shl(b.and_(b.lshr(xyz[a], bit), const(I32, 1)), const(I32, a)))
    return b.zext(slot, I64)


def _copy(b, src, src_at, dst, dst_at, count):
    with for_range(b, const(I64, count)) as i:
        _store(b, _load(b, src, b.add(i, const(I64, src_at))), dst, b.add(i, const(I64, dst_at)))


def _octree_insert(module):
    fn, b = _function(module, "implc_octree_insert")
    nodes, node_cap, state, coords, n, first_index = fn.args
    for arg in (nodes, state, coords):
        arg.add_attribute("noalias")
    ctlz = module.globals.get("llvm.ctlz.i32") or ir.Function(
        module, ir.FunctionType(I32, [I32, ir.IntType(1)]), name="llvm.ctlz.i32")
    depth = _load(b, state, DEPTH)
    depth32 = b.trunc(depth, I32)
    # the state lives in locals (registers, a stack-resident path) during the call, written back at the end
    node_count = Local(b, I64, _load(b, state, NODE_COUNT), "node_count")
    started = Local(b, ir.IntType(1), b.icmp_signed("!=", _load(b, state, STARTED), const(I64, 0)), "started")
    prev = [Local(b, I32, b.trunc(_load(b, state, PREV + a), I32), f"prev{a}") for a in range(3)]
    levels = MAX_DEPTH + 2
    path = local_array(b, I64, levels, "path")
    counts = local_array(b, I64, levels, "counts")
    _copy(b, state, PATH, path, 0, levels)
    _copy(b, state, LEVEL_COUNTS, counts, 0, levels)
    inserted = Local(b, I64, 0, "inserted")
    with while_true(b) as loop:
        v = inserted.get()
        loop.break_if(b.icmp_signed(">=", v, n))
        xyz = [_load(b, coords, b.add(b.mul(v, const(I64, 3)), const(I64, a))) for a in range(3)]
        diff = b.or_(b.or_(b.xor(xyz[0], prev[0].get()), b.xor(xyz[1], prev[1].get())), b.xor(xyz[2], prev[2].get()))
        # the deepest level whose node is shared with the previous voxel (Fig. 2's ascent)
        top_bit = b.sub(const(I32, 31), b.call(ctlz, [diff, const(ir.IntType(1), 0)]))
        shared = b.select(b.icmp_signed("==", diff, const(I32, 0)), b.sub(depth32, const(I32, 1)),
                          b.sub(b.sub(depth32, const(I32, 1)), top_bit))
        start = b.zext(b.select(started.get(), shared, const(I32, 0)), I64)
        # room for the nodes this voxel may create (levels start+1 .. depth-1)
        needed = b.sub(b.sub(depth, const(I64, 1)), start)
        loop.break_if(b.icmp_signed(">", b.add(node_count.get(), needed), node_cap))
        with for_range(b, b.sub(depth, const(I64, 1)), start=start) as level:  # descend, creating nodes
            bit = b.trunc(b.sub(b.sub(depth, const(I64, 1)), level), I32)
            slot = b.add(b.mul(_load(b, path, level), const(I64, 8)), _child_index(b, xyz, bit))
            entry = Local(b, I32, _load(b, nodes, slot))
            with if_(b, b.icmp_signed("==", entry.get(), const(I32, 0))):
                fresh = node_count.get()
                row = b.bitcast(_at(b, nodes, b.mul(fresh, const(I64, 8))), ir.PointerType(ir.VectorType(I32, 8)))
                b.store(ir.Constant(ir.VectorType(I32, 8), [0] * 8), row, align=4)  # rows arrive uninitialised
                entry.set(b.trunc(fresh, I32))
                _store(b, entry.get(), nodes, slot)
                node_count.set(b.add(fresh, const(I64, 1)))
                _bump(b, counts, b.add(level, const(I64, 1)))
            _store(b, b.sext(entry.get(), I64), path, b.add(level, const(I64, 1)))
        leaf_parent = _load(b, path, b.sub(depth, const(I64, 1)))
        slot = b.add(b.mul(leaf_parent, const(I64, 8)), _child_index(b, xyz, const(I32, 0)))
        with if_(b, b.icmp_signed("==", _load(b, nodes, slot), const(I32, 0))):
            _bump(b, counts, depth)
        _store(b, b.trunc(b.add(b.add(first_index, v), const(I64, 1)), I32), nodes, slot)
        for a in range(3):
            prev[a].set(xyz[a])
        started.set(const(ir.IntType(1), 1))
        inserted.set(b.add(v, const(I64, 1)))
    _store(b, node_count.get(), state, NODE_COUNT)
    _store(b, b.zext(started.get(), I64), state, STARTED)
    for a in range(3):
        _store(b, b.zext(prev[a].get(), I64), state, PREV + a)
    _copy(b, path, 0, state, PATH, levels)
    _copy(b, counts, 0, state, LEVEL_COUNTS, levels)
    b.ret(inserted.get())


def _octree_traverse(module):
    fn, b = _function(module, "implc_octree_traverse")
    nodes, depth, target, out, payload = fn.args
    node_stack = local_array(b, I64, MAX_DEPTH + 2, "node_stack")
    next_child = local_array(b, I64, MAX_DEPTH + 2, "next_child")
    level = Local(b, I64, 0, "level")
    xyz = [Local(b, I32, 0, n) for n in "XYZ"]
    count = Local(b, I64, 0, "count")
    _store(b, const(I64, 0), node_stack, 0)
    _store(b, const(I64, 0), next_child, 0)
    with while_true(b) as loop:
        lv = level.get()
        i = _load(b, next_child, lv)
        done_here = b.icmp_signed("==", i, const(I64, 8))
        loop.break_if(b.and_(done_here, b.icmp_signed("==", lv, const(I64, 0))))
        with b.if_else(done_here) as (ascend, visit):
            with ascend:  # every child seen: up one level
                level.set(b.sub(lv, const(I64, 1)))
                for v in xyz:
                    v.set(b.lshr(v.get(), const(I32, 1)))
            with visit:
                _store(b, b.add(i, const(I64, 1)), next_child, lv)
                entry = _load(b, nodes, b.add(b.mul(_load(b, node_stack, lv), const(I64, 8)), i))
                with if_(b, b.icmp_signed("!=", entry, const(I32, 0))):
                    i32 = b.trunc(i, I32)
                    child = [b.or_(b.shl(xyz[a].get(), const(I32, 1)), b.and_(b.lshr(i32, const(I32, a)), const(I32, 1)))
                             for a in range(3)]
                    child_level = b.add(lv, const(I64, 1))
                    with b.if_else(b.icmp_signed("==", child_level, target)) as (emit, descend):
                        with emit:
                            k = count.get()
                            for a in range(3):
                                _store(b, child[a], out, b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                            is_leaf = b.icmp_signed("==", child_level, depth)
                            value = b.sext(entry, I64)
                            _store(b, b.select(is_leaf, b.sub(value, const(I64, 1)), value), payload, k)
                            count.set(b.add(k, const(I64, 1)))
                        with descend:
                            _store(b, b.sext(entry, I64), node_stack, child_level)
                            _store(b, const(I64, 0), next_child, child_level)
                            level.set(child_level)
                            for a in range(3):
                                xyz[a].set(child[a])
    b.ret(count.get())


def _splat(module):
    fn, b = _function(module, "implc_splat")
    px, py, sizes, depth, n, size, zbuf, winner = fn.args
    zero = const(I64, 0)
    with for_range(b, n) as i:
        k = _load(b, sizes, i)
        half = b.sdiv(k, const(I64, 2))
        x0, y0 = b.sub(_load(b, px, i), half), b.sub(_load(b, py, i), half)
        z = _load(b, depth, i)
        with for_range(b, k) as dy:
            y = b.add(y0, dy)
            with if_(b, b.and_(b.icmp_signed(">=", y, zero), b.icmp_signed("<", y, size))):
                with for_range(b, k) as dx:
                    x = b.add(x0, dx)
                    with if_(b, b.and_(b.icmp_signed(">=", x, zero), b.icmp_signed("<", x, size))):
                        pixel = b.add(b.mul(y, size), x)
                        with if_(b, b.fcmp_ordered("<", z, _load(b, zbuf, pixel))):
                            _store(b, z, zbuf, pixel)
                            _store(b, i, winner, pixel)
    b.ret_void()


def build_runtime() -> str:
    """The LLVM IR text of the runtime module."""
    module = ir.Module(name="implc_runtime")
    _subdivide(module)
    _normals(module)
    _octree_insert(module)
    _octree_traverse(module)
    _splat(module)
    return str(module)
