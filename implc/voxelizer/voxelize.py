"""``implc.voxelize``: every cell of a 2^depth grid that may meet the surface, with normals, stored.

Cell (i, j, k) at depth d is the closed box [b0 + i·h, b0 + (i+1)·h] on each axis, h = (b1 − b0) / 2^d.
A cell is a voxel when the compiled enclosure of F over it (padded outward by a few ulps for the
rounding of its corners) contains 0: no cell where F changes sign is ever missed.
"""

from __future__ import annotations

import contextlib
import os
import time
from collections.abc import Callable
from typing import Any

import numpy as np

from ..common.threads import check_workers, default_workers, threads
from ..engines.surface import Surface
from ..engines.walk import Subdivider, SubdivisionStats
from ..meshing.contour import MAX_DEPTH as MESH_MAX_DEPTH
from ..meshing.contour import contour
from ..meshing.simplify import check_tolerance
from ..meshing.triangle_mesh import Mesh
from ..native import big_arrays
from .storage import bytes_per_voxel, make_backend
from .storage.dense import dense_bytes
from .storage.octree import Octree, OctreeAssembly, OctreeBuilder
from .storage.octree_native import OCTREE_INDEX

MIN_DEPTH, MAX_DEPTH = 1, 21


def available_memory() -> int:
    """Bytes of memory available to this process now (MemAvailable on Linux)."""
    try:
        with open("/proc/meminfo") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) * 1024
    except OSError:  # pragma: no cover - non-Linux
        pass
    return os.sysconf("SC_AVPHYS_PAGES") * os.sysconf("SC_PAGE_SIZE")


class Voxels:
    """The voxels of a surface at one depth: Morton-ordered cell indices and unit normals; for a solid
    (``voxelize(..., solid=True)``) also ``inside``: the octants whose whole box lies where F < 0, as
    (n, 4) int32 rows (i, j, k, level), each a cube of 2^(depth − level) voxels per axis, never expanded.

    >>> import implc
    >>> voxels = implc.voxelize(implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1), depth=5, solid=True)
    >>> voxels.depth, voxels.bounds[0], voxels.cell_size.tolist()
    (5, (-1.0, 1.0), [0.0625, 0.0625, 0.0625])
    >>> voxels.centers()[0].tolist()                       # the first voxel's centre, in world coordinates
    [-0.53125, -0.53125, -0.71875]
    >>> grid = voxels.to_dense(solid=True)                 # (32, 32, 32) bool: inside or boundary
    >>> grid.shape, int(grid.sum()) == voxels.inside_voxels() + len(voxels)
    ((32, 32, 32), True)
    >>> coarse, normals = voxels.octree.level(3)           # level of detail: 8³ nodes with mean normals
    >>> len(coarse) < len(voxels)
    True
    >>> mesh = voxels.mesh()                                # a closed mesh of the solid
    >>> mesh.check()["open_edges"]
    0
    """

    def __init__(self, coords: np.ndarray | None, normals: np.ndarray, depth: int, bounds: tuple,
                 stats: SubdivisionStats | None, storage: Any = None, inside: np.ndarray | None = None,
                 surface: Surface | None = None):
        """``coords`` may be None when ``storage`` is an :class:`Octree`: they are read from the tree on
        first use (the octree holds them; the default voxelization stores no other copy). ``surface``: the
        :class:`Surface` voxelized (None for voxels read from a file), which :meth:`mesh` samples."""
        if coords is None and not isinstance(storage, Octree):
            raise ValueError("Voxels without coords need their octree as storage")
        self._coords = coords
        self.normals = normals
        self.depth = depth
        self.bounds = bounds
        self.stats = stats
        self.storage = storage
        self.inside = inside  # None: a shell (solid=False)
        self.surface = surface
        self._octree = storage if isinstance(storage, Octree) else None

    @property
    def coords(self) -> np.ndarray:
        """(N, 3) uint32 cell indices in Morton order (from the octree on first use where not stored)."""
        if self._coords is None:
            assert self._octree is not None  # checked in __init__
            coords, payload = self._octree.traverse(self.depth)
            if len(payload) != len(self.normals) or np.any(payload != np.arange(len(payload))):
                raise AssertionError("the octree's voxels are not its payload in order")
            self._coords = coords
        return self._coords

    def __len__(self) -> int:
        return len(self.normals)

    def __repr__(self) -> str:
        n = 1 << self.depth
        return f"Voxels({len(self)} voxels of a {n}³ grid over {self.bounds})"

    @property
    def cell_size(self) -> np.ndarray:
        """The edge of a voxel along each axis, in world units: (3,)."""
        return np.array([(hi - lo) / (1 << self.depth) for lo, hi in self.bounds])

    @property
    def octree(self) -> Octree:
        """The octree of these voxels (built on first use when another backend was chosen)."""
        if self._octree is None:
            builder = OctreeBuilder()
            builder.begin(self.depth, self.bounds)
            builder.add(self.coords, self.normals)
            self._octree = builder.finish()
            if self.inside is not None:
                self._octree.add_inside(self.inside)
        return self._octree

    def centers(self) -> np.ndarray:
        """Cell centres in world coordinates, (N, 3) float64."""
        origin = np.array([lo for lo, _ in self.bounds])
        return origin + (self.coords.astype(np.float64) + 0.5) * self.cell_size

    def _solid(self) -> np.ndarray:
        if self.inside is None:
            raise ValueError("these voxels are a shell: voxelize(..., solid=True) classifies the inside")
        return self.inside

    def to_dense(self, solid: bool = False) -> np.ndarray:
        """Occupancy as a bool array indexed [i, j, k]: the boundary voxels, and with ``solid`` the inside
        octants too (every cell that may hold a point with F <= 0)."""
        n = 1 << self.depth
        grid = np.zeros((n, n, n), dtype=bool)
        grid[self.coords[:, 0], self.coords[:, 1], self.coords[:, 2]] = True
        if solid:
            inside = self._solid()
            sizes = np.left_shift(1, self.depth - inside[:, 3].astype(np.int64))
            paint_cubes(grid, inside[:, :3].astype(np.int64) * sizes[:, None], sizes)
        return grid

    def show(self, *, height: int = 480, budget: int = 1_000_000, max_bytes: int | None = None) -> Any:
        """The interactive viewer for a notebook (Jupyter displays what this returns): the page and the
        coarsest levels of detail up to ``max_bytes`` (default 24 MiB) inlined in one document, so no
        server or second process is involved. ``.save("x.html")`` writes it as a file; ``.update(surface)``
        redraws it in place with a new surface voxelized at this depth (live editing in a notebook)."""
        from ..view.page import EMBED_BYTES, NotebookView, lod_chunks

        def remake(surface):  # a new surface, for .update(): voxelized as these voxels were
            if not isinstance(surface, Surface):
                from ..engines.surface import compile as compile_surface
                surface = compile_surface(surface, self.bounds)
            return lod_chunks(voxelize(surface, self.depth, solid=self.inside is not None))
        return NotebookView(lod_chunks(self), height=height, budget=budget, remake=remake,
                            max_bytes=EMBED_BYTES if max_bytes is None else max_bytes)

    def _repr_html_(self) -> str:
        """A notebook shows voxels as the viewer (with up to 4 MiB of levels of detail)."""
        return self.show(max_bytes=4 << 20)._repr_html_()

    def mesh(self, surface: Surface | None = None, *, features: bool = True, witnesses: bool = False,
             simplify: float | None = None, workers: int | None = None) -> Mesh:
        """The boundary of {F < 0} within the bounds as a closed, oriented, intersection-free triangle mesh,
        contoured over these voxels' cells (:func:`implc.meshing.contour.contour`; docs/soundness.md says what holds
        by construction). ``surface``: the surface these voxels came from, needed only for voxels read from
        a file. ``features``: place each cell's vertex at the QEF point of its crossings (sharp CSG edges;
        False: at their mean, creases chamfered). ``witnesses``: keep for each vertex two points of its cell
        where F has opposite signs (``Mesh.witnesses``: its edge's ends, or for a dual vertex the ends of an
        edge of its cell). ``simplify``: a tolerance (in the bounds' units) to merge the flat parts'
        triangles within (:meth:`Mesh.simplified`).
        ``workers``: the threads that sample F, enclose it and place the vertices (default: one per usable
        core); the mesh is the same for every count.
        """
        if simplify is not None:
            check_tolerance(simplify)  # refused before the contouring, not after it
        workers = None if workers is None else check_workers(workers)
        surface = self.surface if surface is None else surface
        if not isinstance(surface, Surface):
            raise ValueError("these voxels do not know their surface (read from a file?): pass it, "
                             "voxels.mesh(implc.compile(...))")
        if tuple(map(tuple, surface.bounds)) != tuple(map(tuple, self.bounds)):
            raise ValueError(f"the surface's bounds {surface.bounds} are not these voxels' {self.bounds}")
        with threads(workers):
            mesh = contour(surface, self.coords, self.depth, self.bounds, features=features, witnesses=witnesses)
        return mesh if simplify is None else mesh.simplified(simplify)

    def inside_voxels(self) -> int:
        """How many voxels the inside octants cover."""
        return inside_voxel_count(self._solid(), self.depth)

    def volume_bounds(self) -> tuple[float, float]:
        """(lo, hi) with lo <= the exact volume of {F < 0} within the bounds <= hi: the inside octants'
        volume, and that plus the boundary voxels' (every other cell's enclosure lies above 0). Computed
        exactly in rationals from the float bounds, then rounded outward."""
        return volume_bounds(self.bounds, self.depth, self.inside_voxels(), len(self))


def inside_voxel_count(octants: np.ndarray, depth: int) -> int:
    """How many voxels of the 2^depth grid the octant rows (i, j, k, level) cover."""
    levels = octants[:, 3].astype(np.int64)
    return int(np.sum(np.left_shift(np.int64(1), 3 * (depth - levels)))) if len(levels) else 0


def volume_bounds(bounds: Any, depth: int, inside_voxels: int, boundary_voxels: int) -> tuple[float, float]:
    """(lo, hi): the volume of ``inside_voxels`` cells, and of those and ``boundary_voxels`` more, of the
    2^depth grid over ``bounds``, computed exactly in rationals and rounded outward."""
    from fractions import Fraction
    voxel = Fraction(1)
    for lo, hi in bounds:
        voxel *= (Fraction(hi) - Fraction(lo)) / (1 << depth)
    inside = inside_voxels * voxel
    return _round_down(inside), _round_up(inside + boundary_voxels * voxel)


def paint_cubes(block: np.ndarray, firsts: np.ndarray, sizes: np.ndarray) -> None:
    """Set the cubes (first cell ``firsts[n]``, edge ``sizes[n]``, aligned to their edge: octants) inside
    the bool ``block`` (a cube whose edge is a multiple of every size), edge by edge, each edge's cubes at
    once: cells and cubes of 2³ through flat indices into the block, larger ones through a view of the block
    as cubes of that edge (the view's indexing costs more per cube, the flat indices more per cell)."""
    n = block.shape[0]
    if not block.flags.c_contiguous:
        raise ValueError("paint_cubes paints a C-contiguous block")
    for size in np.unique(sizes):
        size = int(size)
        if size <= 2:
            f = firsts[sizes == size].astype(np.int64)
            e = np.arange(size)
            steps = ((e[:, None, None] * n + e[None, :, None]) * n + e[None, None, :]).ravel()
            block.reshape(-1)[(((f[:, 0] * n + f[:, 1]) * n + f[:, 2])[:, None] + steps[None]).ravel()] = True
            continue
        corners = firsts[sizes == size] // size
        view = block.reshape(n // size, size, n // size, size, n // size, size)
        view[corners[:, 0], :, corners[:, 1], :, corners[:, 2], :] = True


def _round_down(value) -> float:
    f = float(value)
    return f if f <= value else float(np.nextafter(f, -np.inf))


def _round_up(value) -> float:
    f = float(value)
    return f if f >= value else float(np.nextafter(f, np.inf))


class _Collect:
    """Copies each batch into growing voxel arrays as it arrives (overlapping the workers, so nothing
    is left to concatenate at the end) and forwards it to the chosen backend."""

    def __init__(self, backend, capacity: int):
        self.backend = backend
        self.count = 0
        self.coords = big_arrays.empty((max(capacity, 1024), 3), np.uint32)
        self.normals = big_arrays.empty((max(capacity, 1024), 3), np.float32)

    def __call__(self, coords, normals):
        end = self.count + len(coords)
        if end > len(self.coords):
            size = max(end, 2 * len(self.coords))
            self.coords = big_arrays.grown(self.coords, size, self.count)
            self.normals = big_arrays.grown(self.normals, size, self.count)
        self.coords[self.count:end] = coords
        self.normals[self.count:end] = normals
        self.count = end
        self.backend.add(self.coords[end - len(coords):end], self.normals[end - len(coords):end])

    def arrays(self):
        return self.coords[: self.count], self.normals[: self.count]


def _check_count(name, value) -> int:
    """A whole number >= 1 (an int or a numpy integer, not a bool or a float)."""
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 1:
        raise ValueError(f"{name} must be a whole number >= 1, got {value!r}")
    return int(value)


def _check_leaf_options(mean_value_levels, refine_leaves) -> tuple[int, bool | str]:
    """``mean_value_levels`` a whole number >= 0, ``refine_leaves`` True, False (numpy's too) or "auto"."""
    if isinstance(mean_value_levels, bool) or not isinstance(mean_value_levels, (int, np.integer)) \
            or mean_value_levels < 0:
        raise ValueError(f"mean_value_levels must be a whole number >= 0, got {mean_value_levels!r}")
    if isinstance(refine_leaves, (bool, np.bool_)):
        return int(mean_value_levels), bool(refine_leaves)
    if not (isinstance(refine_leaves, str) and refine_leaves == "auto"):
        raise ValueError(f"refine_leaves must be True, False or 'auto', got {refine_leaves!r}")
    return int(mean_value_levels), refine_leaves


def _check_depth(depth):
    if isinstance(depth, bool) or not isinstance(depth, (int, np.integer)) or not MIN_DEPTH <= depth <= MAX_DEPTH:
        raise ValueError(f"depth must be an integer from {MIN_DEPTH} to {MAX_DEPTH}, got {depth!r}")
    return int(depth)


NATURAL = {"mean_value_levels": 0, "refine_leaves": False}
"""``voxelize(s, depth, **implc.NATURAL)``: every leaf the natural enclosure keeps (no second test)."""
TIGHTEST = {"mean_value_levels": 1, "refine_leaves": "auto"}
"""``voxelize(s, depth, **implc.TIGHTEST)``: every leaf decided by the mean-value form, then the default's
second look (never more voxels than the default with compiled kernels, and rarely fewer: the second look
re-tests what the mean-value form would drop; at two to six times the default's time)."""

ESTIMATE_MARGIN = 1.5
"""The memory check's allowance for the estimate running low (measured up to about 1.5x below the peak)."""


ESTIMATE_LEVEL = 6
"""The level whose kept cells the voxel estimate extrapolates from, at most (or six levels above the
leaves): from about level 5 on, surface cells grow 4x per level within about ±15% on the paper's scenes,
while above it a cell may hold several blobs (Scene 1: 1176 cells at level 4, 2296 at level 5)."""


def _estimate_level(depth, plan_level):
    """The level whose kept cells the estimate counts: :data:`ESTIMATE_LEVEL` or six levels above the
    leaves, not above the plan's level (whose cells are counted already)."""
    return min(depth, max(plan_level, min(depth - ESTIMATE_LEVEL, ESTIMATE_LEVEL)))


def _estimate_voxels(cells, level, depth):
    """Surface cells grow about 4x per level (from ``cells`` kept at ``level``)."""
    return cells * 4 ** (depth - level)


def _estimated_bytes(depth, storage, estimate_voxels) -> float:
    """The memory a voxelization is expected to take (before the check's margin)."""
    return estimate_voxels * bytes_per_voxel(storage) + (dense_bytes(depth) if storage == "grid" else 0)


def _check_memory(depth, storage, estimate_voxels, available):
    """Refuse before starting when the result cannot fit."""
    estimate = _estimated_bytes(depth, storage, estimate_voxels * ESTIMATE_MARGIN)  # the margin on the voxels only
    if estimate > available:
        raise MemoryError(f"depth {depth} needs an estimated {estimate / 2**30:.1f} GiB "
                          f"(~{estimate_voxels:.3g} voxels{' plus a dense grid' if storage == 'grid' else ''}) "
                          f"but {available / 2**30:.1f} GiB are available; lower the depth")


def voxelize(surface: Surface, depth: int = 9, *, workers: int | None = None, storage: Any = "octree",
             progress: bool = False, max_voxels: int | None = None, mean_value_levels: int = 0, prune: bool = True,
             refine_leaves: bool | str = "auto", solid: bool = False, cluster: Any = None,
             say: Callable[[str], None] | None = None) -> Voxels:
    """Voxelize a compiled surface on a 2^depth grid over its bounds.

    ``mean_value_levels``: how many of the deepest levels also use the mean-value form (tighter on small
    boxes, about five times the work per box); 0 uses the natural enclosure everywhere. ``prune``: skip,
    below each octant, the terms of a blend sum or a Min/Max chain that its enclosure showed dead there
    (and on the tape engine read a constant for a smooth blend's negligible exponential terms: a few more
    voxels than ``prune=False`` keeps, never fewer; docs/soundness.md).
    ``refine_leaves``: "auto" (the default) tests again the kept leaves that the linear model at their
    centre does not cross with the monotonicity form (over the leaf, then where that fails over its
    eighths and theirs; the tape engine runs its own version) and drops those proven empty;
    True keeps a leaf only if one of its eight half-size sub-boxes may meet the surface (about twice the
    interval work); False keeps what the enclosures of the leaves keep (the natural
    mode, with ``mean_value_levels=0``). The tightest: :data:`TIGHTEST`, ``mean_value_levels=1,
    refine_leaves="auto"``.
    ``solid``: also classify the inside: octants whose enclosure lies below 0 are kept whole
    (``Voxels.inside``, never expanded), which gives ``Voxels.volume_bounds()`` and
    ``Voxels.to_dense(solid=True)``.
    ``cluster``: find the voxels on a Dask cluster (``"local:N"``, a scheduler's address or a
    ``distributed.Client``; :mod:`implc.cluster.tasks`) and gather them here (refused up front where the
    estimate does not fit in memory; ``workers``, ``storage`` and ``prune`` then do not apply); ``say``
    receives the dashboard's address.

    >>> import implc
    >>> ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 1)
    >>> voxels = implc.voxelize(ball, depth=5)             # the 32³ grid over [-1, 1]³
    >>> voxels.coords.shape[1], voxels.normals.dtype, voxels.coords.dtype
    (3, dtype('float32'), dtype('uint32'))
    >>> import numpy as np                                  # every kept cell is within one cell of the sphere
    >>> bool(np.all(np.abs(np.linalg.norm(voxels.centers(), axis=1) - 1) < 2 / 32 * 3**0.5))
    True
    >>> solid = implc.voxelize(ball, depth=5, solid=True)
    >>> lo, hi = solid.volume_bounds()                      # the ball's volume, 4π/3, lies within
    >>> bool(lo <= 4.18879 <= hi)
    True
    """
    if not isinstance(surface, Surface):
        raise TypeError(f"voxelize expects an implc.Surface (from implc.compile), got {type(surface).__name__}")
    depth = _check_depth(depth)
    workers = default_workers() if workers is None else check_workers(workers)
    if max_voxels is not None:
        max_voxels = _check_count("max_voxels", max_voxels)
    mean_value_levels, refine_leaves = _check_leaf_options(mean_value_levels, refine_leaves)
    available = available_memory()
    if max_voxels is None:
        max_voxels = int(available * 0.8 / bytes_per_voxel(storage))

    if cluster is not None:
        if not (isinstance(storage, str) and storage == "octree"):
            raise ValueError(f"storage={storage!r} cannot be combined with cluster=: the workers' voxels are gathered "
                             "into Voxels here (a storage callback cannot travel to the workers)")
        return _voxelize_on_cluster(surface, depth, cluster, progress=progress, solid=solid, say=say,
                                    options={"mean_value_levels": mean_value_levels, "refine_leaves": refine_leaves},
                                    available=available)
    t_start = time.perf_counter()
    # what this run compiles, at once: the octree's index with the walk's modules
    surface.prepare_voxelization(refine_leaves == "auto", also=(OCTREE_INDEX.source,) if storage == "octree" else (),
                                 compiled=surface.engine == "jit" or mean_value_levels > 0)
    subdivider = Subdivider(surface, depth, workers, surface.runtime, max_voxels=max_voxels,
                            mean_value_levels=min(mean_value_levels, depth), prune=prune,
                            refine_leaves=refine_leaves, solid=solid)
    cells, level = subdivider.plan()
    estimate_level = _estimate_level(depth, level)
    counted = len(cells) if estimate_level == level else subdivider.count_cells(estimate_level)
    estimate = _estimate_voxels(counted, estimate_level, depth)
    _check_memory(depth, storage, estimate, available)
    subdivider.stats.estimated_voxels = int(estimate)
    subdivider.stats.estimated_bytes = int(_estimated_bytes(depth, storage, estimate))
    # reserve generously: the pages of a reserved array that stay untouched cost nothing, a growth costs a copy
    capacity = min(2 * estimate, max_voxels)
    if storage == "octree" and level < depth:  # the default: the tree assembled from the tasks' subtrees
        return _voxelize_into_octree(surface, depth, subdivider, (cells, level), capacity, progress, t_start)
    backend = OctreeBuilder(keep_normals=False) if storage == "octree" else make_backend(storage)

    t0 = time.perf_counter()
    backend.begin(depth, surface.bounds)
    if hasattr(backend, "reserve"):
        backend.reserve(capacity)
    collect = _Collect(backend, capacity)
    with _progress_bar(progress, len(cells), depth) as bar:
        stats = subdivider.run(collect, progress=bar, plan=(cells, level))
    t1 = time.perf_counter()
    result = backend.finish()
    coords, normals = collect.arrays()
    inside = subdivider.inside if solid else None
    if isinstance(result, Octree):
        result.normals = normals  # the octree's payload is the voxels' normals array itself
        if inside is not None:
            result.add_inside(inside)
    stats.seconds["finish"] = time.perf_counter() - t1
    stats.seconds["setup"] = t0 - t_start - stats.seconds["plan"]
    stats.seconds["total"] = time.perf_counter() - t_start
    return Voxels(coords, normals, depth, surface.bounds, stats, storage=result, inside=inside, surface=surface)


def _voxelize_on_cluster(surface, depth, cluster, *, progress, solid, say, options, available) -> Voxels:
    """:func:`voxelize` with ``cluster``: the memory checked against the estimate, the tasks run there."""
    from ..cluster.recipe import recipe_of
    from ..cluster.tasks import MIN_TASK_LEVEL, connect, gather_voxels, subdivider_for
    recipe = recipe_of(surface)  # refused before any cluster starts when it cannot travel
    estimate_level = _estimate_level(depth, MIN_TASK_LEVEL)
    counted = subdivider_for(surface, depth, solid=solid, options=options).count_cells(estimate_level)
    estimate = _estimate_voxels(counted, estimate_level, depth)
    _check_memory(depth, "coords", 2 * estimate, available)  # the parts gathered, then joined
    with connect(cluster, say=say) as client:
        coords, normals, inside, stats = gather_voxels(client, recipe, surface, depth, solid=solid, options=options,
                                                       progress=progress)
    return Voxels(coords, normals, depth, surface.bounds, stats, inside=inside, surface=surface)


def mesh(surface: Surface, depth: int = 8, *, workers: int | None = None, progress: bool = False,
         features: bool = True, witnesses: bool = False, simplify: float | None = None, **options: Any) -> Mesh:
    """The boundary of the solid {F < 0} within ``surface``'s bounds as a closed, oriented,
    intersection-free triangle mesh on the 2^depth grid: :func:`voxelize` finds the cells the surface may
    meet, then :meth:`Voxels.mesh` contours them (``features``, ``witnesses``, ``simplify``: see there), both
    on ``workers`` threads.

    The voxelization runs in the natural mode (:data:`NATURAL`) unless ``options`` (its tightness options)
    say otherwise: the mesh does not depend on them. A tighter voxelization keeps fewer cells, but it drops
    only cells proven not to meet the surface, whose sampled corners all agree, and the contouring meshes
    the cells whose samples change sign (and the neighbours they reach): the same cells, the same mesh,
    found sooner (the second look costs most on smooth blends: docs/guide/voxelize.md).

    >>> import implc
    >>> ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 0.5)
    >>> m = implc.mesh(ball, depth=5)
    >>> m.check()["open_edges"], m.volume > 0
    (0, True)
    """
    if _check_depth(depth) > MESH_MAX_DEPTH:  # refused before the voxelization, not after it
        raise ValueError(f"meshes are made at depth 1 to {MESH_MAX_DEPTH}, not {depth}")
    if simplify is not None:
        check_tolerance(simplify)
    voxels = voxelize(surface, depth, workers=workers, progress=progress, **{**NATURAL, **options})
    return voxels.mesh(features=features, witnesses=witnesses, simplify=simplify, workers=workers)


@contextlib.contextmanager
def _progress_bar(progress: bool, tasks: int, depth: int):
    bar = None
    if progress:
        from tqdm import tqdm
        bar = tqdm(total=tasks, unit="octant", desc=f"voxelize {1 << depth}³", leave=False)
    try:
        yield bar
    finally:
        if bar is not None:
            bar.close()


def _voxelize_into_octree(surface, depth, subdivider, plan, capacity, progress, t_start) -> Voxels:
    """The default voxelization: the octree assembled from the tasks' subtrees in parallel, each voxel's
    normal written once and its coordinates kept by the tree only."""
    cells, level = plan
    t0 = time.perf_counter()
    assembly = OctreeAssembly(depth, surface.bounds, level, capacity)
    with _progress_bar(progress, len(cells), depth) as bar:
        stats = subdivider.run(None, progress=bar, plan=plan, placement=assembly)
    t1 = time.perf_counter()
    tree = assembly.finish()
    inside = subdivider.inside if subdivider.solid else None
    if inside is not None:
        tree.add_inside(inside)
    stats.seconds["finish"] = time.perf_counter() - t1
    stats.seconds["setup"] = t0 - t_start - stats.seconds["plan"]
    stats.seconds["total"] = time.perf_counter() - t_start
    return Voxels(None, tree.normals, depth, surface.bounds, stats, storage=tree, inside=inside, surface=surface)
