"""The generic native routines (subdivision, normals, octree, splatting, contouring) as callable functions.

A :class:`Runtime` owns the JIT-compiled runtime module (:mod:`implc.codegen.runtime_module`) and its
entry points, bound from :mod:`implc.abi`, and the modules compiled on first use (the kernels' walk, the
contouring, the meshes' simplification). The module is the same for every surface, so a process needs
one: :meth:`Runtime.shared` builds it on first use (from the disk cache after the first time) and hands
the same one to every caller, which keeps its code alive for the life of the process. The tape engine
(:class:`TapeEngine`, one interpreter for every program) is compiled on first use by a surface that needs it.
"""

from __future__ import annotations

import functools
import threading

from . import abi
from .codegen.runtime_module import build_contouring, build_kernel_walk, build_mesh_simplify, runtime_parts
from .codegen.tape_engine_module import tape_engine_parts
from .jit import NativeModule, Source

TAPE_ENGINE_OPT: int | str = "light"
"""LLVM's optimisation of the tape engine (:data:`implc.jit.LIGHT_PASSES`): its IR is written vectorised
and unrolled, so LLVM's pipelines found nothing to gain at runtime (bear, colonnade and Prospero voxelized
at 512³ and meshed at 256³, within the noise against level 1) and spent most of a first compile: the
module's optimisation 0.42 -> 0.08 s of the 0.9 s its compile took at level 1."""


def _tape_engine_source(directed: bool) -> Source:
    """The tape engine's module, in parts (its compile takes six times the runtime's)."""
    return Source(functools.partial(tape_engine_parts, directed),
                  f"implc-tape-engine-{'directed' if directed else 'widened'}", TAPE_ENGINE_OPT, split=True,
                  weight=6.0)


RUNTIME_SOURCE = Source(runtime_parts, "implc-runtime", split=True)


class TapeEngine:
    """The tape-engine module's entry points for one rounding mode: ``interval``, ``gradient``, ``point``,
    ``subdivide``, ``box_gradient`` and ``grouped`` (signatures in :mod:`implc.abi`; programs from
    :mod:`implc.tape_program`). ``native``: the module, compiled already (else compiled here)."""

    def __init__(self, directed: bool, native: NativeModule | None = None):
        self.directed = directed
        self.native = native or NativeModule.together([_tape_engine_source(directed)])[0]
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

    def __init__(self):
        self.native = NativeModule(build_contouring, source_key="implc-contouring")
        for entry in abi.CONTOURING_ENTRIES:
            setattr(self, entry.name.removeprefix("implc_"), self.native.bind(entry))


class Runtime:
    """The runtime module's entry points: ``drop_marked``, ``octree_insert``, ``octree_traverse``,
    ``octree_mark_inside``, ``octree_subtree_rows``, ``splat`` and ``arrange_groups``; the walk over compiled kernels,
    ``subdivide``, from a module of its own compiled on first use, and likewise ``contouring`` (the
    mesher's, :class:`Contouring`) and ``flat_collapse`` (meshes' simplification; signatures in
    :mod:`implc.abi`)."""

    _shared: Runtime | None = None
    _lock = threading.Lock()

    def __init__(self, native: NativeModule | None = None):
        """``native``: the runtime module, compiled already (else compiled here)."""
        self.native = native or NativeModule.together([RUNTIME_SOURCE])[0]
        self._walk: NativeModule | None = None  # the compiled kernels' walk, built on first use
        self._simplify: NativeModule | None = None  # the meshes' simplification, built on first use
        self._contouring: Contouring | None = None  # the mesher's, built on first use
        self.drop_marked = self.native.bind(abi.DROP_MARKED)
        self.octree_insert = self.native.bind(abi.OCTREE_INSERT)
        self.octree_traverse = self.native.bind(abi.OCTREE_TRAVERSE)
        self.octree_mark_inside = self.native.bind(abi.OCTREE_MARK_INSIDE)
        self.octree_subtree_rows = self.native.bind(abi.OCTREE_SUBTREE_ROWS)
        self.splat = self.native.bind(abi.SPLAT)
        self.arrange_groups = self.native.bind(abi.ARRANGE_GROUPS)
        self._tape_engines: dict[bool, TapeEngine] = {}

    @property
    def contouring(self) -> Contouring:
        """The contouring module's entry points, compiled on first use (from the disk cache after the first
        time)."""
        with self._lock:
            if self._contouring is None:
                self._contouring = Contouring()
            return self._contouring

    def _walk_entry(self, entry: abi.Entry):
        with self._lock:
            if self._walk is None:
                self._walk = NativeModule(build_kernel_walk, source_key="implc-kernel-walk")
        return self._walk.bind(entry)

    @functools.cached_property
    def flat_collapse(self):
        with self._lock:
            if self._simplify is None:
                self._simplify = NativeModule(build_mesh_simplify, source_key="implc-mesh-simplify")
        return self._simplify.bind(abi.FLAT_COLLAPSE)

    @functools.cached_property
    def subdivide(self):
        return self._walk_entry(abi.SUBDIVIDE)

    def tape_engine(self, directed: bool) -> TapeEngine:
        """The tape engine for one rounding mode, compiled on first use (from the disk cache after the
        first time)."""
        with self._lock:
            if directed not in self._tape_engines:
                self._tape_engines[directed] = TapeEngine(directed)
            return self._tape_engines[directed]

    @classmethod
    def shared_tape_engine(cls, directed: bool) -> TapeEngine:
        """``Runtime.shared().tape_engine(directed)``. Where neither is built yet (a first compile), the
        runtime's module and the engine's parts are compiled at once (:meth:`NativeModule.together`)."""
        with cls._lock:
            if cls._shared is None:
                runtime, engine = NativeModule.together([RUNTIME_SOURCE, _tape_engine_source(directed)])
                cls._shared = cls(runtime)
                cls._shared._tape_engines[directed] = TapeEngine(directed, engine)
        return cls._shared.tape_engine(directed)

    @classmethod
    def shared(cls) -> Runtime:
        """The process's runtime, built on first use (thread-safe)."""
        with cls._lock:
            if cls._shared is None:
                cls._shared = cls()
            return cls._shared
