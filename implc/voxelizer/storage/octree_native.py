"""The index-based octree's native routines: insertion (Fig. 2) and traversal (Fig. 6).

- ``implc_octree_insert``: Morton-ordered voxels go into an (M, 8) int32 node array, each starting from
  the previous voxel's path and ascending only to the common parent; it clears each node it creates, so
  the node array may be reserved uninitialised. Its state words are laid out in :mod:`implc.native.abi`.
- ``implc_octree_traverse``: depth-first traversal yielding the nodes of one level in order (the
  boundary's: entries below zero, a solid's inside octants, are neither visited nor yielded).
- ``implc_octree_subtree_rows``: how many nodes Morton-ordered voxels need below their common root
  ``below`` levels up (what ``implc_octree_insert`` will create for them from an empty root).
- ``implc_octree_mark_inside``: records inside octants (rows i, j, k, level) as entries −1, creating the
  nodes above one that no boundary node holds, and merging upward every node whose eight entries are
  inside (it becomes an inside entry of its parent).
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import (
    I32,
    I64,
    Local,
    at,
    bit_intrinsic,
    bump,
    const,
    copy_words,
    define,
    for_range,
    if_,
    load_at,
    local_array,
    store_at,
    while_true,
)
from ...native import abi
from ...native.jit import Source
from ...native.runtime import Library


def _child_index(b, xyz, bit):
    """Child slot (x bit | y bit << 1 | z bit << 2) of coordinates xyz at bit position ``bit``."""
    slot = const(I32, 0)
    for a in range(3):
        slot = b.or_(slot, b.shl(b.and_(b.lshr(xyz[a], bit), const(I32, 1)), const(I32, a)))
    return b.zext(slot, I64)


def _top_differing_bit(b, xyz, other):
    """The highest bit at which two cells' coordinates (three i32 each) differ: an i32, -1 where they are
    the same cell. A voxel shares the node with the previous one at every level above that bit."""
    ctlz = bit_intrinsic(b.module, "ctlz")
    diff = b.xor(xyz[0], other[0])
    for a in (1, 2):
        diff = b.or_(diff, b.xor(xyz[a], other[a]))
    return b.sub(const(I32, 31), b.call(ctlz, [diff, const(ir.IntType(1), 0)]))


def emit_octree_insert(module: ir.Module):
    fn, b = define(module, abi.OCTREE_INSERT)
    nodes, node_cap, state, coords, n, first_index = fn.args
    for arg in (nodes, state, coords):
        arg.add_attribute("noalias")
    depth = load_at(b, state, abi.DEPTH)
    depth32 = b.trunc(depth, I32)
    # the state lives in locals (registers, a stack-resident path) during the call, written back at the end
    node_count = Local(b, I64, load_at(b, state, abi.NODE_COUNT), "node_count")
    started = Local(b, ir.IntType(1), b.icmp_signed("!=", load_at(b, state, abi.STARTED), const(I64, 0)), "started")
    prev = [Local(b, I32, b.trunc(load_at(b, state, abi.PREV + a), I32), f"prev{a}") for a in range(3)]
    levels = abi.MAX_DEPTH + 2
    path = local_array(b, I64, levels, "path")
    counts = local_array(b, I64, levels, "counts")
    copy_words(b, state, abi.PATH, path, 0, levels)
    copy_words(b, state, abi.LEVEL_COUNTS, counts, 0, levels)
    inserted = Local(b, I64, 0, "inserted")
    with while_true(b) as loop:
        v = inserted.get()
        loop.break_if(b.icmp_signed(">=", v, n))
        xyz = [load_at(b, coords, b.add(b.mul(v, const(I64, 3)), const(I64, a))) for a in range(3)]
        # the deepest level whose node is shared with the previous voxel (Fig. 2's ascent)
        top_bit = _top_differing_bit(b, xyz, [p.get() for p in prev])
        shared = b.select(b.icmp_signed("<", top_bit, const(I32, 0)), b.sub(depth32, const(I32, 1)),
                          b.sub(b.sub(depth32, const(I32, 1)), top_bit))
        start = b.zext(b.select(started.get(), shared, const(I32, 0)), I64)
        # room for the nodes this voxel may create (levels start+1 .. depth-1)
        needed = b.sub(b.sub(depth, const(I64, 1)), start)
        loop.break_if(b.icmp_signed(">", b.add(node_count.get(), needed), node_cap))
        with for_range(b, b.sub(depth, const(I64, 1)), start=start) as level:  # descend, creating nodes
            bit = b.trunc(b.sub(b.sub(depth, const(I64, 1)), level), I32)
            slot = b.add(b.mul(load_at(b, path, level), const(I64, 8)), _child_index(b, xyz, bit))
            entry = Local(b, I32, load_at(b, nodes, slot))
            with if_(b, b.icmp_signed("==", entry.get(), const(I32, 0))):
                fresh = node_count.get()
                row = b.bitcast(at(b, nodes, b.mul(fresh, const(I64, 8))), ir.PointerType(ir.VectorType(I32, 8)))
                b.store(ir.Constant(ir.VectorType(I32, 8), [0] * 8), row, align=4)  # rows arrive uninitialised
                entry.set(b.trunc(fresh, I32))
                store_at(b, entry.get(), nodes, slot)
                node_count.set(b.add(fresh, const(I64, 1)))
                bump(b, counts, b.add(level, const(I64, 1)))
            store_at(b, b.sext(entry.get(), I64), path, b.add(level, const(I64, 1)))
        leaf_parent = load_at(b, path, b.sub(depth, const(I64, 1)))
        slot = b.add(b.mul(leaf_parent, const(I64, 8)), _child_index(b, xyz, const(I32, 0)))
        with if_(b, b.icmp_signed("==", load_at(b, nodes, slot), const(I32, 0))):
            bump(b, counts, depth)
        store_at(b, b.trunc(b.add(b.add(first_index, v), const(I64, 1)), I32), nodes, slot)
        for a in range(3):
            prev[a].set(xyz[a])
        started.set(const(ir.IntType(1), 1))
        inserted.set(b.add(v, const(I64, 1)))
    store_at(b, node_count.get(), state, abi.NODE_COUNT)
    store_at(b, b.zext(started.get(), I64), state, abi.STARTED)
    for a in range(3):
        store_at(b, b.zext(prev[a].get(), I64), state, abi.PREV + a)
    copy_words(b, path, 0, state, abi.PATH, levels)
    copy_words(b, counts, 0, state, abi.LEVEL_COUNTS, levels)
    b.ret(inserted.get())


def emit_octree_traverse(module: ir.Module):
    fn, b = define(module, abi.OCTREE_TRAVERSE)
    nodes, depth, target, out, payload = fn.args
    node_stack = local_array(b, I64, abi.MAX_DEPTH + 2, "node_stack")
    next_child = local_array(b, I64, abi.MAX_DEPTH + 2, "next_child")
    level = Local(b, I64, 0, "level")
    xyz = [Local(b, I32, 0, n) for n in "XYZ"]
    count = Local(b, I64, 0, "count")
    store_at(b, const(I64, 0), node_stack, 0)
    store_at(b, const(I64, 0), next_child, 0)
    with while_true(b) as loop:
        lv = level.get()
        i = load_at(b, next_child, lv)
        done_here = b.icmp_signed("==", i, const(I64, 8))
        loop.break_if(b.and_(done_here, b.icmp_signed("==", lv, const(I64, 0))))
        with b.if_else(done_here) as (ascend, visit):
            with ascend:  # every child seen: up one level
                level.set(b.sub(lv, const(I64, 1)))
                for v in xyz:
                    v.set(b.lshr(v.get(), const(I32, 1)))
            with visit:
                store_at(b, b.add(i, const(I64, 1)), next_child, lv)
                entry = load_at(b, nodes, b.add(b.mul(load_at(b, node_stack, lv), const(I64, 8)), i))
                # a node or a voxel (neither empty nor inside)
                with if_(b, b.icmp_signed(">", entry, const(I32, 0))):
                    i32 = b.trunc(i, I32)
                    child = [b.or_(b.shl(xyz[a].get(), const(I32, 1)),
                                   b.and_(b.lshr(i32, const(I32, a)), const(I32, 1))) for a in range(3)]
                    child_level = b.add(lv, const(I64, 1))
                    with b.if_else(b.icmp_signed("==", child_level, target)) as (emit, descend):
                        with emit:
                            k = count.get()
                            for a in range(3):
                                store_at(b, child[a], out, b.add(b.mul(k, const(I64, 3)), const(I64, a)))
                            is_leaf = b.icmp_signed("==", child_level, depth)
                            value = b.sext(entry, I64)
                            store_at(b, b.select(is_leaf, b.sub(value, const(I64, 1)), value), payload, k)
                            count.set(b.add(k, const(I64, 1)))
                        with descend:
                            store_at(b, b.sext(entry, I64), node_stack, child_level)
                            store_at(b, const(I64, 0), next_child, child_level)
                            level.set(child_level)
                            for a in range(3):
                                xyz[a].set(child[a])
    b.ret(count.get())


def emit_octree_mark_inside(module: ir.Module):
    fn, b = define(module, abi.OCTREE_MARK_INSIDE)
    nodes, node_cap, state, rows, n = fn.args
    for arg in (nodes, state, rows):
        arg.add_attribute("noalias")
    node_count = Local(b, I64, load_at(b, state, abi.NODE_COUNT), "node_count")
    levels = abi.MAX_DEPTH + 2
    path = local_array(b, I64, levels, "path")  # the node at each level of the current row's descent
    counts = local_array(b, I64, levels, "counts")
    copy_words(b, state, abi.LEVEL_COUNTS, counts, 0, levels)
    done = Local(b, I64, 0, "done")
    aborted = Local(b, ir.IntType(1), const(ir.IntType(1), 0), "aborted")
    inside = const(I32, -1)
    depth = load_at(b, state, abi.DEPTH)
    # the previous row's first cell (at the grid's depth) and how deep its path is valid (0: only the root)
    prev = [Local(b, I32, const(I32, 0), f"prev{a}") for a in range(3)]
    prev_valid = Local(b, I64, 0, "prev_valid")
    store_at(b, const(I64, 0), path, 0)
    with while_true(b) as rows_loop:
        r = done.get()
        rows_loop.break_if(b.icmp_signed(">=", r, n))
        base = b.mul(r, const(I64, 4))
        xyz = [load_at(b, rows, b.add(base, const(I64, a))) for a in range(3)]
        level = b.sext(load_at(b, rows, b.add(base, const(I64, 3))), I64)
        # start from the deepest node shared with the previous row (rows in Morton order share long paths;
        # a node a previous row merged away is never on a later disjoint row's path)
        to_depth = b.trunc(b.sub(depth, level), I32)
        first = [b.shl(xyz[a], to_depth) for a in range(3)]
        top_bit = _top_differing_bit(b, first, [p.get() for p in prev])
        shared = b.select(b.icmp_signed("<", top_bit, const(I32, 0)), depth,
                          b.sext(b.sub(b.sub(b.trunc(depth, I32), const(I32, 1)), top_bit), I64))
        start = b.select(b.icmp_signed("<", shared, prev_valid.get()), shared, prev_valid.get())
        start = b.select(b.icmp_signed("<", start, b.sub(level, const(I64, 1))), start, b.sub(level, const(I64, 1)))
        node = Local(b, I64, load_at(b, path, start), "node")
        lv = Local(b, I64, start, "lv")
        # descend to the octant's parent, creating missing nodes; stop under an inside entry
        with while_true(b) as descend:
            here = lv.get()
            descend.break_if(b.icmp_signed(">=", b.add(here, const(I64, 1)), level))
            descend.break_if(b.icmp_signed("<", node.get(), const(I64, 0)))
            bit = b.trunc(b.sub(b.sub(level, const(I64, 1)), here), I32)
            slot = b.add(b.mul(node.get(), const(I64, 8)), _child_index(b, xyz, bit))
            entry = Local(b, I32, load_at(b, nodes, slot), "entry")
            with if_(b, b.icmp_signed("==", entry.get(), const(I32, 0))):
                full = b.icmp_signed(">=", node_count.get(), node_cap)
                aborted.set(full)
                descend.break_if(full)
                fresh = node_count.get()
                row = b.bitcast(at(b, nodes, b.mul(fresh, const(I64, 8))), ir.PointerType(ir.VectorType(I32, 8)))
                b.store(ir.Constant(ir.VectorType(I32, 8), [0] * 8), row, align=4)
                entry.set(b.trunc(fresh, I32))
                store_at(b, entry.get(), nodes, slot)
                node_count.set(b.add(fresh, const(I64, 1)))
                bump(b, counts, b.add(here, const(I64, 1)))
            node.set(b.sext(entry.get(), I64))
            lv.set(b.add(here, const(I64, 1)))
            store_at(b, node.get(), path, lv.get())
        rows_loop.break_if(aborted.get())
        for a in range(3):
            prev[a].set(first[a])
        prev_valid.set(lv.get())
        with if_(b, b.icmp_signed(">=", node.get(), const(I64, 0))):
            store_at(b, inside, nodes, b.add(b.mul(node.get(), const(I64, 8)), _child_index(b, xyz, const(I32, 0))))
            # a node whose eight entries are all inside becomes an inside entry of its parent
            p = Local(b, I64, b.sub(level, const(I64, 1)), "p")
            with while_true(b) as merge:
                merge.break_if(b.icmp_signed("<", p.get(), const(I64, 1)))
                row = b.bitcast(at(b, nodes, b.mul(load_at(b, path, p.get()), const(I64, 8))),
                                ir.PointerType(ir.VectorType(I32, 8)))
                entries = b.load(row, align=4)
                every = entries
                for width in (4, 2, 1):  # AND of the eight entries: -1 only if each is -1
                    lo = b.shuffle_vector(every, every, ir.Constant(ir.VectorType(I32, width), list(range(width))))
                    hi = b.shuffle_vector(every, every, ir.Constant(ir.VectorType(I32, width),
                                                                   list(range(width, 2 * width))))
                    every = b.and_(lo, hi)
                merge.break_if(b.icmp_signed("!=", b.extract_element(every, const(I32, 0)), inside))
                parent = load_at(b, path, b.sub(p.get(), const(I64, 1)))
                bit = b.trunc(b.sub(level, p.get()), I32)
                store_at(b, inside, nodes, b.add(b.mul(parent, const(I64, 8)), _child_index(b, xyz, bit)))
                bump(b, counts, p.get(), -1)
                p.set(b.sub(p.get(), const(I64, 1)))
        done.set(b.add(r, const(I64, 1)))
    store_at(b, node_count.get(), state, abi.NODE_COUNT)
    copy_words(b, counts, 0, state, abi.LEVEL_COUNTS, levels)
    b.ret(done.get())


def emit_octree_subtree_rows(module: ir.Module):
    fn, b = define(module, abi.OCTREE_SUBTREE_ROWS)
    coords, n, below = fn.args
    below32 = b.trunc(below, I32)
    # the first voxel creates a node at every level between the root and the voxels
    rows = Local(b, I64, b.select(b.icmp_signed(">", n, const(I64, 0)), b.sub(below, const(I64, 1)), const(I64, 0)),
                 "rows")
    with for_range(b, n, start=const(I64, 1)) as v:
        here = [load_at(b, coords, b.add(b.mul(v, const(I64, 3)), const(I64, a))) for a in range(3)]
        before = [load_at(b, coords, b.add(b.mul(b.sub(v, const(I64, 1)), const(I64, 3)), const(I64, a)))
                  for a in range(3)]
        # a voxel differing from the previous one first at bit t adds a node at each of the t levels
        # above the voxels that it does not share (t = 0: the same leaf parent), capped at below - 1
        top = _top_differing_bit(b, here, before)
        top = b.select(b.icmp_signed("<", top, b.sub(below32, const(I32, 1))), top, b.sub(below32, const(I32, 1)))
        top = b.select(b.icmp_signed("<", top, const(I32, 0)), const(I32, 0), top)
        rows.set(b.add(rows.get(), b.sext(top, I64)))
    b.ret(rows.get())


def build_octree_index() -> ir.Module:
    """The octree index's module."""
    module = ir.Module(name="implc_octree_index")
    emit_octree_insert(module)
    emit_octree_traverse(module)
    emit_octree_mark_inside(module)
    emit_octree_subtree_rows(module)
    return module


OCTREE_INDEX = Library(Source(build_octree_index, "implc-octree-index", max_parts=2), abi.OCTREE_ENTRIES)
