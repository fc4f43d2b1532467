"""The tape engine as an evaluator of the walk (:mod:`implc.engines.walk_native`): each octant runs its own program.

Enclosing an octant's children runs ``tape_interval`` over the octant's program, recording the Min/Max
choices each child's enclosure decided; entering a child gives it its own program, ``tape_simplify``'d by
those choices (or its parent's, where none was decided, pruning is off or the child lies just above the
leaves), so that below an octant every decided branch costs nothing; a task starts from the full program
simplified down the path from the root to its octant. The voxels' unit normals come eight at a time from
``tape_dual`` over the program two levels above the leaves (valid for every voxel below that octant, and
barely longer than their parents'), through the normals block of :mod:`implc.engines.normals_native`; the second
look is :mod:`implc.engines.tape.tighten_native`'s, with the program the walk gives (three levels above the leaves, so
that its batches of eight fill, or two where that program is a fifth shorter: bear's, whose negligible terms
read constants there). The evaluator's words are
:data:`implc.native.abi.TAPE_EVALUATOR_WORDS`."""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import (
    I32,
    I64,
    at,
    const,
    define_internal,
    for_range,
    if_,
    load_at,
    local_array,
    store_at,
)
from ...compiler.llvm.rows import load_xyz, store_xyz
from ...compiler.llvm.vector import DOUBLE, broadcast
from ...native import abi
from ..normals_native import emit_normals_body
from ..walk_native import Evaluator, Walk, emit_walk
from .interpreter_native import I8, LANES, V8, interval_findings
from .plan_native import call_simplify

FLOAT = ir.FloatType()
_P = ir.PointerType


def emit_tape_normals(module: ir.Module, dual: ir.Function) -> ir.Function:
    """``tape_normals(header, program, length, output, slots, leaf_geom, coords, n, out, flags)`` (internal):
    unit normals of ``n`` voxels, the gradient from ``dual`` over the program given (and their flags for
    tightening where ``flags`` is not NULL)."""
    fn, b = define_internal(module, "implc.tape.normals", ir.VoidType(),
                            [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(DOUBLE), _P(I32), I64, _P(FLOAT), _P(I8)])
    header, program, length, output, slots, leaf_geom, coords, n, out, flags = fn.args
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


class TapeEvaluator(Evaluator):
    """The walk's evaluator over the tape engine's internal functions (see the module)."""

    octant_context = True

    def __init__(self, prefill: ir.Function, interval: ir.Function, simplify: tuple, normals: ir.Function,
                 tighten: ir.Function):
        self.prefill, self.interval = prefill, interval
        self.simplify = simplify  # tape_simplify and its substituting variant
        self.normals_fn, self.tighten = normals, tighten

    def begin(self, walk: Walk) -> None:
        b, words = walk.b, walk.evaluator
        self.words = words
        self.header = b.inttoptr(load_at(b, words, abi.TAPE_HEADER), _P(I64))
        self.tapes = b.inttoptr(load_at(b, words, abi.TAPE_TAPES), _P(I32))
        self.choices = b.inttoptr(load_at(b, words, abi.TAPE_CHOICES), _P(I8))
        self.slots = b.inttoptr(load_at(b, words, abi.TAPE_SLOTS), _P(DOUBLE))
        self.need = b.inttoptr(load_at(b, words, abi.TAPE_NEED), _P(I32))
        self.marks = b.inttoptr(load_at(b, words, abi.TAPE_MARKS), _P(I8))
        self.remap = b.inttoptr(load_at(b, words, abi.TAPE_REMAP), _P(I32))
        self.length = load_at(b, self.header, abi.PROGRAM_LENGTH)
        self.grid_depth = load_at(b, words, abi.TAPE_GRID_DEPTH)
        self.box = local_array(b, DOUBLE, 6 * LANES, "box")
        self.result = local_array(b, DOUBLE, 2 * LANES, "result")
        self.substituted = local_array(b, I64, 1, "substituted")
        self.substitution_level = b.sub(self.grid_depth, const(I64, 2))

    # -- each level's program and choices ------------------------------------------------------------
    def program_of(self, b, level):
        return b.inttoptr(load_at(b, self.words, b.add(level, const(I64, abi.TAPE_PROGRAMS))), _P(I32))

    def length_of(self, b, level):
        return load_at(b, self.words, b.add(level, const(I64, abi.TAPE_PROGRAMS + abi.WALK_LEVELS)))

    def output_at(self, b, level):
        return at(b, self.words, b.add(level, const(I64, abi.TAPE_PROGRAMS + 2 * abi.WALK_LEVELS)))

    def program(self, b, level):
        """The program of ``level``: instructions, count, output slot."""
        return self.program_of(b, level), self.length_of(b, level), b.load(self.output_at(b, level))

    def set_program(self, b, level, ptr, n, result_slot):
        store_at(b, b.ptrtoint(ptr, I64), self.words, b.add(level, const(I64, abi.TAPE_PROGRAMS)))
        store_at(b, n, self.words, b.add(level, const(I64, abi.TAPE_PROGRAMS + abi.WALK_LEVELS)))
        b.store(result_slot, self.output_at(b, level))

    def choices_of(self, b, level):
        return b.gep(self.choices, [b.mul(b.mul(level, self.length), const(I64, LANES))])

    def exact_level(self, b, level):
        """The level whose program gives F's partials below the octant at ``level``: its own, or where the
        program two levels above the leaves has a negligible term replaced (:data:`implc.native.abi.TAPE_SUBSTITUTED`)
        and ``level`` is that one or below (a task's walk may start there), the parent of that octant's."""
        replaced = b.and_(b.icmp_signed(">=", level, self.substitution_level),
                          b.icmp_unsigned("!=", load_at(b, self.words, abi.TAPE_SUBSTITUTED), const(I64, 0)))
        return b.select(replaced, b.sub(self.substitution_level, const(I64, 1)), level)

    def worth_simplifying(self, b, level, found):
        """The children (i8 mask) of the octant at ``level`` to get programs of their own, from what
        ``tape_interval`` found (i16): those with a choice decided, and at the level where negligible terms
        are replaced (two above the grid's leaves) those with one."""
        decided, negligible = interval_findings(b, found)
        here = b.icmp_signed("==", b.add(level, const(I64, 1)), self.substitution_level)
        return b.select(here, b.or_(decided, negligible), decided)

    def enclose_children(self, walk: Walk, level, cell, program_level=None):
        """Enclose the eight children of the octant ``cell`` (three i32) at ``level`` with the program of
        ``program_level`` (default: that level's), recording its choices at ``level``; returns the lanes with
        a decided choice or a negligible term (i16, as ``tape_interval``). The enclosures are in ``self.result``
        (lo, then hi)."""
        b, geom = walk.b, walk.geom
        program_level = level if program_level is None else program_level
        child = b.add(level, const(I64, 1))
        vbox = b.bitcast(self.box, _P(V8))
        ivec = ir.VectorType(I32, LANES)
        for a in range(3):  # the children's boxes exactly as the compiled octant kernels make them
            origin, pad = broadcast(b, load_at(b, geom, a), LANES), broadcast(b, load_at(b, geom, 3 + a), LANES)
            h = broadcast(b, load_at(b, geom, b.add(b.mul(child, const(I64, 3)), const(I64, 6 + a))), LANES)
            twice = broadcast(b, b.shl(cell[a], const(I32, 1)), LANES)
            index = b.add(twice, ir.Constant(ivec, [(c >> a) & 1 for c in range(LANES)]))
            i_lo, i_hi = b.uitofp(index, V8), b.uitofp(b.add(index, ir.Constant(ivec, [1] * LANES)), V8)
            b.store(b.fsub(b.fadd(origin, b.fmul(i_lo, h)), pad), b.gep(vbox, [const(I64, a)]), align=8)
            b.store(b.fadd(b.fadd(origin, b.fmul(i_hi, h)), pad), b.gep(vbox, [const(I64, 3 + a)]), align=8)
        return b.call(self.interval, [self.header, *self.program(b, program_level), self.slots,
                                      self.choices_of(b, level), self.box, self.result])

    def enclosure(self, b):
        vresult = b.bitcast(self.result, _P(V8))
        return b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)

    @staticmethod
    def may_meet(b, lo, hi):
        """The lanes whose enclosure contains 0 or is undefined (NaN), as an i32 mask."""
        zero = ir.Constant(V8, [0.0] * LANES)
        lanes = b.or_(b.and_(b.fcmp_ordered("<=", lo, zero), b.fcmp_ordered(">=", hi, zero)),
                      b.or_(b.fcmp_unordered("uno", lo, lo), b.fcmp_unordered("uno", hi, hi)))
        return b.zext(b.bitcast(lanes, I8), I32)

    def program_for_child(self, walk: Walk, level, c, decided):
        """The program of child ``c`` (i32) of the octant at ``level``: simplified by its choices where one
        was decided (``decided``: i1) and pruning is on, else the octant's own. Two levels above the grid's
        leaves it also reads a constant for each negligible exponential term (``tape_simplify_substituting``:
        on smooth blends most of the program just above the leaves), whose partials are not F's:
        the normals below it run its parent's (:meth:`exact_level`), the second look both (:meth:`second_look`).
        A child just
        above the leaves (of the grid, :data:`implc.native.abi.TAPE_GRID_DEPTH`, wherever this walk stops) takes the
        octant's own too: its program would enclose the eight leaves once and serve nothing else, and
        simplifying costs two passes over the octant's program, about a third of what enclosing eight boxes
        costs per instruction, for little: programs shrink by a few per cent there (``implc bench --sections
        models`` counts the live ops per octant, and measures the time)."""
        b = walk.b
        child = b.add(level, const(I64, 1))
        above_the_leaves = b.icmp_signed(">=", child, b.sub(self.grid_depth, const(I64, 1)))
        with b.if_else(b.and_(b.and_(walk.pruning, decided), b.not_(above_the_leaves))) as (simplified, shared):
            with simplified:
                target = b.gep(self.tapes, [b.mul(b.mul(child, self.length), const(I64, abi.INSTRUCTION_WORDS))])
                stamp = b.add(load_at(b, self.words, abi.TAPE_STAMP), const(I64, 1))
                with if_(b, b.icmp_signed(">=", stamp, const(I64, 0x7FFFFFFF))):  # start the stamps over
                    with for_range(b, load_at(b, self.header, abi.PROGRAM_SLOT_COUNT)) as k:
                        store_at(b, const(I32, 0), self.need, k)
                stamp = b.select(b.icmp_signed(">=", stamp, const(I64, 0x7FFFFFFF)), const(I64, 1), stamp)
                store_at(b, stamp, self.words, abi.TAPE_STAMP)
                arguments = [*self.program(b, level), self.choices_of(b, level), b.zext(c, I64), target, self.need,
                             b.trunc(stamp, I32), self.marks, self.remap, self.output_at(b, child),
                             load_at(b, self.header, abi.PROGRAM_ZERO)]
                replacing = b.icmp_signed("==", child, self.substitution_level)
                n = call_simplify(b, self.simplify, arguments, self.substituted, replacing)
                with if_(b, replacing):
                    store_at(b, load_at(b, self.substituted, 0), self.words, abi.TAPE_SUBSTITUTED)
                self.set_program(b, child, target, n, b.load(self.output_at(b, child)))
            with shared:
                self.set_program(b, child, *self.program(b, level))
                with if_(b, b.icmp_signed("==", child, self.substitution_level)):
                    store_at(b, const(I64, 0), self.words, abi.TAPE_SUBSTITUTED)

    # -- the walk's entries ----------------------------------------------------------------------------
    def start(self, walk: Walk, level, cell) -> None:
        """The full program simplified down the path from the root to the task's octant."""
        b = walk.b
        b.call(self.prefill, [self.header, self.slots, self.remap])  # constants, and the names simplify renames
        self.set_program(b, const(I64, 0), b.inttoptr(load_at(b, self.header, abi.PROGRAM_INSTRUCTIONS), _P(I32)),
                         self.length, load_at(b, self.header, abi.PROGRAM_OUTPUT))
        with for_range(b, level) as above_level:
            above = b.trunc(b.sub(level, above_level), I32)  # the ancestor at ``above_level``: the cell >> above
            ancestor = [b.lshr(cell[a], above) for a in range(3)]
            decided = self.worth_simplifying(b, above_level, self.enclose_children(walk, above_level, ancestor))
            below = b.sub(above, const(I32, 1))
            c = const(I32, 0)
            for a in range(3):
                c = b.or_(c, b.shl(b.and_(b.lshr(cell[a], below), const(I32, 1)), const(I32, a)))
            self.program_for_child(walk, above_level, c, b.trunc(b.lshr(b.zext(decided, I32), c), ir.IntType(1)))

    def enclose(self, walk: Walk, level, cell):
        b = walk.b
        decided = self.worth_simplifying(b, level, self.enclose_children(walk, level, cell))
        f_lo, f_hi = self.enclosure(b)
        below = b.zext(b.bitcast(b.fcmp_ordered("<", f_hi, ir.Constant(V8, [0.0] * LANES)), I8), I32)
        return self.may_meet(b, f_lo, f_hi), below, b.zext(decided, I32)

    def refine(self, walk: Walk, level, c, leaf):
        b = walk.b
        self.enclose_children(walk, b.add(level, const(I64, 1)), leaf, program_level=level)
        return b.icmp_unsigned("!=", self.may_meet(b, *self.enclosure(b)), const(I32, 0))

    def enter(self, walk: Walk, level, c, decided) -> None:
        self.program_for_child(walk, level, c, decided)

    def size(self, walk: Walk, level):
        return self.length_of(walk.b, level)

    def normals(self, walk: Walk, level, first, count) -> None:
        b = walk.b
        offset = b.mul(first, const(I64, 3))
        level = self.exact_level(b, level)
        b.call(self.normals_fn, [self.header, *self.program(b, level), self.slots, walk.leaf_geom,
                                 b.gep(walk.out, [offset]), count, b.gep(walk.out_normals, [offset]),
                                 walk.flags_from(first)])

    def second_look(self, walk: Walk, level, first, count) -> None:
        """The look with the octant's own program (where a negligible term reads a constant, its proofs
        still hold: docs/soundness.md), then, where that program has a term replaced, with the exact one
        (:meth:`exact_level`) at the leaves it left flagged: never a voxel more than the exact program's
        look alone keeps, for less work than that look alone (``implc bench --sections models``)."""
        b = walk.b

        def look(at_level):
            b.call(self.tighten, [self.header, *self.program(b, at_level), self.slots,
                                  self.choices_of(b, b.add(walk.depth, const(I64, 1))), walk.geom, walk.depth,
                                  b.gep(walk.out, [b.mul(first, const(I64, 3))]), b.gep(walk.out_flags, [first]),
                                  count])
        look(level)
        exact = self.exact_level(b, level)
        with if_(b, b.icmp_signed("!=", exact, level)):
            look(exact)


def emit_tape_subdivide(module: ir.Module, prefill: ir.Function, interval: ir.Function, simplify: tuple,
                        normals: ir.Function, tighten: ir.Function) -> ir.Function:
    """``implc_tape_subdivide``: the walk over the tape engine (``simplify``: ``tape_simplify`` and its
    substituting variant)."""
    return emit_walk(module, abi.TAPE_SUBDIVIDE, TapeEvaluator(prefill, interval, simplify, normals, tighten))
