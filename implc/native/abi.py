"""The native ABI: every exported entry point and the memory layouts native code shares with Python.

Each entry point is declared once, here: its name, its parameters with their kinds, its return kind.
The code generators declare functions from :meth:`Entry.llvm_type` (and call through function pointers
of that type); :class:`implc.native.jit.NativeModule` binds them with :meth:`Entry.ctypes_type`. A signature
cannot differ between the two sides, and a call through ctypes cannot disagree with the code it calls.

Pointers cross as plain addresses (``ctypes.c_void_p``: numpy's ``.ctypes.data`` or None for NULL).
"""

from __future__ import annotations

import ctypes
from dataclasses import dataclass

from llvmlite import ir

# -- kinds of parameters and results --------------------------------------------------------------
_LLVM_KINDS = {
    "i32": ir.IntType(32),
    "i64": ir.IntType(64),
    "f64*": ir.PointerType(ir.DoubleType()),
    "f32*": ir.PointerType(ir.FloatType()),
    "i8*": ir.PointerType(ir.IntType(8)),
    "i32*": ir.PointerType(ir.IntType(32)),
    "i64*": ir.PointerType(ir.IntType(64)),
    "f64": ir.DoubleType(),
    "fn*": ir.PointerType(ir.IntType(8)),  # the address of another entry point
}
_CTYPES_KINDS = {"i32": ctypes.c_int32, "i64": ctypes.c_int64, "f64": ctypes.c_double}  # every pointer kind: c_void_p


@dataclass(frozen=True)
class Entry:
    """One exported native function: ``name(params...) -> returns`` (None: void)."""

    name: str
    params: tuple[tuple[str, str], ...]  # (parameter name, kind)
    returns: str | None = None

    def llvm_type(self) -> ir.FunctionType:
        ret = ir.VoidType() if self.returns is None else _LLVM_KINDS[self.returns]
        return ir.FunctionType(ret, [_LLVM_KINDS[kind] for _, kind in self.params])

    def ctypes_type(self):
        def ctype(kind):
            return _CTYPES_KINDS.get(kind, ctypes.c_void_p)
        ret = None if self.returns is None else ctype(self.returns)
        return ctypes.CFUNCTYPE(ret, *[ctype(kind) for _, kind in self.params])

    @property
    def param_names(self) -> list[str]:
        return [name for name, _ in self.params]


def _entry(name, params: str, returns=None) -> Entry:
    """``params``: "name:kind name:kind ..." (kinds as in _LLVM_KINDS)."""
    return Entry(name, tuple((p.split(":")[0], p.split(":")[1]) for p in params.split()), returns)


# -- a surface's kernels (implc.engines.compiled.kernels_native); n is a multiple of the vector width ----
POINT = _entry("implc_point", "pts:f64* out:f64* n:i64")
POINT_FAST = Entry("implc_point_fast", POINT.params)
GRADIENT = _entry("implc_gradient", "pts:f64* out_value:f64* out_grad:f64* n:i64")
GRADIENT_LIVE = _entry("implc_gradient_live", "pts:f64* out_value:f64* out_grad:f64* n:i64 live:i64")
INTERVAL = _entry("implc_interval", "lo:f64* hi:f64* out_lo:f64* out_hi:f64* n:i64 live_in:i64* live_out:i64*")
OCTANT = _entry("implc_octant", "geom:f64* cell:i32* level:i64 live_in:i64 live_out:i64*", "i32")
SURFACE_ENTRIES = (POINT, POINT_FAST, GRADIENT, GRADIENT_LIVE, INTERVAL, OCTANT)

# ... and the mean-value module, compiled on first use
INTERVAL_MVF = Entry("implc_interval_mvf", INTERVAL.params)
OCTANT_MVF = Entry("implc_octant_mvf", OCTANT.params, OCTANT.returns)
INTERVAL_MONOTONE = Entry("implc_interval_monotone", INTERVAL.params)
BOUND_MONOTONE = _entry("implc_bound_monotone", "lo:f64* hi:f64* side:f64* out:f64* n:i64 live_in:i64*")
MEAN_VALUE_ENTRIES = (INTERVAL_MVF, OCTANT_MVF, INTERVAL_MONOTONE)
BOUND_ENTRIES = (BOUND_MONOTONE,)
"""... and the voxelizer's monotonicity bound, in a small module compiled on first use."""
BOX_GRADIENT = _entry("implc_box_gradient", "lo:f64* hi:f64* out:f64* n:i64")
BOX_GRADIENT_ENTRIES = (BOX_GRADIENT,)
"""... and the enclosures of F and its partials over boxes (eight doubles per box: F's lo, hi, then each
partial's), in a small module compiled on a surface's first mesh."""

# -- the modules every surface shares, one per process (implc.native.runtime) --------------------------
WALK_PARAMS = _entry("implc_walk", "evaluator:i64* prune:i64 refine:i64 geom:f64* state:i64* frames:i32* out:i32* "
                     "out_masks:i64* out_normals:f32* out_flags:i8* capacity:i64 inside:i32* "
                     "inside_capacity:i64 stats:i64* cancel:i32*", "i64").params
"""The subdivision walk's parameters (:mod:`implc.engines.walk_native`), the same over every evaluator: the
evaluator's words (its context and kernels: :data:`KERNEL_EVALUATOR_WORDS`, :data:`TAPE_EVALUATOR_WORDS`),
then the walk's own state and frames, its outputs (cells, per-voxel masks, normals, flags for the second
look) and the inside octants."""
SUBDIVIDE = Entry("implc_subdivide", WALK_PARAMS, "i64")
"""The walk over a surface's compiled kernels (:mod:`implc.engines.compiled.evaluator_native`)."""
DROP_MARKED = _entry("implc_drop_marked", "depth:i64 coords:i32* masks:i64* normals:f32* flags:i8* n:i64 inside:i32* "
                                          "inside_count:i64* stats:i64*", "i64")
OCTREE_INSERT = _entry("implc_octree_insert", "nodes:i32* node_capacity:i64 state:i64* coords:i32* n:i64 "
                                              "first_index:i64", "i64")
OCTREE_TRAVERSE = _entry("implc_octree_traverse", "nodes:i32* depth:i64 level:i64 out:i32* payload:i64*", "i64")
OCTREE_SUBTREE_ROWS = _entry("implc_octree_subtree_rows", "coords:i32* n:i64 below:i64", "i64")
OCTREE_MARK_INSIDE = _entry("implc_octree_mark_inside", "nodes:i32* node_capacity:i64 state:i64* rows:i32* n:i64",
                            "i64")
SPLAT = _entry("implc_splat", "px:i64* py:i64* sizes:i64* depth:f64* n:i64 size:i64 zbuf:f64* winner:i64*")
HASH_INDEX = _entry("implc_hash_index", "table:i64* bits:i64 keys:i64* n:i64 insert:i64 numbers:i64* uniques:i64* "
                                        "state:i64*", "i64")
CELL_CORNERS = _entry("implc_cell_corners", "lowest:i64* n:i64 offsets:i64* table:i64* bits:i64 uniques:i64* "
                                            "limit:i64 state:i64* numbers:i64*", "i64")
CORNER_SIGNS = _entry("implc_corner_signs", "numbers:i64* n:i64 values:f64* signs:i8*")
KUHN_TRIANGLES = _entry("implc_kuhn_triangles", "lowest:i64* offsets:i64* signs:i8* n:i64 tables:i64* "
                                                "table:i64* bits:i64 uniques:i64* limit:i64 state:i64* faces:i64* "
                                                "owner:i64*", "i64")
FAN_TRIANGLES = _entry("implc_fan_triangles", "lowest:i64* cellkey:i64* offsets:i64* signs:i8* cell_in:i8* "
                                              "face_in:i8* split:i8* n:i64 tables:i64* table:i64* bits:i64 "
                                              "uniques:i64* limit:i64 state:i64* faces:i64*", "i64")
FAN_FACES, FAN_COUNTS, FAN_EDGES, FAN_SHAPES, FAN_SHAPE, FAN_SLOTS = 0, 12, 28, 124, 1 + 4 * 27, 102
FAN_TABLES = (FAN_FACES, FAN_COUNTS, FAN_EDGES, FAN_SHAPES, FAN_SHAPE, FAN_SLOTS)
"""``implc_fan_triangles``'s tables (int64): from FAN_FACES per face its axis and the local corner of its
lowest corner (2 × 6); from FAN_COUNTS per sign case of a fan tetrahedron its triangle count (16); from
FAN_EDGES per (case, triangle, vertex) the edge among its six keys (96); from FAN_SHAPES per (face, split)
FAN_SHAPE words: the face's triangle count, then per triangle its three corners' inside flags (a local
corner, or 8: the face point) and the six keys of the fan tetrahedron over it, each (kind, local, code,
slot): the slot, below FAN_SLOTS, names the key among a cell's (its number is looked up once per cell)."""
QEF = _entry("implc_qef", "points:f64* normals:f64* mask:i8* m:i64 k:i64 project:i64 cutoff:f64 out:f64*")
BENT_CELLS = _entry("implc_bent_cells", "faces:i64* owner:i64* n:i64 normals:f64* cells:i64 mean:f64* cosine:f64 "
                                        "bent:i8*")
EDGE_ENDS = _entry("implc_edge_ends", "keys:i64* n:i64 geometry:f64* table:i64* bits:i64 values:f64* a:f64* b:f64* "
                                      "fa:f64* fb:f64*", "i64")
EDGE_ROOTS = _entry("implc_edge_roots", "phase:i64 n:i64 rows:i64* keys:i64* a:f64* b:f64* fa:f64* fb:f64* state:f64* "
                                        "f:f64* g:f64* guesses:f64* vertices:f64* normals:f64* margin:f64 "
                                        "nudge:f64 tolerance:f64", "i64")
CORNER_POINTS = _entry("implc_corner_points", "keys:i64* n:i64 geometry:f64* points:f64*")
ARRANGE_GROUPS = _entry("implc_arrange_groups", "labels:i64* n:i64 bound:i64 counts:i64* group_labels:i64* "
                                                "starts:i64* taken:i64* place:i64*", "i64")
ROWS_ENTRIES = (DROP_MARKED, ARRANGE_GROUPS)
"""... the walk's rows (:mod:`implc.engines.rows_native`), a module both engines use, ..."""
OCTREE_ENTRIES = (OCTREE_INSERT, OCTREE_TRAVERSE, OCTREE_MARK_INSIDE, OCTREE_SUBTREE_ROWS)
"""... the octree index (:mod:`implc.voxelizer.storage.octree_native`), built with a first voxelization, ..."""
SPLAT_ENTRIES = (SPLAT,)
"""... splatting (:mod:`implc.view.splat_native`), built on a first render, ..."""
DUAL_EDGES = _entry("implc_dual_edges", "lowest:i64* offsets:i64* signs:i8* n:i64 tables:i64* table:i64* bits:i64 "
                                        "uniques:i64* limit:i64 state:i64* numbers:i64*", "i64")
DUAL_POINTS = _entry("implc_dual_points", "edges:i64* m:i64 positions:f64* normals:f64* cells:i64* geometry:f64* "
                                          "cutoff:f64 margin:f64 sharp:i64 out:f64*")
DUAL_TRIANGLES = _entry("implc_dual_triangles", "cells:i64* signs:i8* edges:i64* first:i64 points:f64* start:i64 "
                                                "m:i64 tables:i64* geometry:f64* cell_table:i64* cell_bits:i64 "
                                                "dual_of_row:i64* table:i64* bits:i64 faces:i64* counts:i64*", "i64")
CONTOURING_ENTRIES = (HASH_INDEX, CELL_CORNERS, CORNER_SIGNS, KUHN_TRIANGLES, FAN_TRIANGLES, QEF, BENT_CELLS, EDGE_ENDS,
                      EDGE_ROOTS, CORNER_POINTS, DUAL_EDGES, DUAL_POINTS, DUAL_TRIANGLES)
"""... and the contouring's (:mod:`implc.meshing.contour_native`), a module of its own built on first use by the
mesher: a first voxelization does not compile it."""
FLAT_COLLAPSE = _entry("implc_flat_collapse", "faces:i64* vertices:f64* region:i64* planes:f64* inner:i8* movable:i8* "
                                              "head:i64* next:i64* dead:i8* order:i64* count:i64 passes:i64 "
                                              "min_sine:f64 stats:i64*", "i64")
MESH_SIMPLIFY_ENTRIES = (FLAT_COLLAPSE,)
"""... and the simplification of meshes' flat regions (:mod:`implc.meshing.simplify_native`), a module of its
own built on first use by ``simplify``."""
KERNEL_WALK_ENTRIES = (SUBDIVIDE,)
"""... and the compiled kernels' walk (subdivision, normals, second look), a module of its own
(:mod:`implc.engines.compiled.evaluator_native`), built on first use by a surface with compiled
kernels: a process that only runs the tape engine never compiles it."""

# -- the tape engine (implc.engines.tape.engine_native): one interpreter for every program -----------------
# (``program``: a program header, implc.engines.tape.program; ``slots``: TAPE_SLOT_DOUBLES per slot of the full
# program, 64-byte aligned; ``choices``: 8 bytes per instruction (and per level); n a multiple of 8)
TAPE_INTERVAL = _entry("implc_tape_interval", "program:i64* slots:f64* choices:i8* "
                                              "lo:f64* hi:f64* out_lo:f64* out_hi:f64* n:i64")
TAPE_GRADIENT = _entry("implc_tape_gradient", "program:i64* slots:f64* pts:f64* out_value:f64* out_grad:f64* n:i64")
TAPE_POINT = _entry("implc_tape_point", "program:i64* slots:f64* pts:f64* out_value:f64* n:i64")
"""F at points: the dual numbers' value rules without the partials (``implc_tape_gradient``'s values)."""
TAPE_SUBDIVIDE = Entry("implc_tape_subdivide", WALK_PARAMS, "i64")
"""The walk over the tape engine (:mod:`implc.engines.tape.evaluator_native`)."""
TAPE_BOX_GRADIENT = _entry("implc_tape_box_gradient", "program:i64* slots:f64* lo:f64* hi:f64* out:f64* n:i64")
"""Enclosures of F and its partials over boxes: eight doubles per box in ``out`` (F's lo, hi, then each
partial's lo, hi), as the tape engine's second look uses them."""
TAPE_GROUPED = _entry("implc_tape_grouped",
                      "program:i64* slots:f64* choices:i8* need:i32* marks:i8* remap:i32* work:i32* lo:f64* hi:f64* "
                      "starts:i64* groups:i64 pts:f64* pts_hi:f64* out_value:f64* out_grad:f64* mode:i64 "
                      "seeds:f64*")
"""F (mode 0), F and its gradient (1) at points, enclosures of F and its partials (or, with ``seeds`` not
NULL, its derivatives along the three directions there: 9 doubles) over boxes (2), or of F
alone with negligible terms replaced (3), the rows grouped by box, each group's program simplified over its
box (:mod:`implc.engines.tape.points_native`);
``choices``: 8 bytes per instruction (16 in mode 3), ``need`` zeros, ``work`` room for one program."""
TAPE_ENTRIES = (TAPE_INTERVAL, TAPE_GRADIENT, TAPE_POINT, TAPE_SUBDIVIDE, TAPE_BOX_GRADIENT, TAPE_GROUPED)

# -- layouts shared by native code and Python ------------------------------------------------------
MAX_DEPTH = 21
"""The deepest grid (2^21 cells per axis: cell indices fit in uint32 with room for a child level)."""

GEOMETRY_DOUBLES = 6 + 3 * (MAX_DEPTH + 2)
"""Subdivision geometry (``geom``): origin (3), outward pad (3), then cell size per level (3 per level,
one level past the deepest grid for leaf refinement)."""

TIGHTEN_STATS_WORDS = 2
"""``implc_drop_marked``'s counts (int64, added to): leaves flagged for the second look, leaves dropped."""
TIGHTEN_ABOVE, TIGHTEN_BELOW = 1, 4
"""The normals' flags for tightening (:data:`TIGHTEN_ABOVE`: F(c) above the linear model's reach over the
cell, so the test is whether F > 0 on all of it; :data:`TIGHTEN_BELOW`: below, F < 0); 0: kept as is."""
INSIDE_WORDS = 4
"""An inside octant, as the walk writes them where ``inside`` is not NULL (int32): its cell (i, j,
k) and its level. Its whole box lies where F < 0."""
OCTANT_INSIDE_SHIFT = 8
"""The octant kernels return bit c set where child c may meet the surface, and bit 8 + c where child c's
enclosure lies below zero (inside)."""

TAPE_SLOT_DOUBLES = 112
"""Scratch doubles per slot of a tape program (eight lanes each): its interval (two vectors) in the first
region, its dual number (four vectors) in the second, its interval and interval partials (eight vectors)
in the third."""
PROGRAM_INSTRUCTIONS, PROGRAM_LENGTH, PROGRAM_OUTPUT = 0, 1, 2
PROGRAM_CONSTANTS, PROGRAM_CONSTANT_SLOTS, PROGRAM_CONSTANT_COUNT = 3, 4, 5
PROGRAM_VARIABLES = 6
"""A program header (int64, :class:`implc.engines.tape.program.TapeProgram`): the address of the instructions,
their count, the output slot; the constant table's address, its slots' address, its row count; the slots
of x, y, z (three words, -1 where unused); then the slot count, and the slot of the exact zero constant (-1:
the program has none)."""
PROGRAM_SLOT_COUNT = 9
PROGRAM_ZERO = 10
PROGRAM_WORDS = 11
INSTRUCTION_WORDS = 5
"""A tape instruction (int32): opcode (its low :data:`OPCODE_BITS`; the bits above: the axes the value does
not depend on, bit 0 for x), output slot, three operand slots (unused ones 0; a watched sum's third word says
which of its operands an exponential gives: :data:`implc.engines.tape.program.TINY_EXPONENTS`)."""
OPCODE_BITS = 8
OPCODE_MASK = (1 << OPCODE_BITS) - 1
"""The opcode's bits of an instruction's first word."""
WALK_LEVELS = MAX_DEPTH + 2
"""Levels the walk keeps a frame (and an evaluator a context) for (0 to MAX_DEPTH + 1)."""
WALK_FRAME_WORDS = 5
"""The walk's frame per level (int32): the octant's cell (i, j, k), the children still to visit (bit c:
child c), the children with a choice decided (their context may be shorter than the octant's)."""
WALK_PHASE, WALK_LEVEL, WALK_DEPTH, WALK_TASK_LEVEL, WALK_PENDING, WALK_INSIDE_COUNT = range(6)
"""The walk's state (int64): phase (0 new task, 1 running, 2 done), the level of the frame in hand, the
grid depth, the task's level, whether the frame in hand still needs its children, the inside octants
written in the last call."""
WALK_STATE_WORDS = 6
WALK_STATS_WORDS = 3 * WALK_LEVELS
"""The walk's statistics (int64, added to): boxes enclosed, then octants kept per level (at 1 + level,
WALK_LEVELS words), then for evaluators with a size (the tape engine) instructions run per level (the
octant's level) and octants expanded per level."""
KERNEL_OCTANT, KERNEL_FINE_OCTANT, KERNEL_FINE_LEVEL, KERNEL_GRADIENT, KERNEL_POINT, KERNEL_BOUND = range(6)
"""The compiled kernels' evaluator words (int64): the addresses of the octant kernel, of the one from
``fine_level`` on (the mean-value form's, or the same), that level, of the gradient (live terms), point
(``implc_point_fast``) and monotonicity-bound kernels (0: no second look)..."""
KERNEL_MASKS = 6
"""... then each level's live-term mask (WALK_LEVELS words), then each level's children's (8 per level)."""
KERNEL_EVALUATOR_WORDS = KERNEL_MASKS + 9 * WALK_LEVELS
TAPE_HEADER, TAPE_TAPES, TAPE_CHOICES, TAPE_SLOTS, TAPE_NEED, TAPE_MARKS, TAPE_REMAP, TAPE_STAMP = range(8)
"""The tape engine's evaluator words (int64): the addresses of the program header, of room for a program
per level, of each level's choices (8 bytes per instruction), the interpreter's slots, ``need`` (stamps,
zeroed), the marks and the remap scratch of simplification, then the last stamp simplification used..."""
TAPE_GRID_DEPTH = 8
"""... then the depth of the voxelization's grid (a walk may stop above it: a plan's)..."""
TAPE_SUBSTITUTED = 9
"""... then whether the program of the octant in hand two levels above the grid's leaves has a negligible
term replaced by a constant (:mod:`implc.engines.tape.plan_native`): then it serves enclosures and a first
second look, not normals..."""
TAPE_PROGRAMS = 10
"""... then each level's program: the instructions' address (WALK_LEVELS words), their count, the output
slot (WALK_LEVELS words each)."""
TAPE_EVALUATOR_WORDS = TAPE_PROGRAMS + 3 * WALK_LEVELS

# implc_octree_insert's state (int64 words; implc_octree_mark_inside reads and updates NODE_COUNT, DEPTH
# and LEVEL_COUNTS)
NODE_COUNT, DEPTH, STARTED, PREV = 0, 1, 2, 3
"""Indices of the node count, the grid depth, whether a voxel was inserted, the previous voxel (3 words)."""
LEVEL_COUNTS = 8
"""Start of the nodes-per-level counts (MAX_DEPTH + 2 words)."""
PATH = LEVEL_COUNTS + MAX_DEPTH + 2
"""Start of the previous voxel's path of node indices from the root (MAX_DEPTH + 2 words)."""
OCTREE_STATE_WORDS = PATH + MAX_DEPTH + 2
