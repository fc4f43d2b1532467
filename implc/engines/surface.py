"""``implc.compile``: a SymPy expression becomes a :class:`Surface` with native kernels.

A Surface owns its tapes, its :class:`~implc.native.jit.NativeModule` (and the mean-value one, compiled on
first use), its kernels bound from :mod:`implc.native.abi`, and batched entry points that validate their
arrays, run the compiled code over whole vectors and handle the ragged tail.
"""

from __future__ import annotations

from collections.abc import Callable
from functools import partial
from typing import Any

import numpy as np
from llvmlite.ir import Module as LLVMModule
from numpy.typing import ArrayLike

from ..common.bounds import check_bounds
from ..common.threads import CHUNK, chunk_rows, in_parallel
from ..compiler.gradient import with_gradient
from ..compiler.ir import Tape
from ..compiler.vm import VmModel
from ..errors import CompileError
from ..native import abi
from ..native.abi import MAX_DEPTH
from ..native.jit import NativeModule, Source, host_has_avx512
from ..native.runtime import Runtime
from .compiled.evaluator import KernelWalk
from .compiled.evaluator_native import KERNEL_WALK
from .compiled.kernels_native import (
    WIDTH,
    WIDTHS,
    build_bound_module,
    build_box_gradient_module,
    build_mean_value_module,
    build_module,
)
from .compiled.plan import plan_regions
from .rows_native import ROWS
from .tape.engine import tape_engine
from .tape.evaluator import TapeWalk
from .tape.program import TapeProgram, encode, slot_scratch, unsupported_ops
from .walk import WalkEvaluator

DEFAULT_BOUNDS = ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
ROUNDINGS = ("auto", "directed", "widen")
KINK_OPS = frozenset({"abs", "min", "max", "select_lt", "select_le"})
"""The IR ops whose derivative may jump (:attr:`Surface.has_kinks`)."""
ALL_TERMS = -1
"""The live-term mask with every term of a region plan live (``implc_gradient_live``'s last argument)."""
def _rows(name: str, array) -> np.ndarray:
    a = np.ascontiguousarray(array, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] != 3:
        raise ValueError(f"{name} must be an (N, 3) array, got shape {a.shape}")
    return a


ENGINES = ("auto", "jit", "tape")
TAPE_ABOVE = 1000
"""With ``engine="auto"``, a tape of more nodes than this runs on the tape engine (nothing to compile)."""


def choose_engine(tape: Tape, engine: str, vector_width: int = WIDTH) -> str:
    """"jit" or "tape" for ``engine`` ("auto": the tape engine where it can run the tape and the tape has a
    Min/Max or a select that only the engine prunes, i.e. neither in the top-level chain nor a blend term
    of a top-level sum, or is large). The engine's vectors are eight wide: another ``vector_width`` means
    the compiled kernels."""
    unsupported = unsupported_ops(tape) if engine != "jit" else set()
    if engine == "tape":
        if unsupported:
            raise CompileError(f"engine='tape' cannot run {', '.join(sorted(unsupported))} "
                               "(use engine='jit' or 'auto')")
        if vector_width != WIDTH:
            raise CompileError(f"engine='tape' runs {WIDTH} lanes; vector_width={vector_width} needs engine='jit'")
    if engine != "auto":
        return engine
    if unsupported or vector_width != WIDTH:
        return "jit"
    pruned = _pruned_by_kernels(tape)
    nested = any(op in CHOICE_NODES and i not in pruned for i, (op, _, _) in enumerate(tape.nodes))
    return "tape" if nested or len(tape) > TAPE_ABOVE else "jit"


CHOICE_NODES = ("min", "max", "select_lt", "select_le")


def _pruned_by_kernels(tape: Tape) -> set[int]:
    """The choice nodes the compiled kernels prune themselves: the top-level Min/Max chain, or the blend
    terms of a top-level sum (:func:`implc.engines.compiled.plan.plan_regions`; only planned for a sum, the chain is a
    walk)."""
    out = tape.outputs[0]
    top = tape.nodes[out][0]
    if top in ("min", "max"):
        chain, stack = {out}, [out]
        while stack:
            for a in tape.nodes[stack.pop()][1]:
                if tape.nodes[a][0] == top and a not in chain:
                    chain.add(a)
                    stack.append(a)
        return chain
    if top == "add":
        return {t.root for t in plan_regions(tape).terms if t.kind == "sum"}
    return set()


class Grouping:
    """Rows sorted by group and padded to whole blocks of eight, as ``implc_tape_grouped`` takes them: made
    once from the rows' group labels (int64) and ``boxes`` (the (lo, hi) corners, (M, 3) each, of the sorted
    distinct labels asked for), used for every call over rows with those groups (a vertex's root steps
    and its normal; :meth:`subset` for the rows still open after a step)."""

    def __init__(self, groups: np.ndarray, boxes: Callable[[np.ndarray], tuple]):
        labels = np.ascontiguousarray(groups, dtype=np.int64)
        self._labels, self._boxes = labels, boxes
        bound = int(labels.max()) + 1 if len(labels) else 0
        if len(labels) and (labels.min() < 0 or bound > max(4 * len(labels), 1 << 16)):
            distinct, dense = np.unique(labels, return_inverse=True)  # a sparse range: numbered densely first
            self._lay_out(np.ascontiguousarray(dense.reshape(-1), dtype=np.int64), len(distinct),
                          lambda chosen: boxes(distinct[chosen]))
        else:
            self._lay_out(labels, bound, boxes)

    def _lay_out(self, labels: np.ndarray, bound: int, boxes: Callable[[np.ndarray], tuple]):
        """The padded places of rows with ``labels`` (each below ``bound``), native: ``implc_arrange_groups``."""
        n = self.rows = len(labels)
        group_labels, starts, place = np.empty(n, np.int64), np.empty(n + 1, np.int64), np.empty(n, np.int64)
        taken = np.empty(8 * n, np.int64)  # at most seven repeats a group: pages never written cost nothing
        counts = np.zeros(bound, np.int64)  # named: a temporary's address would point at freed memory
        count = Runtime.shared().library(ROWS).arrange_groups(labels.ctypes.data, n, bound, counts.ctypes.data,
                                                group_labels.ctypes.data, starts.ctypes.data, taken.ctypes.data,
                                                place.ctypes.data)
        self.starts = starts[: count + 1]
        self.padded = int(self.starts[-1])
        self.taken = taken[: self.padded]  # the row in each padded place
        self.place = place  # each row's padded place
        self.lo, self.hi = (np.ascontiguousarray(a, dtype=np.float64) for a in boxes(group_labels[:count]))

    def subset(self, rows: np.ndarray) -> Grouping:
        """The grouping of ``rows`` (increasing row numbers of this one's), as row 0, 1, … in that order:
        the same groups."""
        return Grouping(self._labels[rows], self._boxes)


def _grouping(groups: np.ndarray | Grouping, boxes: Callable[[np.ndarray], tuple] | None) -> Grouping:
    if isinstance(groups, Grouping):
        return groups
    if boxes is None:
        raise ValueError("group labels need their boxes")
    return Grouping(groups, boxes)


class Surface:
    """A compiled implicit surface F(x, y, z) = 0 (F < 0 inside) over a bounding box.

    ``engine``: "jit" (kernels compiled for this surface by LLVM when it is compiled) or "tape" (the shared
    tape engine runs the surface's :class:`~implc.engines.tape.program.TapeProgram`, pruning every decided Min/Max
    and select per octant; compiled kernels are built on first use by what needs them, e.g. the mean-value
    form).
    """

    def __init__(self, expr: Any, bounds: Any, tape: Tape, vector_width: int = WIDTH, directed: bool = False,
                 engine: str = "jit"):
        self.expr = expr
        self.bounds = bounds
        self.tape = tape
        self.width = vector_width
        self.directed = directed  # interval arithmetic rounded by AVX-512 instructions rather than widened
        self.engine = engine
        self.program: TapeProgram | None = encode(tape) if engine == "tape" else None
        self._gradient_tape: Tape | None = None
        self._native: NativeModule | None = None  # compiled on first use
        self._mean_value_native: NativeModule | None = None  # compiled on first use
        self._bound_native: NativeModule | None = None  # compiled on the first voxelization
        self._box_gradient_native: NativeModule | None = None  # compiled on the first mesh
        self._bound: dict[str, object] = {}
        self._engine = tape_engine(directed) if engine == "tape" else None  # shared, cached
        if engine == "jit":
            self._module_of(abi.POINT)  # this surface's kernels: compiled now, or loaded from the cache

    @property
    def has_kinks(self) -> bool:
        """Whether F has an op whose derivative may jump (Min, Max, abs, a select): without one, F is
        smooth wherever its ops are defined, and so is its surface wherever F's gradient is not zero."""
        return any(op in KINK_OPS for op, _, _ in self.tape.nodes)

    @property
    def gradient_tape(self) -> Tape:
        """The value tape with the gradient's nodes (:func:`implc.compiler.gradient.with_gradient`), built on first
        use."""
        if self._gradient_tape is None:
            self._gradient_tape = with_gradient(self.tape)
        return self._gradient_tape

    @property
    def _key(self) -> str:
        return (f"w{self.width}{'d' if self.directed else ''}" + self.tape.fingerprint()
                + self.gradient_tape.fingerprint())

    @property
    def tape_engine(self):
        """The shared tape engine's entry points (:func:`implc.engines.tape.engine.tape_engine`) that run this
        surface (None for engine "jit")."""
        return self._engine

    @property
    def from_cache(self) -> bool:
        """Whether this surface's native code was loaded from the disk cache (no code generation, no LLVM):
        its compiled kernels, or for the tape engine the shared engine (nothing of the surface's own)."""
        native = self._engine.native if self._engine is not None else self._native
        return native is not None and native.from_cache

    @property
    def runtime(self) -> Runtime:
        """The generic native routines (subdivider, normals, octree) this surface's voxelizations run on:
        the process's one :class:`~implc.native.runtime.Runtime`."""
        return Runtime.shared()

    def _bound_source(self) -> Source:
        return Source(lambda: build_bound_module(self.tape, self.gradient_tape, width=self.width,
                                                 directed=self.directed), "bound" + self._key, weight=2.0)

    def _build_with(self, generic: tuple[Source, ...], own: str, source: Callable[[], Source] | None) -> None:
        """Build at once where missing: the runtime's ``generic`` modules and, where ``source`` is given, this
        surface's module of that source, kept in the attribute ``own``."""
        extra = [source()] if source is not None and getattr(self, own) is None else []
        built = self.runtime.modules(*generic, extra=extra)
        if extra:
            setattr(self, own, built[-1])

    def prepare_voxelization(self, tightens: bool, also: tuple[Source, ...] = (), compiled: bool | None = None) -> None:
        """Build at once what a voxelization of this surface runs and is missing: the modules ``also`` (those
        its caller needs: its storage's) and, over ``compiled`` kernels (by default where the surface's engine is
        "jit"), the walk's rows, the kernel walk and where the second look ``tightens``, the surface's bound
        kernel."""
        if not (self.engine == "jit" if compiled is None else compiled):
            self.runtime.modules(*also)
        else:
            self._build_with((ROWS.source, KERNEL_WALK.source, *also), "_bound_native",
                             self._bound_source if tightens else None)

    def walk_evaluator(self, program: TapeProgram | None, depth: int, mean_value_levels: int, fine_level: int,
                       tightens: bool) -> WalkEvaluator:
        """The evaluator the walk runs over: the tape engine over ``program``, else the compiled kernels (the
        mean-value form is compiled only)."""
        if program is not None:
            return TapeWalk(self, program, depth)
        self.prepare_voxelization(tightens, compiled=True)
        return KernelWalk(self, self.runtime, mean_value_levels, fine_level, tightens)

    def _box_gradient_source(self) -> Source:
        return Source(lambda: build_box_gradient_module(self.gradient_tape, width=self.width,
                                                        directed=self.directed), "box-gradient" + self._key,
                      weight=2.0)

    def prepare_mesher(self, contouring: Source) -> None:
        """Build at once what meshing this surface runs and is missing: the mesher's ``contouring`` module and,
        over compiled kernels, the surface's box-gradient kernel."""
        self._build_with((contouring,), "_box_gradient_native",
                         self._box_gradient_source if self.engine == "jit" else None)

    def _module_of(self, entry: abi.Entry) -> NativeModule:
        if entry in abi.SURFACE_ENTRIES:
            if self._native is None:
                self._native = NativeModule(self._build, self._key, max_parts=4)
            return self._native
        if entry in abi.BOUND_ENTRIES:
            if self._bound_native is None:  # the voxelizer's: built by prepare_voxelization, or here
                self._bound_native = NativeModule.together([self._bound_source()])[0]
            return self._bound_native
        if entry in abi.BOX_GRADIENT_ENTRIES:
            if self._box_gradient_native is None:  # the mesher's: built by prepare_mesher, or here
                self._box_gradient_native = NativeModule.together([self._box_gradient_source()])[0]
            return self._box_gradient_native
        if entry not in abi.MEAN_VALUE_ENTRIES:
            raise LookupError(f"{entry.name} is not a surface kernel")
        if self._mean_value_native is None:  # about three times the others' size: compiled on first use
            self._mean_value_native = NativeModule(
                lambda: build_mean_value_module(self.tape, self.gradient_tape, width=self.width,
                                                directed=self.directed),
                source_key="mvf" + self._key, max_parts=4)
        return self._mean_value_native

    def kernel(self, entry: abi.Entry) -> Any:
        """The compiled kernel ``entry`` (one of :data:`implc.native.abi.SURFACE_ENTRIES`, ``MEAN_VALUE_ENTRIES``,
        ``BOUND_ENTRIES`` or ``BOX_GRADIENT_ENTRIES``) as a ctypes function with the ABI's prototype, valid
        while this Surface lives. The low-level seam under :meth:`eval`, :meth:`interval` and the voxelizer:
        arrays go in as addresses, ``n`` a multiple of :attr:`width`."""
        if entry.name not in self._bound:
            self._bound[entry.name] = self._module_of(entry).bind(entry)
        return self._bound[entry.name]

    def kernel_address(self, entry: abi.Entry) -> int:
        """The address of the compiled kernel ``entry``, for native callers (the subdivider)."""
        return self._module_of(entry).address(entry.name)

    # -- inspection ----------------------------------------------------------------------------
    @property
    def ir(self) -> str:
        """The value tape, printed."""
        return str(self.tape)

    def _build(self) -> LLVMModule:
        return build_module(self.tape, self.gradient_tape, width=self.width, directed=self.directed)

    @property
    def llvm_ir(self) -> str:
        """The LLVM IR of the kernels as generated (before optimisation)."""
        return str(self._build())

    def __repr__(self) -> str:
        return f"Surface({self.expr}, bounds={self.bounds}, {len(self.tape)} ops)"

    # -- batched evaluation -----------------------------------------------------------------------
    def _run(self, kernel, inputs: list[np.ndarray], out_shapes: list[tuple], extra=(),
             fewest: int | None = CHUNK) -> list[np.ndarray]:
        """Run ``kernel`` over whole vectors, in chunks of :func:`chunk_rows` rows (``fewest``: at least that
        many where there are more; None: a costly entry point's, :func:`implc.common.threads.fewest_rows`)
        spread over the threads (Ctrl-C is seen between them), then once more over
        the zero-padded tail (``extra``: trailing arguments, e.g. NULL live masks)."""
        n = len(inputs[0])
        outs = [np.empty((n, *shape), dtype=np.float64) for shape in out_shapes]
        width = self.width
        main = n - n % width

        rows_per_call = chunk_rows(main, width, fewest)

        def chunk(start):
            count = min(rows_per_call, main - start)
            kernel(*[a[start:].ctypes.data for a in inputs], *[o[start:].ctypes.data for o in outs], count, *extra)
        in_parallel([partial(chunk, start) for start in range(0, main, rows_per_call)])
        if main < n:
            tail_in = [np.zeros((width, 3)) for _ in inputs]
            for pad, a in zip(tail_in, inputs):
                pad[: n - main] = a[main:]
            tail_out = [np.empty((width, *shape)) for shape in out_shapes]
            kernel(*[a.ctypes.data for a in tail_in], *[o.ctypes.data for o in tail_out], width, *extra)
            for o, t in zip(outs, tail_out):
                o[main:] = t[: n - main]
        return outs

    def _tape_kernel(self, function, choices: bool = False):
        """A tape-engine entry point with this surface's program and fresh scratch bound in front."""
        program = self.program

        def call(*args):
            slots = slot_scratch(program.slot_count)
            # the choices' scratch is held by a name for the whole call: an address taken from a temporary
            # array points at freed memory, which the engine then wrote (a heap corruption seen as aborts)
            scratch = np.empty(len(program) * 8, dtype=np.uint8) if choices else None
            function(program.header.ctypes.data, slots.ctypes.data,
                     *((scratch.ctypes.data,) if choices else ()), *args)
        return call

    def _value_and_gradient(self, points, fast: bool = False):
        extra: tuple[int, ...]
        if self.engine == "tape":
            kernel, extra = self._tape_kernel(self.tape_engine.gradient), ()
        elif fast:
            kernel, extra = self.kernel(abi.GRADIENT_LIVE), (ALL_TERMS,)
        else:
            kernel, extra = self.kernel(abi.GRADIENT), ()
        return self._run(kernel, [_rows("points", points)], [(), (3,)], extra)

    def eval(self, points: ArrayLike, *, fast: bool = False) -> np.ndarray:
        """F at each row of an (N, 3) array of points. ``fast``: on the compiled kernels, sin, cos, exp,
        log and atan2 computed in vector registers, all lanes at once, within the error bounds proven in
        :mod:`implc.compiler.llvm.elementary` (about 1e-15; the voxelizer's and the mesher's samples), rather than
        by the C library (within an ulp or two, one lane per call), which is several times slower where F has
        them. The tape
        engine always computes them so.

        >>> import implc
        >>> ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1)
        >>> ball.eval([[0, 0, 0], [1, 1, 1]])
        array([-1.,  2.])
        """
        if self.engine == "tape":
            kernel = self._tape_kernel(self.tape_engine.point)
        else:
            kernel = self.kernel(abi.POINT_FAST if fast else abi.POINT)
        (values,) = self._run(kernel, [_rows("points", points)], [()])
        return values

    def gradient(self, points: ArrayLike) -> np.ndarray:
        """The analytic gradient of F at each point: (N, 3).

        >>> import implc
        >>> implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1).gradient([[1, 2, 3]])
        array([[2., 4., 6.]])
        """
        return self._value_and_gradient(points)[1]

    def value_and_gradient(self, points: ArrayLike, *, fast: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(F, its gradient) at each point: (N,) and (N, 3), in one pass (``fast``: as for :meth:`eval`)."""
        values, gradients = self._value_and_gradient(points, fast)
        return values, gradients

    def eval_grouped(self, points: np.ndarray, groups: np.ndarray | Grouping,
                     boxes: Callable[[np.ndarray], tuple] | None = None,
                     gradient: bool = False) -> tuple[np.ndarray, np.ndarray | None]:
        """(F, its gradient or None) at ``points`` ((N, 3)), point i lying in the box of group
        ``groups[i]`` (int64 labels; ``boxes(labels)`` gives the (lo, hi) corners, (M, 3) each, of the
        sorted distinct labels asked for), or a :class:`Grouping` of the points made once for several calls:
        on the tape engine each group's points run the program simplified over its box
        (``implc_tape_grouped``), far shorter than the whole on Min/Max models; the compiled kernels ignore
        the groups. F is :meth:`eval`'s value (on the tape engine, over the simplified program: the same
        value)."""
        points = _rows("points", points)
        if self.engine != "tape":
            if gradient:
                return self._value_and_gradient(points)
            return self.eval(points), None
        values, grads = self._grouped(points, None, _grouping(groups, boxes), 1 if gradient else 0)
        return values, grads if gradient else None

    def gradient_enclosures(self, lo: ArrayLike, hi: ArrayLike, groups: np.ndarray | Grouping | None = None,
                            boxes: Callable[[np.ndarray], tuple] | None = None,
                            directions: ArrayLike | None = None) -> np.ndarray:
        """Enclosures of F and of its three partials over each box [lo[i], hi[i]]: (N, 8), F's lo, hi,
        then each partial's lo, hi (NaN where a partial may be undefined or jump). Where a Min/Max may take
        either operand a partial's enclosure is the hull of both (the generalized gradient: an enclosure
        that excludes 0 still proves F strictly monotone along that axis). ``groups`` and ``boxes`` as for
        :meth:`eval_grouped` (on the tape engine, each box's program simplified over its group's box).
        ``directions`` ((3, 3), a direction a row): F's derivatives along them instead of the partials, on
        the tape engine each computed in forward mode with its own hull at a kink (across a crease whose
        two sides both rise along a diagonal, that derivative's enclosure excludes 0 where every partial's
        straddles it); the compiled kernels refuse them (from the partials' enclosures they would prove
        nothing more)."""
        lo, hi = _rows("lo", lo), _rows("hi", hi)
        seeds = None
        if directions is not None:
            seeds = np.ascontiguousarray(directions, dtype=np.float64)
            if seeds.shape != (3, 3) or not np.isfinite(seeds).all():
                raise ValueError(f"directions must be a finite (3, 3) array, one direction a row, not {seeds.shape}")
            if self.engine != "tape":
                raise ValueError("derivatives along directions need the tape engine (engine='tape')")
        if self.engine != "tape":
            (out,) = self._run(self.kernel(abi.BOX_GRADIENT), [lo, hi], [(8,)], fewest=None)
            return out
        if groups is None or (boxes is None and not isinstance(groups, Grouping)):  # one group: the bounds
            bounds = np.array(self.bounds, dtype=np.float64)
            groups = Grouping(np.zeros(len(lo), np.int64), lambda labels: (bounds[None, :, 0], bounds[None, :, 1]))
        return self._grouped(lo, hi, _grouping(groups, boxes), 2, seeds)[1]

    def _grouped(self, rows: np.ndarray, rows_hi: np.ndarray | None, plan: Grouping, mode: int,
                 seeds: np.ndarray | None = None):
        """``implc_tape_grouped`` over ``rows`` (points, or boxes' lo corners with ``rows_hi``) grouped by
        ``plan``: (values, (N, 3) gradients, (N, 8) enclosures of F and its partials (or its derivatives
        along the directions ``seeds``), or (N, 2) of F)."""
        n = len(rows)
        width = {2: 8, 3: 2}.get(mode, 3)
        if n != plan.rows:
            raise ValueError(f"a grouping of {plan.rows} rows used for {n}")
        if not n:
            return np.empty(0), np.empty((0, width))
        padded_rows = np.take(rows, plan.taken, axis=0)  # several times faster than fancy indexing of (N, 3)
        padded_hi = padded_rows if rows_hi is None else np.take(rows_hi, plan.taken, axis=0)
        total = plan.padded
        out_value = np.empty(total)
        out_grad = np.empty((total if mode else 8, width))
        program = self.program
        assert program is not None  # the tape engine's surfaces have one
        length = max(len(program), 1)
        lo, hi, starts = plan.lo, plan.hi, plan.starts

        def batch(at, count):  # its own scratch: batches run at once on several cores
            slots = slot_scratch(program.slot_count)
            choices = np.empty(length * 16, dtype=np.uint8)  # the groups' choices (then the boxes', mode 3)
            need = np.zeros(program.slot_count, dtype=np.int32)  # each call's stamps start from one
            marks = np.empty(length, dtype=np.uint8)
            remap = np.empty(program.slot_count, dtype=np.int32)
            work = np.empty(length * abi.INSTRUCTION_WORDS, dtype=np.int32)
            self.tape_engine.grouped(
                program.header.ctypes.data, slots.ctypes.data, choices.ctypes.data, need.ctypes.data,
                marks.ctypes.data, remap.ctypes.data, work.ctypes.data, lo[at:].ctypes.data, hi[at:].ctypes.data,
                starts[at:].ctypes.data, count, padded_rows.ctypes.data, padded_hi.ctypes.data,
                out_value.ctypes.data, out_grad.ctypes.data, mode, None if seeds is None else seeds.ctypes.data)
        groups = len(lo)
        step = max(1, groups * chunk_rows(total) // total)  # about chunk_rows per call: Ctrl-C between calls
        in_parallel([partial(batch, at, min(step, groups - at)) for at in range(0, groups, step)])
        values = np.take(out_value, plan.place)
        grads = np.take(out_grad, plan.place, axis=0) if mode else np.empty((n, width))
        return values, grads

    def interval(self, lo: ArrayLike, hi: ArrayLike, mean_value: bool = False,
                 monotone: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """(f_lo, f_hi): an enclosure of F over each box [lo[i], hi[i]] ((N, 3) corners each).

        Boxes where F may be undefined (NaN) get the whole line (-inf, inf): they never prune.
        ``mean_value=True`` intersects the natural enclosure with the mean-value form: tighter on small
        boxes, about four times the work. ``monotone=True`` intersects it with the monotonicity form
        instead (each bound taken at the corner where F is least or greatest along the axes where the
        gradient's sign is known over the box): at least as tight as the mean-value form up to rounding,
        exact where every partial keeps its sign; the voxelizer's second look at leaves uses it.

        >>> import implc
        >>> ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1)
        >>> lo, hi = ball.interval([[0, 0, 0]], [[1, 1, 1]])   # F over [0, 1]³ is [-1, 2], rounded outward
        >>> bool(lo[0] <= -1 and hi[0] >= 2 and hi[0] - lo[0] < 3 + 1e-12)
        True
        """
        lo, hi = _rows("lo", lo), _rows("hi", hi)
        if lo.shape != hi.shape:
            raise ValueError(f"lo and hi differ in shape: {lo.shape} vs {hi.shape}")
        if not np.all(lo <= hi):
            bad = int(np.argmin(np.all(lo <= hi, axis=1)))
            raise ValueError(f"box {bad} has lo > hi (or NaN): {lo[bad]} .. {hi[bad]}")
        if mean_value and monotone:
            raise ValueError("choose one of mean_value and monotone")
        if mean_value or monotone:
            kernel = self.kernel(abi.INTERVAL_MONOTONE if monotone else abi.INTERVAL_MVF)
            f_lo, f_hi = self._run(kernel, [lo, hi], [(), ()], extra=(None, None), fewest=None)
        elif self.engine == "tape":
            f_lo, f_hi = self._run(self._tape_kernel(self.tape_engine.interval, choices=True), [lo, hi], [(), ()],
                                   fewest=None)
        else:
            f_lo, f_hi = self._run(self.kernel(abi.INTERVAL), [lo, hi], [(), ()], extra=(None, None),
                                   fewest=None)
        return f_lo, f_hi


def compile(expr: Any, bounds: Any = None, *, vector_width: int = WIDTH, rounding: str = "auto",
            engine: str = "auto") -> Surface:
    """Compile the surface ``expr = 0`` over ``bounds`` (default: a model's own, else [-1, 1]³).

    ``expr``: a SymPy expression in x, y, z, r, theta, phi, or a model read by :func:`implc.load_vm`.

    ``vector_width``: lanes per kernel step (8 by default: an octant's children at once; 1 for scalar
    code, to measure what vectors bring). ``rounding``: how interval bounds are rounded outward:
    "directed" (each add, sub, mul and sqrt rounded toward the bound by the instruction; needs AVX-512),
    "widen" (round to nearest, then move outward by a relative ulp or more: any CPU) or "auto" (directed
    where the host has AVX-512). Both are sound; directed is faster and a few ulps tighter. ``engine``:
    "jit" (LLVM compiles this surface's kernels), "tape" (the shared tape engine interprets it, pruning
    every Min/Max an octant decides; nothing to compile) or "auto" (the tape engine for tapes with Min/Max
    below the top level or more than :data:`TAPE_ABOVE` nodes, where it can run every op).

    >>> import implc
    >>> ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1)
    >>> ball.bounds
    ((-1.0, 1.0), (-1.0, 1.0), (-1.0, 1.0))
    >>> flower = implc.compile(implc.r - 0.5)   # spherical coordinates: the sphere of radius 1/2
    >>> float(flower.eval([[0.5, 0, 0]])[0])
    0.0
    """
    if isinstance(expr, VmModel):
        checked, directed = _check_options(expr.bounds if bounds is None else bounds, vector_width, rounding, engine)
        return Surface(expr, checked, expr.tape, vector_width, directed, choose_engine(expr.tape, engine, vector_width))
    import sympy  # here, not above: a .vm model never needs SymPy (its import is a quarter second)

    from ..compiler.lower import lower
    if not isinstance(expr, sympy.Basic):
        raise TypeError(f"implc.compile expects a SymPy expression or a .vm model, got {type(expr).__name__}")
    if isinstance(expr, sympy.Equality):
        expr = expr.lhs - expr.rhs
    if isinstance(expr, (sympy.core.relational.Relational, sympy.logic.boolalg.BooleanFunction,
                         sympy.logic.boolalg.BooleanAtom)):
        raise CompileError(f"expected a real-valued expression F (the surface is F = 0), got {expr}")
    checked, directed = _check_options(DEFAULT_BOUNDS if bounds is None else bounds, vector_width, rounding, engine)
    try:
        tape = lower(expr)
    except RecursionError:
        raise CompileError("the expression is nested too deeply for the front end") from None
    return Surface(expr, checked, tape, vector_width, directed, choose_engine(tape, engine, vector_width))


def _check_options(bounds, vector_width, rounding, engine) -> tuple[tuple, bool]:
    """(checked bounds, directed rounding?): the options validated before any work is done."""
    checked = check_bounds(bounds, MAX_DEPTH)
    if vector_width not in WIDTHS:
        raise CompileError(f"vector_width must be one of {WIDTHS}, got {vector_width!r}")
    if engine not in ENGINES:
        raise CompileError(f"engine must be one of {', '.join(ENGINES)}, got {engine!r}")
    if rounding not in ROUNDINGS:
        raise CompileError(f"rounding must be one of {', '.join(ROUNDINGS)}, got {rounding!r}")
    if rounding == "directed" and not host_has_avx512():
        raise CompileError("rounding='directed' needs a CPU with AVX-512F; this one has none (use 'auto' or 'widen')")
    return checked, rounding == "directed" or (rounding == "auto" and host_has_avx512())
