"""``implc_tape_subdivide``: Fig. 1 for the tape engine, each octant running its own simplified program.

A depth-first walk with one frame per level (:data:`implc.abi.TAPE_FRAME_WORDS`): expanding a frame encloses
its octant's eight children with ``tape_interval`` over the octant's program, recording the Min/Max choices
each child's enclosure decided; stepping into a child that may meet the surface gives it its own program,
``tape_simplify``'d by those choices (or its parent's, where none was decided or pruning is off), so that
below an octant every decided branch costs nothing. Children are visited in Morton order; a task starts from
the full program simplified down the path from the root to its octant. The children of an octant one level
above the leaves are the voxels (with ``refine``, those one of whose eighths may meet the surface); their
unit normals come eight at a time from ``tape_dual`` over the program
two levels above the leaves (valid for every voxel below that octant, and barely longer than their
parents'), through the normals block of :mod:`implc.codegen.normals`, before the voxels leave the call.
Where ``out_flags`` is not NULL each voxel gets its flag for tightening, and the flagged ones their second
look (:mod:`implc.codegen.tape_tighten`, with the program three levels above the leaves, so that its batches
of eight fill, or two levels above where that program is a fifth shorter), which marks those it proves
empty for :mod:`implc.codegen.tighten` to drop.
Where ``inside`` is not NULL (a solid), every child whose enclosure lies below 0 is written there too
(:data:`implc.abi.INSIDE_WORDS` each). Resumable: when the output is full or the cancel flag is raised it
returns with its frames and state intact (layouts in :mod:`implc.abi`)."""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import (
    I32,
    I64,
    Local,
    at,
    bit_intrinsic,
    const,
    define,
    for_range,
    for_set_bits,
    if_,
    load_at,
    local_array,
    store_at,
    while_true,
)
from .kernels import load_xyz, store_xyz
from .normals import emit_normals_body
from .subdivision import append_inside
from .tape_eval import I8, LANES, V8
from .vector import DOUBLE, broadcast

FLOAT = ir.FloatType()
_P = ir.PointerType


def emit_tape_normals(module: ir.Module, dual: ir.Function) -> ir.Function:
    """``tape_normals(header, program, length, output, slots, leaf_geom, coords, n, out, flags)`` (internal):
    unit normals of ``n`` voxels, the gradient from ``dual`` over the program given (and their flags for
    tightening where ``flags`` is not NULL)."""
    fn = ir.Function(module, ir.FunctionType(ir.VoidType(), [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(DOUBLE),
                                                              _P(I32), I64, _P(FLOAT), _P(I8)]),
                     name="implc.tape.normals")
    fn.linkage = "internal"
    header, program, length, output, slots, leaf_geom, coords, n, out, flags = fn.args
    b = ir.IRBuilder(fn.append_basic_block("entry"))
    points = local_array(b, DOUBLE, 3 * LANES, "points")
    result = local_array(b, DOUBLE, 4 * LANES, "result")
    vpoints, vresult = b.bitcast(points, _P(V8)), b.bitcast(result, _P(V8))

    def dual_at(interleaved):
        """F and its gradient at the eight points of ``interleaved`` (x, y, z per point) into result."""
        for a, axis in enumerate(load_xyz(b, interleaved, const(I64, 0), LANES)):
            b.store(axis, b.gep(vpoints, [const(I64, a)]), align=8)
        b.call(dual, [header, program, length, output, slots, points, result])

    def gradient_at(pts, values, grad, live):
        dual_at(pts)
        b.store(b.load(vresult, align=8), b.bitcast(values, _P(V8)), align=8)
        store_xyz(b, grad, const(I64, 0), [b.load(b.gep(vresult, [const(I64, 1 + a)]), align=8) for a in range(3)],
                  LANES)

    def values_at(probe, probe_values):
        for k in range(6):
            dual_at(b.gep(probe, [const(I64, 3 * LANES * k)]))
            b.store(b.load(vresult, align=8), b.bitcast(b.gep(probe_values, [const(I64, LANES * k)]), _P(V8)),
                    align=8)

    emit_normals_body(b, leaf_geom, coords, ir.Constant(_P(I64), None), n, out, gradient_at, values_at, flags)
    b.ret_void()
    return fn


def emit_tape_subdivide(module: ir.Module, prefill: ir.Function, interval: ir.Function, simplify: ir.Function,
                        normals: ir.Function, tighten: ir.Function):
    fn, b = define(module, abi.TAPE_SUBDIVIDE)
    (header, prune, refine, geom, state, frames, tapes, choices, slots, need, mark, remap, out, out_normals,
     out_flags, capacity, inside, inside_capacity, stats, cancel) = fn.args
    has_flags = b.icmp_unsigned("!=", out_flags, ir.Constant(out_flags.type, None))
    solid = b.icmp_unsigned("!=", inside, ir.Constant(inside.type, None))
    program = b.inttoptr(load_at(b, header, abi.PROGRAM_INSTRUCTIONS), _P(I32))
    length = load_at(b, header, abi.PROGRAM_LENGTH)
    output = load_at(b, header, abi.PROGRAM_OUTPUT)
    box = local_array(b, DOUBLE, 6 * LANES, "box")
    result = local_array(b, DOUBLE, 2 * LANES, "result")
    leaf_geom = local_array(b, DOUBLE, 6, "leaf_geom")
    depth = load_at(b, state, abi.TAPE_DEPTH)
    task_level = load_at(b, state, abi.TAPE_TASK_LEVEL)
    for a in range(3):
        store_at(b, load_at(b, geom, a), leaf_geom, a)
        store_at(b, load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))), leaf_geom, 3 + a)
    count = Local(b, I64, 0, "count")
    inside_count = Local(b, I64, 0, "inside_count")
    normals_done = Local(b, I64, 0, "normals_done")  # voxels before this one have their normals
    tightened = Local(b, I64, 0, "tightened")  # voxels before this one had their second look
    octant_start = Local(b, I64, 0, "octant_start")  # the first voxel of the octant at normals_level
    # normals come from the program two levels above the leaves (valid for all its voxels, eight at a time)
    normals_level = b.select(b.icmp_signed(">", b.sub(depth, const(I64, 2)), task_level), b.sub(depth, const(I64, 2)),
                             task_level)
    # the second look runs over the program three levels above the leaves (its batches of eight fuller),
    # unless the one two levels above is much shorter (leave_normals_octant)
    tighten_level = b.select(b.icmp_signed(">", b.sub(depth, const(I64, 3)), task_level), b.sub(depth, const(I64, 3)),
                             task_level)
    ctpop, cttz = bit_intrinsic(module, "ctpop"), bit_intrinsic(module, "cttz")

    def program_of(level):
        return b.inttoptr(load_at(b, state, b.add(level, const(I64, abi.TAPE_PROGRAMS))), _P(I32))

    def length_of(level):
        return load_at(b, state, b.add(level, const(I64, abi.TAPE_PROGRAMS + abi.TAPE_LEVELS)))

    def output_of(level):
        return load_at(b, state, b.add(level, const(I64, abi.TAPE_PROGRAMS + 2 * abi.TAPE_LEVELS)))

    def output_at(level):
        return at(b, state, b.add(level, const(I64, abi.TAPE_PROGRAMS + 2 * abi.TAPE_LEVELS)))

    def set_program(level, ptr, n, result_slot):
        store_at(b, b.ptrtoint(ptr, I64), state, b.add(level, const(I64, abi.TAPE_PROGRAMS)))
        store_at(b, n, state, b.add(level, const(I64, abi.TAPE_PROGRAMS + abi.TAPE_LEVELS)))
        b.store(result_slot, output_at(level))

    def frame(level, k):
        return at(b, frames, b.add(b.mul(level, const(I64, abi.TAPE_FRAME_WORDS)), const(I64, k)))

    def choices_of(level):
        return b.gep(choices, [b.mul(b.mul(level, length), const(I64, LANES))])

    def enclose_children(level, cell, program_level=None):
        """Enclose the eight children of the octant ``cell`` (three i32) at ``level`` with the program of
        ``program_level`` (default: that level's), recording its choices; returns the lanes with a decided
        choice (i8)."""
        program_level = level if program_level is None else program_level
        child = b.add(level, const(I64, 1))
        vbox = b.bitcast(box, _P(V8))
        ivec = ir.VectorType(I32, LANES)
        for a in range(3):  # the children's boxes exactly as the compiled octant kernels make them
            origin, pad = broadcast(b, load_at(b, geom, a), LANES), broadcast(b, load_at(b, geom, 3 + a), LANES)
            h = broadcast(b, load_at(b, geom, b.add(b.mul(child, const(I64, 3)), const(I64, 6 + a))), LANES)
            twice = broadcast(b, b.shl(cell[a], const(I32, 1)), LANES)
            index = b.add(twice, ir.Constant(ivec, [(c >> a) & 1 for c in range(LANES)]))
            i_lo, i_hi = b.uitofp(index, V8), b.uitofp(b.add(index, ir.Constant(ivec, [1] * LANES)), V8)
            b.store(b.fsub(b.fadd(origin, b.fmul(i_lo, h)), pad), b.gep(vbox, [const(I64, a)]), align=8)
            b.store(b.fadd(b.fadd(origin, b.fmul(i_hi, h)), pad), b.gep(vbox, [const(I64, 3 + a)]), align=8)
        return b.call(interval, [header, program_of(program_level), length_of(program_level),
                                 output_of(program_level), slots, choices_of(level), box, result])

    def program_for_child(level, c, decided):
        """The program of child ``c`` (i32) of the octant at ``level``: simplified by its choices where one
        was decided (``decided``: i1) and pruning is on, else the octant's own."""
        child = b.add(level, const(I64, 1))
        with b.if_else(b.and_(b.icmp_signed("!=", prune, const(I64, 0)), decided)) as (simplified, shared):
            with simplified:
                target = b.gep(tapes, [b.mul(b.mul(child, length), const(I64, abi.INSTRUCTION_WORDS))])
                stamp = b.add(load_at(b, state, abi.TAPE_STAMP), const(I64, 1))
                with if_(b, b.icmp_signed(">=", stamp, const(I64, 0x7FFFFFFF))):  # start the stamps over
                    with for_range(b, load_at(b, header, abi.PROGRAM_SLOT_COUNT)) as k:
                        store_at(b, const(I32, 0), need, k)
                stamp = b.select(b.icmp_signed(">=", stamp, const(I64, 0x7FFFFFFF)), const(I64, 1), stamp)
                store_at(b, stamp, state, abi.TAPE_STAMP)
                n = b.call(simplify, [program_of(level), length_of(level), output_of(level), choices_of(level),
                                      b.zext(c, I64), target, need, b.trunc(stamp, I32), mark, remap,
                                      output_at(child)])
                set_program(child, target, n, b.load(output_at(child)))
            with shared:
                set_program(child, program_of(level), length_of(level), output_of(level))

    with if_(b, b.icmp_signed("==", load_at(b, state, abi.TAPE_PHASE), const(I64, 0))):
        # a new task: its program is the full one simplified down the path from the root to its octant
        b.call(prefill, [header, slots, remap])  # constants, and the names simplify renames through
        set_program(const(I64, 0), program, length, output)
        task_cell = [b.load(frame(task_level, a)) for a in range(3)]
        with for_range(b, task_level) as level:
            above = b.trunc(b.sub(task_level, level), I32)  # the ancestor at ``level``: the cell >> above
            ancestor = [b.lshr(task_cell[a], above) for a in range(3)]
            decided = enclose_children(level, ancestor)
            below = b.sub(above, const(I32, 1))
            c = const(I32, 0)
            for a in range(3):
                c = b.or_(c, b.shl(b.and_(b.lshr(task_cell[a], below), const(I32, 1)), const(I32, a)))
            program_for_child(level, c, b.trunc(b.lshr(b.zext(decided, I32), c), ir.IntType(1)))
        store_at(b, task_level, state, abi.TAPE_LEVEL)
        store_at(b, const(I64, 1), state, abi.TAPE_PENDING)
        store_at(b, const(I64, 1), state, abi.TAPE_PHASE)

    def flush_normals(whole_blocks=False):
        """Normals of the voxels written since the last flush (``whole_blocks``: of a multiple of eight of
        them), from the program of their ancestor at ``normals_level``."""
        first = normals_done.get()
        pending = b.sub(count.get(), first)
        if whole_blocks:
            pending = b.and_(pending, const(I64, -LANES))
        with if_(b, b.icmp_signed(">", pending, const(I64, 0))):
            offset = b.mul(first, const(I64, 3))
            b.call(normals, [header, program_of(normals_level), length_of(normals_level), output_of(normals_level),
                             slots, leaf_geom,
                             b.gep(out, [offset]), pending, b.gep(out_normals, [offset]),
                             b.select(has_flags, b.gep(out_flags, [first]), out_flags)])
            normals_done.set(b.add(first, pending))

    def flush_tighten(upto, level):
        """The second look at the voxels flagged since the last one, up to ``upto``, with the program of
        ``level`` (all of them lie below its octant: its program is valid for each)."""
        first = tightened.get()
        pending = b.sub(upto, first)
        with if_(b, b.and_(has_flags, b.icmp_signed(">", pending, const(I64, 0)))):
            b.call(tighten, [header, program_of(level), length_of(level), output_of(level),
                             slots, choices_of(b.add(depth, const(I64, 1))), geom, depth,
                             b.gep(out, [b.mul(first, const(I64, 3))]), b.gep(out_flags, [first]), pending])
            tightened.set(upto)

    def leave_normals_octant():
        """Normals for the octant at ``normals_level`` just finished; its second look now, with its own
        program, where that is a fifth shorter than the one at ``tighten_level`` or more (fuller batches do not
        pay for that: Min/Max models such as Prospero), after the voxels of its siblings still waiting."""
        flush_normals()
        shorter = b.icmp_signed("<", b.mul(length_of(normals_level), const(I64, 5)),
                                b.mul(length_of(tighten_level), const(I64, 4)))
        with if_(b, shorter):
            flush_tighten(octant_start.get(), tighten_level)
            flush_tighten(normals_done.get(), normals_level)
        octant_start.set(normals_done.get())

    def may_meet(lo, hi):
        """The lanes whose enclosure contains 0 or is undefined (NaN)."""
        zero = ir.Constant(V8, [0.0] * LANES)
        return b.or_(b.and_(b.fcmp_ordered("<=", lo, zero), b.fcmp_ordered(">=", hi, zero)),
                     b.or_(b.fcmp_unordered("uno", lo, lo), b.fcmp_unordered("uno", hi, hi)))

    def expand(level):
        """Enclose the children of the octant in frame ``level``; keep those that may meet the surface
        (the leaves: write them with their normals)."""
        child = b.add(level, const(I64, 1))
        own_length = length_of(level)
        decided = enclose_children(level, [b.load(frame(level, a)) for a in range(3)])
        vresult = b.bitcast(result, _P(V8))
        f_lo, f_hi = b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)
        zero = ir.Constant(V8, [0.0] * LANES)
        kept = b.zext(b.bitcast(may_meet(f_lo, f_hi), I8), I32)
        refined = Local(b, I32, kept, "refined")  # with refine, a leaf stays only if one of its eighths may meet F
        with if_(b, b.and_(b.icmp_signed("==", child, depth), b.icmp_signed("!=", refine, const(I64, 0)))):
            with for_set_bits(b, kept) as c:
                leaf = [b.add(b.shl(b.load(frame(level, a)), const(I32, 1)), b.and_(b.lshr(c, const(I32, a)),
                                                                                      const(I32, 1)))
                        for a in range(3)]
                enclose_children(child, leaf, program_level=level)
                sub_lo, sub_hi = b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)
                empty = b.icmp_unsigned("==", b.bitcast(may_meet(sub_lo, sub_hi), I8), const(I8, 0))
                drop = b.select(empty, b.shl(const(I32, 1), c), const(I32, 0))
                refined.set(b.and_(refined.get(), b.not_(drop)))
                slot = at(b, stats, 0)
                b.store(b.add(b.load(slot), const(I64, LANES)), slot)
        kept = refined.get()
        with if_(b, solid):  # children whose box lies inside
            below = b.zext(b.bitcast(b.fcmp_ordered("<", f_hi, zero), I8), I32)
            cells = [[b.add(b.shl(b.load(frame(level, a)), const(I32, 1)), const(I32, (c >> a) & 1))
                      for a in range(3)] for c in range(LANES)]
            append_inside(b, inside, inside_count, cells, b.trunc(child, I32), below)
        slot = at(b, stats, 0)
        b.store(b.add(b.load(slot), const(I64, LANES)), slot)
        for index, amount in ((b.add(child, const(I64, 1)), b.zext(b.call(ctpop, [kept]), I64)),
                              (b.add(level, const(I64, abi.TAPE_LEVELS)), own_length),
                              (b.add(level, const(I64, 2 * abi.TAPE_LEVELS)), const(I64, 1))):
            slot = at(b, stats, index)
            b.store(b.add(b.load(slot), amount), slot)
        with b.if_else(b.icmp_signed("==", child, depth)) as (leaves, inner):
            with leaves:  # the kept children are voxels: written in Morton order (branch-free)
                n = count.get()
                for c in range(LANES):
                    for a in range(3):
                        bit = (c >> a) & 1
                        coord = b.add(b.shl(b.load(frame(level, a)), const(I32, 1)), const(I32, bit))
                        store_at(b, coord, out, b.add(b.mul(n, const(I64, 3)), const(I64, a)))
                    n = b.add(n, b.zext(b.trunc(b.lshr(kept, const(I32, c)), ir.IntType(1)), I64))
                count.set(n)
                flush_normals(whole_blocks=True)
                b.store(const(I32, 0), frame(level, 3))
            with inner:
                b.store(kept, frame(level, 3))
                b.store(b.and_(b.zext(decided, I32), kept), frame(level, 4))

    with while_true(b) as loop:
        loop.break_if(b.icmp_signed("==", load_at(b, state, abi.TAPE_PHASE), const(I64, 2)))
        loop.break_if(b.icmp_signed("!=", b.load_atomic(cancel, "monotonic", 4), const(I32, 0)))
        level = load_at(b, state, abi.TAPE_LEVEL)
        pending = b.icmp_signed("!=", load_at(b, state, abi.TAPE_PENDING), const(I64, 0))
        leaf_parent = b.icmp_signed("==", b.add(level, const(I64, 1)), depth)
        no_room = b.icmp_signed(">", b.add(count.get(), const(I64, LANES)), capacity)
        loop.break_if(b.and_(pending, b.and_(leaf_parent, no_room)))
        no_inside_room = b.icmp_signed(">", b.add(inside_count.get(), const(I64, LANES)), inside_capacity)
        loop.break_if(b.and_(pending, b.and_(solid, no_inside_room)))
        with b.if_else(pending) as (expanding, stepping):
            with expanding:
                expand(level)
                store_at(b, const(I64, 0), state, abi.TAPE_PENDING)
            with stepping:
                remaining = b.load(frame(level, 3))
                with b.if_else(b.icmp_unsigned("==", remaining, const(I32, 0))) as (up, down):
                    with up:  # every child visited: back to the parent, or the task is done
                        with if_(b, b.icmp_signed("==", level, normals_level)):
                            leave_normals_octant()
                        with if_(b, b.icmp_signed("==", level, tighten_level)):
                            flush_normals()
                            flush_tighten(normals_done.get(), tighten_level)
                        done = b.icmp_signed("==", level, task_level)
                        store_at(b, b.select(done, const(I64, 2), const(I64, 1)), state, abi.TAPE_PHASE)
                        store_at(b, b.select(done, level, b.sub(level, const(I64, 1))), state, abi.TAPE_LEVEL)
                    with down:  # into the next kept child, in Morton order, with its own program
                        c = b.call(cttz, [remaining, const(ir.IntType(1), 1)])
                        b.store(b.and_(remaining, b.sub(remaining, const(I32, 1))), frame(level, 3))
                        child = b.add(level, const(I64, 1))
                        for a in range(3):
                            bit = b.and_(b.lshr(c, const(I32, a)), const(I32, 1))
                            b.store(b.add(b.shl(b.load(frame(level, a)), const(I32, 1)), bit), frame(child, a))
                        program_for_child(level, c, b.trunc(b.lshr(b.load(frame(level, 4)), c), ir.IntType(1)))
                        store_at(b, child, state, abi.TAPE_LEVEL)
                        store_at(b, const(I64, 1), state, abi.TAPE_PENDING)
    flush_normals()  # leaving (done, output full or cancelled): every voxel written has its normal
    flush_tighten(normals_done.get(), tighten_level)
    store_at(b, inside_count.get(), state, abi.TAPE_INSIDE_COUNT)
    b.ret(count.get())
