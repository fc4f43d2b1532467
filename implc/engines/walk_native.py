"""The subdivision walk, Fig. 1 of the paper, written once over an evaluator (:class:`Evaluator`).

A depth-first walk with one frame per level (:data:`implc.native.abi.WALK_FRAME_WORDS`): expanding a frame has the
evaluator enclose its octant's eight children; those that may meet the surface are visited in Morton order,
each entered with the context the evaluator derives for it from its parent's (a live-term mask, a simplified
program). A task starts from the evaluator's context at its octant. The children of an octant one level
above the leaves are the voxels (with ``refine``, those one of whose eighths may meet the surface), written
with what the evaluator keeps per voxel (``out_masks``); their unit normals (and, where ``out_flags`` is not
NULL, their flags for a second look) come from the evaluator eight at a time before the voxels leave the
call, and the flagged ones get the evaluator's second look, which marks those it proves empty for
:func:`implc.engines.compiled.tighten_native.emit_drop_marked` to drop. Where ``inside`` is not NULL (a solid),
every child
whose enclosure lies below 0 is written there too (:data:`implc.native.abi.INSIDE_WORDS` each). Resumable: when the
output is full or the cancel flag is raised it returns with its frames and state intact (layouts in
:mod:`implc.native.abi`).

An evaluator whose context is per octant (``octant_context``: the tape engine's programs) gets the normals
of the voxels below each octant two levels above the leaves, and the second look below each octant three
levels above them (or two, where that one's program is a fifth shorter), with the context of that octant,
valid for every voxel below it. One that carries its context per voxel (the compiled kernels' masks) gets
whole blocks of eight, and the second look once per call.
"""

from __future__ import annotations

from llvmlite import ir

from ..compiler.llvm.control import (
    I32,
    I64,
    Local,
    at,
    bit_intrinsic,
    bump,
    const,
    define,
    for_set_bits,
    if_,
    load_at,
    local_array,
    store_at,
    while_true,
)
from ..native import abi

DOUBLE = ir.DoubleType()

NORMALS_BATCH = 512
"""Voxels an evaluator whose context is per voxel gets normals for at once (or fewer, when the call ends):
fewer calls, their rows still in cache."""


class Evaluator:
    """What the walk asks of an evaluator: IR emitted at the walk's builder (``walk.b``), in the walk's
    function. ``level`` is an i64 value, ``cell`` three i32 values (an octant at ``level``), ``c`` an
    i32 child index (0-7, bit a: the upper half along axis a)."""

    octant_context = False
    """Whether the context is per octant (normals and second look flushed per octant, see the module)."""

    def begin(self, walk: Walk) -> None:
        """At the function's entry: read the evaluator's words (``walk.evaluator``)."""

    def start(self, walk: Walk, level, cell) -> None:
        """A new task at the octant ``cell`` of ``level``: its context."""
        raise NotImplementedError

    def enclose(self, walk: Walk, level, cell):
        """Enclose the eight children of the octant ``cell`` at ``level`` with its context; returns three i32
        masks (bit c: child c): may meet the surface, lies below 0 (inside), a choice decided (its context
        may be shorter than the octant's)."""
        raise NotImplementedError

    def refine(self, walk: Walk, level, c, leaf):
        """Whether one of the eight boxes below leaf ``c`` (cell ``leaf``) of the octant at ``level``, just
        enclosed, may meet the surface (an i1)."""
        raise NotImplementedError

    def enter(self, walk: Walk, level, c, decided) -> None:
        """The context of child ``c`` of the octant at ``level`` (its own from ``level + 1``); ``decided``:
        an i1, whether its enclosure decided a choice."""
        raise NotImplementedError

    def leaf(self, walk: Walk, level, c, slot) -> None:
        """Voxel ``c`` of the octant at ``level`` is written at row ``slot`` (an i64), branch-free: what the
        evaluator keeps per voxel (``walk.out_masks``)."""

    def size(self, walk: Walk, level):
        """The length of the context at ``level`` (an i64: for the statistics, and where the context is per
        octant, which of two levels' the second look takes), or None."""
        return None

    def normals(self, walk: Walk, level, first, count) -> None:
        """Unit normals of the ``count`` voxels from row ``first`` (and their flags where
        ``walk.out_flags`` is not NULL) with the context of their ancestor at ``level``."""
        raise NotImplementedError

    def second_look(self, walk: Walk, level, first, count) -> None:
        """Mark the flagged ones of the ``count`` voxels from row ``first`` that a tighter test proves on
        their side (:data:`implc.engines.second_look_native.OUTSIDE`,
        :data:`~implc.engines.second_look_native.INSIDE`), with the
        context of their ancestor at ``level``."""
        raise NotImplementedError


class Walk:
    """The walk's function as the evaluator sees it: its builder, arguments and frames, and the voxels'
    geometry (``leaf_geom``: the origin, then their size)."""

    def __init__(self, module: ir.Module, entry):
        self.module = module
        self.fn, self.b = define(module, entry)
        (self.evaluator, self.prune, self.refine, self.geom, self.state, self.frames, self.out, self.out_masks,
         self.out_normals, self.out_flags, self.capacity, self.inside, self.inside_capacity, self.stats,
         self.cancel) = self.fn.args
        b = self.b
        self.pruning = b.icmp_signed("!=", self.prune, const(I64, 0))
        self.depth = load_at(b, self.state, abi.WALK_DEPTH)
        self.task_level = load_at(b, self.state, abi.WALK_TASK_LEVEL)
        self.has_flags = b.icmp_unsigned("!=", self.out_flags, ir.Constant(self.out_flags.type, None))
        self.leaf_geom = local_array(b, DOUBLE, 6, "leaf_geom")  # the origin, then the voxels' size
        for a in range(3):
            store_at(b, load_at(b, self.geom, a), self.leaf_geom, a)
            store_at(b, load_at(b, self.geom, b.add(b.mul(self.depth, const(I64, 3)), const(I64, 6 + a))),
                     self.leaf_geom, 3 + a)

    def frame(self, level, k):
        """&frame[level][k] (k: 0-2 the octant's cell, 3 the children still to visit, 4 those with a
        choice decided)."""
        b = self.b
        return at(b, self.frames, b.add(b.mul(level, const(I64, abi.WALK_FRAME_WORDS)), const(I64, k)))

    def cell(self, level):
        return [self.b.load(self.frame(level, a)) for a in range(3)]

    def child_cell(self, level, c):
        """The cell of child ``c`` (an i32 value or a Python int) of the octant at ``level``."""
        b = self.b
        bits = [const(I32, (c >> a) & 1) if isinstance(c, int) else b.and_(b.lshr(c, const(I32, a)), const(I32, 1))
                for a in range(3)]
        return [b.add(b.shl(p, const(I32, 1)), bit) for p, bit in zip(self.cell(level), bits)]

    def flags_from(self, first):
        """The voxels' flags from row ``first`` on (NULL where the walk gets none)."""
        b = self.b
        return b.select(self.has_flags, b.gep(self.out_flags, [first]), self.out_flags)

    def levels_above_leaves(self, k):
        """The level k above the leaves, or the task's where that lies below it."""
        b = self.b
        above = b.sub(self.depth, const(I64, k))
        return b.select(b.icmp_signed(">", above, self.task_level), above, self.task_level)


def append_inside(b: ir.IRBuilder, inside, count: Local, cells, level, inside_bits):
    """Append the eight children ``cells`` (per child, three i32) of one octant at ``level`` (i32) whose
    bit is set in ``inside_bits`` (i32, bit c: child c) to ``inside`` (:data:`implc.native.abi.INSIDE_WORDS` per
    row), in Morton order and branch-free (every child is written, only the inside ones are kept)."""
    n = count.get()
    for c in range(8):
        row = b.mul(n, const(I64, abi.INSIDE_WORDS))
        for a in range(3):
            store_at(b, cells[c][a], inside, b.add(row, const(I64, a)))
        store_at(b, level, inside, b.add(row, const(I64, 3)))
        n = b.add(n, b.zext(b.trunc(b.lshr(inside_bits, const(I32, c)), ir.IntType(1)), I64))
    count.set(n)


def emit_walk(module: ir.Module, entry, evaluator: Evaluator) -> ir.Function:
    """Define ``entry`` (with :data:`implc.native.abi.WALK_PARAMS`) in ``module``: the walk over ``evaluator``."""
    walk = Walk(module, entry)
    b, state, stats, depth, task_level = walk.b, walk.state, walk.stats, walk.depth, walk.task_level
    solid = b.icmp_unsigned("!=", walk.inside, ir.Constant(walk.inside.type, None))
    refining = b.icmp_signed("!=", walk.refine, const(I64, 0))
    evaluator.begin(walk)
    count = Local(b, I64, 0, "count")
    inside_count = Local(b, I64, 0, "inside_count")
    normals_done = Local(b, I64, 0, "normals_done")  # voxels before this one have their normals
    looked = Local(b, I64, 0, "looked")  # voxels before this one had their second look
    octant_start = Local(b, I64, 0, "octant_start")  # the first voxel of the octant at normals_level
    normals_level, look_level = walk.levels_above_leaves(2), walk.levels_above_leaves(3)
    ctpop, cttz = bit_intrinsic(module, "ctpop"), bit_intrinsic(module, "cttz")

    # the walk's position in registers while it runs, written back to ``state`` when it returns
    phase = Local(b, I64, load_at(b, state, abi.WALK_PHASE), "phase")
    at_level = Local(b, I64, load_at(b, state, abi.WALK_LEVEL), "level")
    needs_children = Local(b, I64, load_at(b, state, abi.WALK_PENDING), "pending")
    with if_(b, b.icmp_signed("==", phase.get(), const(I64, 0))):  # a new task
        evaluator.start(walk, task_level, walk.cell(task_level))
        at_level.set(task_level)
        needs_children.set(const(I64, 1))
        phase.set(const(I64, 1))

    def flush_normals(whole_blocks=False):
        """Normals of the voxels written since the last flush (``whole_blocks``: of a multiple of eight, and
        where the context is per voxel, once :data:`NORMALS_BATCH` wait)."""
        first = normals_done.get()
        pending = b.sub(count.get(), first)
        least = 0
        if whole_blocks:
            pending = b.and_(pending, const(I64, -8))
            least = 0 if evaluator.octant_context else NORMALS_BATCH - 1
        with if_(b, b.icmp_signed(">", pending, const(I64, least))):
            evaluator.normals(walk, normals_level, first, pending)
            normals_done.set(b.add(first, pending))

    def flush_look(upto, level):
        """The second look at the voxels flagged since the last one, up to ``upto``, with the context of
        ``level`` (all of them lie below its octant)."""
        first = looked.get()
        pending = b.sub(upto, first)
        with if_(b, b.and_(walk.has_flags, b.icmp_signed(">", pending, const(I64, 0)))):
            evaluator.second_look(walk, level, first, pending)
            looked.set(upto)

    def leave_normals_octant():
        """The octant at ``normals_level`` is done: its voxels' normals; its second look now, with its own
        context, where that is a fifth shorter than the one at ``look_level`` or more (fuller batches do
        not pay for that: Min/Max models such as Prospero), after the voxels of its siblings still waiting."""
        flush_normals()
        shorter = b.icmp_signed("<", b.mul(evaluator.size(walk, normals_level), const(I64, 5)),
                                b.mul(evaluator.size(walk, look_level), const(I64, 4)))
        with if_(b, shorter):
            flush_look(octant_start.get(), look_level)
            flush_look(normals_done.get(), normals_level)
        octant_start.set(normals_done.get())

    def expand(level):
        """Enclose the children of the octant in frame ``level``; keep those that may meet the surface
        (the leaves: write them)."""
        child = b.add(level, const(I64, 1))
        kept, below, decided = evaluator.enclose(walk, level, walk.cell(level))
        bump(b, stats, 0, 8)
        refined = Local(b, I32, kept, "refined")  # with refine, a leaf stays only if one of its eighths may meet F
        with if_(b, b.and_(b.icmp_signed("==", child, depth), refining)):
            with for_set_bits(b, kept) as c:
                empty = b.not_(evaluator.refine(walk, level, c, walk.child_cell(level, c)))
                drop = b.select(empty, b.shl(const(I32, 1), c), const(I32, 0))
                refined.set(b.and_(refined.get(), b.not_(drop)))
                bump(b, stats, 0, 8)
        kept = refined.get()
        with if_(b, solid):  # children whose box lies inside
            append_inside(b, walk.inside, inside_count, [walk.child_cell(level, c) for c in range(8)],
                          b.trunc(child, I32), below)
        bump_by = [(b.add(child, const(I64, 1)), b.zext(b.call(ctpop, [kept]), I64))]
        size = evaluator.size(walk, level)
        if size is not None:  # MPR's live ops per octant, per level
            bump_by += [(b.add(level, const(I64, abi.WALK_LEVELS)), size),
                        (b.add(level, const(I64, 2 * abi.WALK_LEVELS)), const(I64, 1))]
        for index, amount in bump_by:
            slot = at(b, stats, index)
            b.store(b.add(b.load(slot), amount), slot)
        with b.if_else(b.icmp_signed("==", child, depth)) as (leaves, inner):
            with leaves:  # the kept children are voxels: written in Morton order (branch-free)
                n = count.get()
                for c in range(8):
                    for a, coord in enumerate(walk.child_cell(level, c)):
                        store_at(b, coord, walk.out, b.add(b.mul(n, const(I64, 3)), const(I64, a)))
                    evaluator.leaf(walk, level, const(I32, c), n)
                    n = b.add(n, b.zext(b.trunc(b.lshr(kept, const(I32, c)), ir.IntType(1)), I64))
                count.set(n)
                flush_normals(whole_blocks=True)
                b.store(const(I32, 0), walk.frame(level, 3))
            with inner:
                b.store(kept, walk.frame(level, 3))
                b.store(b.and_(decided, kept), walk.frame(level, 4))

    with while_true(b) as loop:  # one octant per turn: its children enclosed, then the next octant entered
        loop.break_if(b.icmp_signed("==", phase.get(), const(I64, 2)))
        loop.break_if(b.icmp_signed("!=", b.load_atomic(walk.cancel, "monotonic", 4), const(I32, 0)))
        with if_(b, b.icmp_signed("!=", needs_children.get(), const(I64, 0))):
            level = at_level.get()
            leaf_parent = b.icmp_signed("==", b.add(level, const(I64, 1)), depth)
            no_room = b.icmp_signed(">", b.add(count.get(), const(I64, 8)), walk.capacity)
            loop.break_if(b.and_(leaf_parent, no_room))
            no_inside_room = b.icmp_signed(">", b.add(inside_count.get(), const(I64, 8)), walk.inside_capacity)
            loop.break_if(b.and_(solid, no_inside_room))
            expand(level)
            needs_children.set(const(I64, 0))
        with while_true(b) as climb:  # every child of the octant in hand visited: back to its parent
            level = at_level.get()
            climb.break_if(b.icmp_unsigned("!=", b.load(walk.frame(level, 3)), const(I32, 0)))
            if evaluator.octant_context:
                with if_(b, b.icmp_signed("==", level, normals_level)):
                    leave_normals_octant()
                with if_(b, b.icmp_signed("==", level, look_level)):
                    flush_normals()
                    flush_look(normals_done.get(), look_level)
            done = b.icmp_signed("==", level, task_level)  # the task is done
            with if_(b, done):
                phase.set(const(I64, 2))
            climb.break_if(done)
            at_level.set(b.sub(level, const(I64, 1)))
        with if_(b, b.icmp_signed("!=", phase.get(), const(I64, 2))):  # into the next kept child, in Morton order
            level = at_level.get()
            remaining = b.load(walk.frame(level, 3))
            c = b.call(cttz, [remaining, const(ir.IntType(1), 1)])
            b.store(b.and_(remaining, b.sub(remaining, const(I32, 1))), walk.frame(level, 3))
            child = b.add(level, const(I64, 1))
            for a, coord in enumerate(walk.child_cell(level, c)):
                b.store(coord, walk.frame(child, a))
            evaluator.enter(walk, level, c, b.trunc(b.lshr(b.load(walk.frame(level, 4)), c), ir.IntType(1)))
            at_level.set(child)
            needs_children.set(const(I64, 1))
    flush_normals()  # leaving (done, output full or cancelled): every voxel written has its normal
    flush_look(normals_done.get(), look_level)
    for word, value in ((abi.WALK_PHASE, phase), (abi.WALK_LEVEL, at_level), (abi.WALK_PENDING, needs_children),
                        (abi.WALK_INSIDE_COUNT, inside_count)):
        store_at(b, value.get(), state, word)
    b.ret(count.get())
    return walk.fn
