"""Simplifying a closed mesh's flat parts: vertices removed where every face around them lies in one plane.

A *flat region* is a set of vertices whose analytic normals agree (to :data:`NORMAL_STEP`) and whose
distances along that normal lie in a slab no thicker than ``tolerance`` (a box's face, a CSG part's flat
side, a cap on the bounds). A vertex is *inner* where every neighbour lies in its region and the faces
around it, projected on the region's plane, all turn one way and go once around it: they tile a polygon
around it. A vertex is removed by collapsing it into a neighbour ``u`` (the two faces through ``u`` vanish,
the others take ``u`` in its place) only where it and all its neighbours are inner, and

- every new face turns one way in projection, with some area: the new fan then tiles the same polygon (a
  fan from a corner of a polygon whose triangles all turn one way covers it once);
- the link condition holds (the two vertices share no neighbour but the two of their common faces), so the
  mesh stays a closed, oriented 2-manifold of the same topology.

What follows: every vertex left is one of the mesh's own (so near the surface as before); each region's
footprint on its plane is the same, and every new face lies in the region's slab, so no point moves by
more than ``tolerance`` along the region's normal and the volume changes by at most the regions' area
times ``tolerance``; the faces within two edges of a removed vertex are its region's, tiling the plane
beside the footprint, so the new faces meet none of them. A part of the surface farther away could be
crossed only where it passes within ``tolerance`` of a region's interior without touching it (a wall
thinner than the tolerance): that is checked by the tests, not proven. The regions are found in numpy,
the collapses run natively, one vertex at a time (:mod:`implc.meshing.simplify_native`).
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

NORMAL_STEP = 1e-9
"""How closely the vertices of one flat region agree on their unit normal, per component."""
MIN_SINE = 1e-3
"""A face is kept turning one way in projection where the sine of its angle at the pivot exceeds this."""
MAX_PASSES = 64
"""Passes over the movable vertices at most (they stop sooner, when one removes nothing)."""


@dataclass
class SimplifyStats:
    """What a simplification did: triangles and vertices before and after, flat regions found, passes."""
    triangles_before: int = 0
    triangles: int = 0
    vertices_before: int = 0
    vertices: int = 0
    regions: int = 0
    passes: int = 0
    seconds: float = 0.0


def check_tolerance(tolerance) -> float:
    """``tolerance`` as a positive finite float; ValueError otherwise."""
    if isinstance(tolerance, bool) or not isinstance(tolerance, (int, float, np.integer, np.floating)):
        raise ValueError(f"simplify takes a tolerance (a positive number, in the bounds' units), got {tolerance!r}")
    value = float(tolerance)
    if not (np.isfinite(value) and value > 0):
        raise ValueError(f"simplify takes a positive finite tolerance, got {tolerance!r}")
    return value


def flat_regions(vertices: np.ndarray, normals: np.ndarray, tolerance: float) -> tuple[np.ndarray, np.ndarray]:
    """(region of each vertex, -1 for none; each region's unit normal). Vertices are grouped by their normal
    rounded to :data:`NORMAL_STEP` (only normals four vertices share or more), then by their distance along
    it: a gap wider than ``tolerance`` / 2 starts a new group; a group whose distances spread over more
    than ``tolerance`` keeps its densest slab that thick; a region has four vertices or more."""
    region = np.full(len(vertices), -1, np.int64)
    binned = np.round(normals / NORMAL_STEP).astype(np.int64)
    # only normals shared by four vertices or more can make a region: found first with one int64 key each
    # (distinct normals may share a key; the exact grouping below separates them)
    key = binned[:, 0] * np.int64(0x9E3779B97F4A7C15 - (1 << 64)) ^ binned[:, 1] * np.int64(0x632BE59BD9B4E019)
    key ^= binned[:, 2] * np.int64(0x7FB5D329728EA185)
    by_key = np.argsort(key, kind="stable")
    sorted_key = key[by_key]
    run_start = np.flatnonzero(np.r_[True, sorted_key[1:] != sorted_key[:-1]])
    run_length = np.diff(np.r_[run_start, len(key)])
    shared = np.zeros(len(key), bool)
    shared[by_key] = np.repeat(run_length >= 4, run_length)
    candidates = np.flatnonzero(shared)
    n = len(candidates)
    if n == 0:
        return region, np.zeros((0, 3))
    vertices, binned = vertices[candidates], binned[candidates]
    by_bin = np.lexsort((binned[:, 2], binned[:, 1], binned[:, 0]))
    step = np.any(binned[by_bin[1:]] != binned[by_bin[:-1]], axis=1)
    bin_of = np.empty(n, np.int64)
    bin_of[by_bin] = np.concatenate([[0], np.cumsum(step)])
    bins = binned[by_bin[np.concatenate([[True], step])]]
    unit = bins.astype(np.float64)
    unit /= np.linalg.norm(unit, axis=1, keepdims=True)
    offset = np.einsum("ij,ij->i", vertices, unit[bin_of])
    order = np.lexsort((offset, bin_of))
    b, d = bin_of[order], offset[order]
    start = np.ones(n, bool)
    start[1:] = (b[1:] != b[:-1]) | (d[1:] - d[:-1] > tolerance / 2)
    first = np.flatnonzero(start)
    end = np.append(first[1:], n)
    member = np.zeros(n, bool)  # sorted rows that join their group's region
    spread = np.maximum.reduceat(d, first) - np.minimum.reduceat(d, first)
    member[np.repeat(spread <= tolerance, end - first)] = True
    for g in np.flatnonzero((spread > tolerance) & (end - first >= 4)):  # the densest slab of a spread group
        lo, hi = first[g], end[g]
        reach = np.searchsorted(d[lo:hi], d[lo:hi] + tolerance, side="right")
        best = int(np.argmax(reach - np.arange(hi - lo)))
        member[lo + best: lo + reach[best]] = True
    group = np.cumsum(start) - 1
    size = np.bincount(group[member], minlength=len(first))
    good = size >= 4
    renumber = np.full(len(first), -1, np.int64)
    renumber[good] = np.arange(int(good.sum()))
    sorted_region = np.where(member, renumber[group], -1)
    region[candidates[order]] = sorted_region
    normal_of = unit[b[first[good]]]
    return region, normal_of


def _planes(normals: np.ndarray) -> np.ndarray:
    """Per region: its unit normal, then a unit tangent (the normal crossed with the axis it leans on least)."""
    axis = np.eye(3)[np.argmin(np.abs(normals), axis=1)]
    tangent = np.cross(normals, axis)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    return np.ascontiguousarray(np.hstack([normals, tangent]), dtype=np.float64)


def _corner_lists(faces: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(head, next): each vertex's first corner and each corner's successor among its vertex's (-1: none)."""
    corner_vertex = faces.reshape(-1)
    order = np.argsort(corner_vertex, kind="stable")
    following = np.full(len(order), -1, np.int64)
    same = corner_vertex[order[1:]] == corner_vertex[order[:-1]]
    following[order[:-1][same]] = order[1:][same]
    head = np.full(n, -1, np.int64)
    first = np.ones(len(order), bool)
    first[1:] = ~same
    head[corner_vertex[order[first]]] = order[first]
    return head, following


def simplify_flat(vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray, tolerance: float,
                  runtime=None) -> tuple[np.ndarray, np.ndarray, SimplifyStats]:
    """(kept vertex indices, faces renumbered over them, stats) of the closed, oriented 2-manifold
    (``vertices``, ``faces``, ``normals`` its unit normals at the vertices) with its flat regions' inner
    vertices collapsed away (module docstring). Deterministic."""
    from ..native.runtime import Runtime
    from .simplify_native import MESH_SIMPLIFY
    routines = (Runtime.shared() if runtime is None else runtime).library(MESH_SIMPLIFY)
    t0 = time.perf_counter()
    stats = SimplifyStats(triangles_before=len(faces), vertices_before=len(vertices))
    vertices = np.ascontiguousarray(vertices, dtype=np.float64)
    faces = np.array(faces, dtype=np.int64, order="C", copy=True)
    n = len(vertices)
    region, region_normal = flat_regions(vertices, normals, tolerance)
    stats.regions = len(region_normal)
    planes = _planes(region_normal)
    inner = np.zeros(n, np.uint8)  # written by the native pass: the vertices interior to their region
    movable = np.zeros(n, np.uint8)
    order = np.flatnonzero(region >= 0).astype(np.int64)
    dead = np.zeros(len(faces), np.uint8)
    if len(order):
        head, following = _corner_lists(faces, n)
        passes = np.zeros(1, np.int64)
        routines.flat_collapse(faces.ctypes.data, vertices.ctypes.data, region.ctypes.data, planes.ctypes.data,
                              inner.ctypes.data, movable.ctypes.data, head.ctypes.data, following.ctypes.data,
                              dead.ctypes.data, order.ctypes.data, len(order), MAX_PASSES, MIN_SINE, passes.ctypes.data)
        stats.passes = int(passes[0])
    kept_faces = faces[dead == 0]
    used = np.zeros(n, bool)
    used[kept_faces.reshape(-1)] = True
    kept = np.flatnonzero(used)
    renumber = np.full(n, -1, np.int64)
    renumber[kept] = np.arange(len(kept))
    stats.triangles, stats.vertices = len(kept_faces), len(kept)
    stats.seconds = time.perf_counter() - t0
    return kept, renumber[kept_faces], stats
