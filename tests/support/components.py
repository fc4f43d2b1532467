"""A mesh's connected components and the regions of the grid's sampled signs they border (for the tests
of the mesh's pieces and ``benchmarks/mesh_components.py``)."""

import numpy as np
import scipy.sparse as sp
from scipy import ndimage
from scipy.sparse.csgraph import connected_components

KUHN_STEPS = [(1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1), (1, 1, 1)]
"""The edges of the Kuhn split of a cell from a corner: the axes, the face diagonals and the main diagonal."""


def components(mesh) -> tuple[int, np.ndarray]:
    """The number of connected components (triangles sharing a vertex) and each vertex's component."""
    f = mesh.faces
    n = len(mesh.vertices)
    rows, cols = np.r_[f[:, 0], f[:, 1], f[:, 2]], np.r_[f[:, 1], f[:, 2], f[:, 0]]
    return connected_components(sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n, n)), directed=False)


def sign_regions(surface, bounds, depth) -> tuple[int, int]:
    """The regions of the sampled signs at the 2^depth grid's corners joined along the Kuhn split's edges:
    (inside: F < 0, outside: the rest with the outside of the bounds), sampled through ``Surface.eval``
    (NaN is outside, as the mesher takes it) and labelled by scipy."""
    n = (1 << depth) + 1
    axes = [np.linspace(lo, hi, n) for lo, hi in bounds]
    inside = np.zeros((n, n, n), bool)
    xx, yy = np.meshgrid(axes[0], axes[1], indexing="ij")
    for k, zv in enumerate(axes[2]):  # a layer at a time
        points = np.stack([xx.ravel(), yy.ravel(), np.full(xx.size, zv)], 1)
        inside[:, :, k] = (surface.eval(points, fast=True) < 0).reshape(n, n)
    kuhn = np.zeros((3, 3, 3), bool)
    kuhn[1, 1, 1] = True
    for d in KUHN_STEPS:
        kuhn[1 + d[0], 1 + d[1], 1 + d[2]] = kuhn[1 - d[0], 1 - d[1], 1 - d[2]] = True
    return ndimage.label(inside, kuhn)[1], ndimage.label(np.pad(~inside, 1, constant_values=True), kuhn)[1]


def lone_point_bubbles(mesh, depth, bounds) -> int:
    """Components (of a mesh made with ``witnesses=True``) whose every vertex lies on an edge from one and
    the same point that is not a grid corner: a closed surface around one added point alone."""
    count, label = components(mesh)
    lo = np.array([b[0] for b in bounds])
    step = (np.array([b[1] for b in bounds]) - lo) / (1 << depth)
    bubbles = 0
    for c in range(count):
        w = mesh.witnesses[label == c]
        for p in w[0]:
            if np.all(np.all(w[:, 0] == p, axis=1) | np.all(w[:, 1] == p, axis=1)):
                q = (p - lo) / step
                bubbles += not np.allclose(q, np.round(q), rtol=0, atol=1e-9)
                break
    return bubbles
