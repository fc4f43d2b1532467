"""The generic native routines (subdivision, normals, octree, splatting, contouring) as callable functions.

A :class:`Runtime` owns the JIT-compiled generic modules (:mod:`implc.codegen.runtime_module`: the
runtime module, the kernels' walk, the contouring, the meshes' simplification; and the tape engine,
:class:`TapeEngine`, one interpreter for every program) and their entry points, bound from
:mod:`implc.abi`. Each module is compiled on first use (from the disk cache after the first time), those
first needed together at once, with a surface's own where it asks (a first voxelization over compiled
kernels: the runtime module, the walk and the surface's bound kernel). They are the same for every
surface, so a process needs one runtime: :meth:`Runtime.shared` hands the same one to every caller,
which keeps its code alive for the life of the process.
"""

from __future__ import annotations

import functools
import threading
from collections.abc import Sequence

from . import abi
from .codegen.runtime_module import build_contouring, build_kernel_walk, build_mesh_simplify, build_runtime
from .codegen.tape_engine_module import build_tape_engine
from .jit import NativeModule, Source

TAPE_ENGINE_OPT: int | str = "light"
"""LLVM's optimisation of the tape engine (:data:`implc.jit.LIGHT_PASSES`): its IR is written vectorised
and unrolled, so LLVM's pipelines found nothing to gain at runtime (bear, colonnade and Prospero voxelized
at 512³ and meshed at 256³, within the noise against level 1) and spent most of a first compile: the
module's optimisation 0.42 -> 0.08 s of the 0.9 s its compile took at level 1."""


def _tape_engine_source(directed: bool) -> Source:
    """The tape engine's module, in parts (its compile takes six times the runtime's)."""
    return Source(functools.partial(build_tape_engine, directed),
                  f"implc-tape-engine-{'directed' if directed else 'widened'}", TAPE_ENGINE_OPT, max_parts=4,
                  weight=6.0)


RUNTIME_SOURCE = Source(build_runtime, "implc-runtime", max_parts=4)
KERNEL_WALK_SOURCE = Source(build_kernel_walk, "implc-kernel-walk", max_parts=2, weight=2.0)
MESH_SIMPLIFY_SOURCE = Source(build_mesh_simplify, "implc-mesh-simplify")
CONTOURING_SOURCE = Source(build_contouring, "implc-contouring", max_parts=4, weight=2.0)


class TapeEngine:
    """The tape-engine module's entry points for one rounding mode: ``interval``, ``gradient``, ``point``,
    ``subdivide``, ``box_gradient`` and ``grouped`` (signatures in :mod:`implc.abi`; programs from
    :mod:`implc.tape_program`); ``native``: the module (:meth:`Runtime.tape_engine` builds it)."""

    def __init__(self, directed: bool, native: NativeModule):
        self.directed = directed
        self.native = native
        self.interval = self.native.bind(abi.TAPE_INTERVAL)
        self.gradient = self.native.bind(abi.TAPE_GRADIENT)
        self.point = self.native.bind(abi.TAPE_POINT)
        self.subdivide = self.native.bind(abi.TAPE_SUBDIVIDE)
        self.box_gradient = self.native.bind(abi.TAPE_BOX_GRADIENT)
        self.grouped = self.native.bind(abi.TAPE_GROUPED)


class Contouring:
    """The contouring module's entry points (:data:`implc.abi.CONTOURING_ENTRIES`), each an attribute named
    after its entry without the ``implc_`` prefix: ``hash_index``, ``cell_corners``, ``corner_signs``,
    ``kuhn_triangles``, ``fan_triangles``, ``qef``, ``bent_cells``, ``edge_ends``, ``edge_roots`` and
    ``corner_points``."""

    def __init__(self, native: NativeModule):
        self.native = native
        for entry in abi.CONTOURING_ENTRIES:
            setattr(self, entry.name.removeprefix("implc_"), self.native.bind(entry))


def _entry(entry: abi.Entry, source: Source):
    """A :class:`Runtime` attribute: ``entry`` of ``source``'s module, bound on first use (the module compiled
    then, or loaded from the disk cache)."""

    def bound(self: Runtime):
        return self.modules(source)[0].bind(entry)

    bound.__doc__ = f"``{entry.name}`` (:mod:`implc.abi`), from the module ``{source.key}``."
    return functools.cached_property(bound)


class Runtime:
    """The generic native routines, each module compiled on first use (from the disk cache after the first
    time): the runtime module's entry points ``drop_marked``, ``octree_insert``, ``octree_traverse``,
    ``octree_mark_inside``, ``octree_subtree_rows``, ``splat`` and ``arrange_groups``; the walk over compiled
    kernels, ``subdivide``; ``flat_collapse`` (meshes' simplification); ``contouring`` (the mesher's,
    :class:`Contouring`) and the tape engine per rounding mode (signatures in :mod:`implc.abi`). Modules
    first needed together are compiled at once (:meth:`modules`)."""

    _shared: Runtime | None = None
    _lock = threading.Lock()

    def __init__(self):
        self._modules: dict[str, NativeModule] = {}  # by source key
        self._tape_engines: dict[bool, TapeEngine] = {}

    def modules(self, *sources: Source, extra: Sequence[Source] = ()) -> list[NativeModule]:
        """The modules of ``sources`` (kept by this runtime, so built once) and then of ``extra`` (a
        surface's, returned only), those not built yet compiled at once (:meth:`NativeModule.together`)."""
        with self._lock:
            missing = list({s.key: s for s in sources if s.key not in self._modules}.values())
            built = NativeModule.together([*missing, *extra]) if missing or extra else []
            self._modules.update((s.key, m) for s, m in zip(missing, built))
            return [self._modules[s.key] for s in sources] + built[len(missing):]

    drop_marked = _entry(abi.DROP_MARKED, RUNTIME_SOURCE)
    octree_insert = _entry(abi.OCTREE_INSERT, RUNTIME_SOURCE)
    octree_traverse = _entry(abi.OCTREE_TRAVERSE, RUNTIME_SOURCE)
    octree_mark_inside = _entry(abi.OCTREE_MARK_INSIDE, RUNTIME_SOURCE)
    octree_subtree_rows = _entry(abi.OCTREE_SUBTREE_ROWS, RUNTIME_SOURCE)
    splat = _entry(abi.SPLAT, RUNTIME_SOURCE)
    arrange_groups = _entry(abi.ARRANGE_GROUPS, RUNTIME_SOURCE)
    subdivide = _entry(abi.SUBDIVIDE, KERNEL_WALK_SOURCE)
    flat_collapse = _entry(abi.FLAT_COLLAPSE, MESH_SIMPLIFY_SOURCE)

    @functools.cached_property
    def contouring(self) -> Contouring:
        """The contouring module's entry points, compiled on first use (from the disk cache after the first
        time)."""
        return Contouring(self.modules(CONTOURING_SOURCE)[0])

    def tape_engine(self, directed: bool) -> TapeEngine:
        """The tape engine for one rounding mode, compiled on first use (from the disk cache after the
        first time) at once with the runtime module where that is not built yet either."""
        with self._lock:
            engine = self._tape_engines.get(directed)
        if engine is None:
            native = self.modules(RUNTIME_SOURCE, _tape_engine_source(directed))[1]
            with self._lock:
                engine = self._tape_engines.setdefault(directed, TapeEngine(directed, native))
        return engine

    @classmethod
    def shared(cls) -> Runtime:
        """The process's runtime, built on first use (thread-safe)."""
        with cls._lock:
            if cls._shared is None:
                cls._shared = cls()
            return cls._shared
