"""``implc_subdivide``: Fig. 1 of the paper, the native depth-first subdivision of one task.

A loop over an explicit stack. It calls a surface's octant kernel (``implc_octant``: the eight children of
an octant, generated and enclosed in vector registers) through a function pointer (a second, finer kernel,
e.g. the mean-value form, from a given child level on; optionally a leaf is kept only if one of its eight
halves-per-axis may meet the surface), prunes children whose enclosure excludes 0, pushes the rest in
reverse so that leaves come out in Morton order, and writes leaf coordinates with their live-term masks;
where ``inside`` is not NULL (a solid), also every child whose enclosure lies below 0
(:data:`implc.abi.INSIDE_WORDS` each; their count goes to the state). It is resumable: when the output
buffer is full or the cancel flag is raised it returns with its stack intact (the layouts are
:mod:`implc.abi`'s)."""

from __future__ import annotations

from llvmlite import ir

from .. import abi
from .control import (
    I32,
    I64,
    Local,
    at,
    bit_intrinsic,
    bump,
    const,
    define,
    if_,
    load_at,
    local_array,
    store_at,
    while_true,
)


def append_inside(b: ir.IRBuilder, inside, count: Local, cells, level, inside_bits):
    """Append the eight children ``cells`` (per child, three i32) of one octant at ``level`` (i32) whose
    bit is set in ``inside_bits`` (i32, bit c: child c) to ``inside`` (:data:`implc.abi.INSIDE_WORDS` per
    row), in Morton order and branch-free (every child is written, only the inside ones are kept)."""
    n = count.get()
    for c in range(8):
        row = b.mul(n, const(I64, abi.INSIDE_WORDS))
        for a in range(3):
            store_at(b, cells[c][a], inside, b.add(row, const(I64, a)))
        store_at(b, level, inside, b.add(row, const(I64, 3)))
        n = b.add(n, b.zext(b.trunc(b.lshr(inside_bits, const(I32, c)), ir.IntType(1)), I64))
    count.set(n)


def emit_subdivide(module: ir.Module):
    fn, b = define(module, abi.SUBDIVIDE)
    (box_ptr, fine_ptr, fine_level, prune, refine, geom, stack, masks, state, out, out_masks, cap, inside,
     inside_cap, stats, cancel) = fn.args
    box = b.bitcast(box_ptr, ir.PointerType(abi.OCTANT.llvm_type()))
    fine = b.bitcast(fine_ptr, ir.PointerType(abi.OCTANT.llvm_type()))
    depth = b.trunc(load_at(b, state, 1), I32)
    size = Local(b, I64, load_at(b, state, 0), "size")
    count = Local(b, I64, 0, "count")
    inside_count = Local(b, I64, 0, "inside_count")
    solid = b.icmp_unsigned("!=", inside, ir.Constant(inside.type, None))
    child_masks = local_array(b, I64, 8, "child_masks")
    sub_cell = local_array(b, I32, 3, "sub_cell")
    pruning = b.icmp_signed("!=", prune, const(I64, 0))
    refining = b.icmp_signed("!=", refine, const(I64, 0))
    null64 = ir.Constant(ir.PointerType(I64), None)
    all_live = const(I64, -1)

    with while_true(b) as loop:
        s = size.get()
        loop.break_if(b.icmp_signed("==", s, const(I64, 0)))
        flag = b.load_atomic(cancel, "monotonic", 4)
        loop.break_if(b.icmp_signed("!=", flag, const(I32, 0)))
        top = b.mul(b.sub(s, const(I64, 1)), const(I64, 4))
        cell = [load_at(b, stack, b.add(top, const(I64, a))) for a in range(3)]
        child_level = b.add(load_at(b, stack, b.add(top, const(I64, 3))), const(I32, 1))
        leaf = b.icmp_signed("==", child_level, depth)
        no_room = b.icmp_signed(">", b.add(count.get(), const(I64, 8)), cap)
        loop.break_if(b.and_(leaf, no_room))
        loop.break_if(b.and_(solid, b.icmp_signed(">", b.add(inside_count.get(), const(I64, 8)), inside_cap)))
        size.set(b.sub(s, const(I64, 1)))
        parent_mask = b.select(pruning, load_at(b, masks, b.sub(s, const(I64, 1))), all_live)

        level64 = b.zext(child_level, I64)
        children = [[b.add(b.shl(cell[a], const(I32, 1)), const(I32, (c >> a) & 1)) for a in range(3)]
                    for c in range(8)]
        kernel = b.select(b.icmp_signed(">=", level64, fine_level), fine, box)
        decided = b.call(kernel, [geom, at(b, stack, top), level64, parent_mask, child_masks])
        kept = b.and_(decided, const(I32, 0xFF))
        bump(b, stats, 0, 8)
        with if_(b, solid):  # children whose box lies inside
            append_inside(b, inside, inside_count, children, child_level,
                          b.lshr(decided, const(I32, abi.OCTANT_INSIDE_SHIFT)))
        stat_slot = b.add(level64, const(I64, 1))

        def keep(c):
            return b.trunc(b.lshr(kept, const(I32, c)), ir.IntType(1))

        def child_mask(c):
            return b.select(pruning, load_at(b, child_masks, c), all_live)

        def refined_keep(c):
            """Whether some eighth of leaf c may meet the surface (one more level, for tightness)."""
            for a in range(3):
                store_at(b, children[c][a], sub_cell, a)
            sub_kept = b.call(kernel, [geom, sub_cell, b.add(level64, const(I64, 1)), child_mask(c), null64])
            bump(b, stats, 0, 8)
            return b.icmp_unsigned("!=", b.and_(sub_kept, const(I32, 0xFF)), const(I32, 0))

        ctpop = bit_intrinsic(module, "ctpop")

        def append(array, masks_array, n, c, width):
            """Write child c at slot n whether it is kept or not; the next slot is n + its keep bit
            (branch-free: which children survive is unpredictable)."""
            for a in range(3):
                store_at(b, children[c][a], array, b.add(b.mul(n, const(I64, width)), const(I64, a)))
            if width == 4:
                store_at(b, child_level, array, b.add(b.mul(n, const(I64, 4)), const(I64, 3)))
            store_at(b, child_mask(c), masks_array, n)
            return b.add(n, b.zext(keep(c), I64))

        with b.if_else(b.and_(leaf, refining)) as (refined, plain):
            with refined:  # emit the kept leaves that pass refinement, in Morton order
                for c in range(8):
                    with if_(b, keep(c)):
                        with if_(b, refined_keep(c)):
                            n = count.get()
                            for a in range(3):
                                store_at(b, children[c][a], out, b.add(b.mul(n, const(I64, 3)), const(I64, a)))
                            store_at(b, child_mask(c), out_masks, n)
                            count.set(b.add(n, const(I64, 1)))
                            bump(b, stats, stat_slot)
            with plain:
                slot = at(b, stats, stat_slot)
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
    store_at(b, size.get(), state, 0)
    store_at(b, inside_count.get(), state, 2)
    b.ret(count.get())


