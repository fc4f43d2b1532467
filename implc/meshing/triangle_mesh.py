"""Triangle meshes: :class:`Mesh` (vertices, faces, analytic normals), its counted checks, and mesh files.

Files are read by :mod:`implc.meshing.readers` (untrusted input: nothing followed out of the file, every
count bounded) and written by :mod:`implc.meshing.formats` (trimesh's writers took several
times as long, OBJ's and 3MF's most: ``implc bench --sections mesh``), under a temporary name renamed into place.
"""

from __future__ import annotations

import math
import os
from pathlib import Path
from typing import Any

import numpy as np

from ..common.atomic_file import replacing
from ..errors import MeshFileError
from .readers import read_mesh

MESH_SUFFIXES = (".stl", ".obj", ".ply", ".glb", ".3mf")
MEASURE_ROWS = 1 << 18
"""Triangles measured at a time (area, volume)."""


class Mesh:
    """A triangle mesh in world coordinates: ``vertices`` (V, 3) float64, ``faces`` (F, 3) int64 vertex
    indices, counter-clockwise seen from outside, ``normals`` (V, 3) float64 unit normals at the vertices
    (from contouring: F's analytic gradient at the last point sampled on the vertex's edge, within 10⁻³ of
    the edge of the vertex; docs/soundness.md), ``stats`` (how it was made) and ``bounds``;
    from contouring, ``unproven_cells`` ((k, 3) grid indices: the crossed cells not proven regular, see
    :class:`implc.meshing.contour.MeshStats`)."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None = None, *,
                 stats: Any = None, bounds: tuple | None = None):
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.faces = np.ascontiguousarray(faces, dtype=np.int64).reshape(-1, 3)
        self.normals = None if normals is None else np.ascontiguousarray(normals, dtype=np.float64).reshape(-1, 3)
        self.stats = stats
        self.bounds = bounds
        self.witnesses = None  # (V, 2, 3) where contouring was asked to keep them (implc.mesh(..., witnesses=True))
        self.unproven_cells = np.zeros((0, 3), np.int64)  # cells the mesh crosses where no partial keeps its sign

    def __repr__(self) -> str:
        return f"Mesh({len(self.vertices)} vertices, {len(self.faces)} triangles)"

    def __len__(self) -> int:
        return len(self.faces)

    # -- measures ---------------------------------------------------------------------------------
    def _corner_columns(self, rows: int = MEASURE_ROWS):
        """Per chunk of ``rows`` triangles (:data:`MEASURE_ROWS`), their corners' coordinates as nine contiguous
        columns ((ax, ay, az), (bx, by, bz), (cx, cy, cz)): gathered from the vertices' columns, no (F, 3, 3)
        array (np.cross on those dominated a big mesh's volume)."""
        columns = [np.ascontiguousarray(self.vertices[:, axis]) for axis in range(3)]
        for start in range(0, len(self.faces), rows):
            part = self.faces[start:start + rows]
            yield [[np.take(column, part[:, k]) for column in columns] for k in range(3)]

    @property
    def area(self) -> float:
        """The surface area: the sum of the triangles' areas."""
        return math.fsum(float(np.sqrt(_doubled_area_squared(a, b, c)).sum())
                         for a, b, c in self._corner_columns()) / 2

    @property
    def volume(self) -> float:
        """The signed volume enclosed (divergence theorem): positive for a closed mesh oriented outward."""
        return math.fsum(_six_volumes(a, b, c) for a, b, c in self._corner_columns()) / 6

    def measures(self, rows: int = MEASURE_ROWS) -> tuple[float, float]:
        """(:attr:`area`, :attr:`volume`) in one pass, summed ``rows`` triangles at a time (exactly rounded sums
        of the chunks' sums: the same to rounding for any ``rows``)."""
        areas, volumes = [], []
        for a, b, c in self._corner_columns(rows):
            areas.append(float(np.sqrt(_doubled_area_squared(a, b, c)).sum()))
            volumes.append(_six_volumes(a, b, c))
        return math.fsum(areas) / 2, math.fsum(volumes) / 6

    def check(self) -> dict:
        """Counted facts about the mesh, each 0 for a closed, oriented, edge-manifold mesh without
        degenerate triangles: ``open_edges`` and ``overused_edges`` (undirected edges in fewer or more
        than two faces), ``repeated_directed_edges`` (an oriented edge used twice: inconsistent
        orientation), ``degenerate`` (triangles with a repeated vertex or zero area), ``split_vertices``
        (vertices whose faces form more than one fan; None where the edges are not manifold and
        oriented), and ``volume``."""
        f = self.faces
        directed = np.concatenate([f[:, [0, 1]], f[:, [1, 2]], f[:, [2, 0]]])
        nv = max(len(self.vertices), 1)
        dkey = directed[:, 0] * nv + directed[:, 1]
        _, dcount = np.unique(dkey, return_counts=True)
        ukey = np.minimum(directed[:, 0], directed[:, 1]) * nv + np.maximum(directed[:, 0], directed[:, 1])
        _, ucount = np.unique(ukey, return_counts=True)
        areas, volumes = [np.zeros(0)], []  # one pass over the corners for both
        for a, b, c in self._corner_columns():
            areas.append(_doubled_area_squared(a, b, c))
            volumes.append(_six_volumes(a, b, c))
        area2 = np.concatenate(areas)
        repeated = (f[:, 0] == f[:, 1]) | (f[:, 1] == f[:, 2]) | (f[:, 2] == f[:, 0])
        return {"open_edges": int(np.sum(ucount < 2)), "overused_edges": int(np.sum(ucount > 2)),
                "repeated_directed_edges": int(np.sum(dcount > 1)),
                "degenerate": int(np.sum(repeated | ~(area2 > 0))),
                "split_vertices": _split_vertices(f, len(self.vertices)), "volume": math.fsum(volumes) / 6}

    def simplified(self, tolerance: float) -> Mesh:
        """This mesh with its flat parts' inner vertices collapsed away (:mod:`implc.meshing.simplify`): the
        same closed, oriented 2-manifold, every vertex one of this mesh's (with its normal and witnesses),
        no point moved by more than ``tolerance`` (in the bounds' units). Needs the normals at the
        vertices (a mesh from contouring has them)."""
        import copy

        from .simplify import check_tolerance, simplify_flat
        tolerance = check_tolerance(tolerance)
        if self.normals is None:
            raise ValueError("simplify needs the normals at the vertices (a mesh from implc.mesh has them)")
        kept, faces, stats = simplify_flat(self.vertices, self.faces, self.normals, tolerance)
        mesh_stats: Any = stats
        if hasattr(self.stats, "simplified"):  # a contouring's: the counts now, and what the simplifying did
            mesh_stats = copy.copy(self.stats)
            mesh_stats.triangles, mesh_stats.vertices, mesh_stats.simplified = len(faces), len(kept), stats
        result = Mesh(self.vertices[kept], faces, self.normals[kept], stats=mesh_stats, bounds=self.bounds)
        result.witnesses = None if self.witnesses is None else self.witnesses[kept]
        result.unproven_cells = self.unproven_cells
        return result

    def show(self, *, height: int = 480, name: str = "", view: tuple[float, float] | None = None,
             max_bytes: int | None = None) -> Any:
        """The interactive viewer for a notebook (Jupyter displays what this returns): the page and the
        whole mesh inlined in one document (refused beyond ``max_bytes``, default 24 MiB: about 700,000
        triangles); ``view``: (azimuth, elevation) in degrees. ``.save("x.html")`` writes it as a file."""
        from ..view.mesh_payload import MeshPayload
        from ..view.page import EMBED_BYTES, NotebookView
        return NotebookView(MeshPayload(self, name=name, view=view), height=height,
                            max_bytes=EMBED_BYTES if max_bytes is None else max_bytes)

    # -- files ------------------------------------------------------------------------------------
    def to_trimesh(self) -> Any:
        """A ``trimesh.Trimesh`` of this mesh (vertices not merged, faces not reordered)."""
        import trimesh
        return trimesh.Trimesh(vertices=self.vertices, faces=self.faces, vertex_normals=self.normals,
                               process=False, validate=False)

    def save(self, path: str | os.PathLike[str]) -> Path:
        """Write ``path`` (.stl, .obj, .ply, .glb or .3mf, by its suffix) under a temporary name renamed into
        place, by :mod:`implc.meshing.formats` (binary STL and PLY; the vertex normals in PLY, OBJ and GLB).
        Refused where the format's precision would break the mesh (:func:`~implc.meshing.formats.precision_problem`)
        or it holds no triangles."""
        path = Path(path)
        suffix = path.suffix.lower()
        if suffix not in MESH_SUFFIXES:
            raise MeshFileError(f"unknown mesh format {path.suffix or '(none)'!r} for {path}: use "
                                f"{', '.join(MESH_SUFFIXES)}")
        from . import formats as mesh_formats
        if len(self.faces) == 0:
            raise MeshFileError(f"the mesh holds no triangles: nothing to write to {path}")
        problem = mesh_formats.precision_problem(suffix, self.vertices, self.faces)
        if problem is not None:
            raise MeshFileError(f"cannot write {path}: {problem}")
        with replacing(path) as tmp, open(tmp, "wb") as f:
            if suffix == ".stl":
                mesh_formats.write_stl(f, self.vertices, self.faces)
            elif suffix == ".3mf":
                mesh_formats.write_3mf(f, self.vertices, self.faces)
            else:
                write = {".ply": mesh_formats.write_ply, ".obj": mesh_formats.write_obj, ".glb": mesh_formats.write_glb}
                write[suffix](f, self.vertices, self.faces, self.normals)
        return path


def _cross(u, v):
    """The cross product of two vectors given as three columns each."""
    return [u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0]]


def _six_volumes(a, b, c) -> float:
    """Σ a · (b x c) over the triangles (corners as three columns each): six times the signed volume of the
    tetrahedra they make with the origin."""
    n = _cross(b, c)
    return float((a[0] * n[0] + a[1] * n[1] + a[2] * n[2]).sum())


def _doubled_area_squared(a, b, c) -> np.ndarray:
    """|(b - a) x (c - a)|² per triangle (corners as three columns each): twice its area, squared."""
    n = _cross([b[i] - a[i] for i in range(3)], [c[i] - a[i] for i in range(3)])
    return n[0] * n[0] + n[1] * n[1] + n[2] * n[2]


def _split_vertices(faces: np.ndarray, count: int) -> int | None:
    """How many vertices have faces that form more than one fan: a closed edge-manifold mesh can still be
    pinched at a vertex, which this counts (None where the edges are not manifold and oriented, so fans
    are not defined).

    At each corner of each face the link edge (next vertex -> previous vertex) is one step of a walk
    around the vertex; on an oriented edge-manifold mesh the steps at a vertex form cycles, one per fan.
    The cycles are labelled by pointer jumping (each round takes the least label within twice the
    distance, until the distance covers the longest walk), all vertices at once."""
    if not len(faces):
        return 0
    center = faces.reshape(-1)
    start = np.roll(faces, -1, axis=1).reshape(-1)
    end = np.roll(faces, 1, axis=1).reshape(-1)
    count = max(count, 1)
    key = center * count + start
    order = np.argsort(key)
    wanted = center * count + end
    rows = np.minimum(np.searchsorted(key[order], wanted), len(key) - 1)
    if np.any(key[order][rows] != wanted) or np.any(np.diff(key[order]) == 0):
        return None
    step = order[rows]  # the entry that continues the walk
    label = np.arange(len(key))
    longest = int(np.bincount(center).max())  # no walk is longer than its vertex's corners
    for _ in range(int(np.ceil(np.log2(longest))) + 1):
        label = np.minimum(label, label[step])
        step = step[step]
    fans = np.bincount(center[label == np.arange(len(key))], minlength=count)
    return int(np.sum(fans > 1))


def is_mesh_file(path: str | os.PathLike[str]) -> bool:
    """Whether ``path`` is to be read as a mesh: a mesh suffix, and for .ply (also implc's voxel point
    clouds) a header that declares faces."""
    path = Path(path)
    if path.suffix.lower() != ".ply":
        return path.suffix.lower() in MESH_SUFFIXES
    if not path.is_file():  # a FIFO is never opened here (the reader that comes next refuses it)
        return False
    try:
        with open(path, "rb") as f:
            header = f.read(4096)
    except OSError:
        return False
    return b"element face" in header.split(b"end_header")[0]


def load(path: str | os.PathLike[str]) -> Mesh:
    """Read a mesh file (STL, PLY, OBJ, GLB or 3MF: :mod:`implc.meshing.readers`, which follow nothing out of
    the file) as a :class:`Mesh`; one clear error if it is not one."""
    return Mesh(*read_mesh(path))


def describe(path: str | os.PathLike[str]) -> list[str]:
    """``implc info`` for a mesh file: size, extent, and the counted checks (after merging the vertices
    that formats such as STL repeat per triangle: equal coordinates are one vertex)."""
    path = Path(path)
    mesh = load(path)
    distinct, inverse = np.unique(mesh.vertices, axis=0, return_inverse=True)  # STL repeats them per triangle
    merged = Mesh(distinct, inverse.reshape(-1)[mesh.faces])
    report = merged.check()
    lo, hi = mesh.vertices.min(axis=0), mesh.vertices.max(axis=0)
    closed = report["open_edges"] == 0 and report["overused_edges"] == 0
    return [
        f"{path}: a triangle mesh ({path.suffix.lower()[1:]}), {len(mesh.faces)} triangles, "
        f"{len(merged.vertices)} distinct vertices",
        "extent: " + ", ".join(f"[{a:.6g}, {b:.6g}]" for a, b in zip(lo, hi)),
        f"closed: {'yes' if closed else 'no'} ({report['open_edges']} open, {report['overused_edges']} "
        f"non-manifold edges); orientation: "
        f"{'consistent' if report['repeated_directed_edges'] == 0 else 'inconsistent'}"
        f"; degenerate triangles: {report['degenerate']}; pinched vertices: "
        f"{'not counted' if report['split_vertices'] is None else report['split_vertices']}",
        f"volume: {report['volume']:.9g}, area: {mesh.area:.9g}",
    ]
