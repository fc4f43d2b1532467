"""Simplified meshes: the flat parts merged, every promise of the mesh kept, checked from outside.

Each simplified mesh goes through the validators of tests/test_mesh.py (edges and fans counted in numpy,
manifold3d, pymeshlab's topology and self-intersection selection, trimesh), its vertices through the
numpy sign-change check of their witnesses, its volume through the solid's bounds; and its distance to
the mesh it came from is measured both ways, point by point, against the tolerance.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy

import implc
from implc import shapes, x, y, z
from implc.cli.commands import main
from implc.files.scene import load as load_scene

from ..support.meshes import (
    BOX_BALL,
    SURFACES,
    assert_closed_manifold,
    assert_vertices_on_sign_changes,
    assert_volume_within,
    numpy_f,
    point_triangle_distance,
)

R = sympy.Rational
BOX = sympy.Max(sympy.Abs(x) - sympy.Rational(1, 2), sympy.Abs(y) - sympy.Rational(2, 5),
                sympy.Abs(z) - sympy.Rational(3, 10))
CASES = {  # name: (expression, bounds, the largest share of the triangles left)
    "box": (BOX, ((-1, 1),) * 3, 0.45),
    "tilted_box": (shapes.rotate(shapes.rotate(BOX, sympy.Rational(1, 3), "z"), sympy.Rational(1, 5), "x"),
                   ((-1, 1),) * 3, 0.5),
    "box_minus_ball": (BOX_BALL, ((-1, 1),) * 3, 0.9),
    "columns": (sympy.Min(shapes.box((R(7, 10), R(1, 10), R(7, 10))),
                          *[shapes.box((R(1, 10), R(6, 10), R(1, 10)), (R(a, 5), 0, R(c, 5)))
                            for a in (-2, 2) for c in (-2, 2)]),
                ((-1, 1),) * 3, 0.65),  # straight creases, faces in one plane on several columns
    "csg_part": (load_scene("csg_part").surface, load_scene("csg_part").bounds, 0.9),
    "heightfield": (*SURFACES["heightfield"], 0.97),  # its caps on the bounds' faces (merged before) are flat
}

SLOW = {"box_minus_ball", "csg_part"}  # the biggest meshes: in the slow set


def samples_on(mesh, count, rng):
    """Random points inside ``count`` of the mesh's triangles (its vertices are the full mesh's own)."""
    tri = mesh.vertices[mesh.faces[rng.choice(len(mesh.faces), min(count, len(mesh.faces)), replace=False)]]
    u, v = rng.random((2, len(tri)))
    flip = u + v > 1
    u[flip], v[flip] = 1 - u[flip], 1 - v[flip]
    inside = tri[:, 0] + u[:, None] * (tri[:, 1] - tri[:, 0]) + v[:, None] * (tri[:, 2] - tri[:, 0])
    return inside


def farthest(points, mesh, reach):
    """The largest distance from ``points`` to the mesh (each point against the triangles whose bounding
    box, grown by ``reach``, holds it; a point with none is ``reach`` away at least, reported as inf)."""
    tri = mesh.vertices[mesh.faces]
    lo, hi = tri.min(1) - reach, tri.max(1) + reach
    worst = 0.0
    for p in points:
        near = np.all((lo <= p) & (p <= hi), axis=1)
        worst = max(worst, point_triangle_distance(p, tri[near]).min() if near.any() else np.inf)
    return worst


@pytest.mark.parametrize("cells", [1e-3, pytest.param(0.3, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", [pytest.param(name, marks=pytest.mark.slow) if name in SLOW else name
                                  for name in sorted(CASES)])
def test_simplified_meshes_keep_every_promise_and_stay_within_the_tolerance(name, cells):
    """At a thousandth of a cell and at 0.3 of a cell (far more than CSG's flat faces need)."""
    expr, bounds, share = CASES[name]
    depth = 6
    cell = (bounds[0][1] - bounds[0][0]) / 2**depth
    tolerance = cells * cell
    voxels = implc.voxelize(implc.compile(expr, bounds), depth, solid=True)
    full = voxels.mesh(witnesses=True)
    mesh = voxels.mesh(witnesses=True, simplify=tolerance)
    assert len(mesh.faces) <= share * len(full.faces), (len(mesh.faces), len(full.faces))
    assert mesh.stats.simplified.triangles_before == len(full.faces) and mesh.stats.triangles == len(mesh.faces)
    assert_closed_manifold(mesh)
    assert_vertices_on_sign_changes(mesh, numpy_f(expr), bounds, depth, voxels.coords)
    assert_volume_within(mesh, *voxels.volume_bounds())
    assert abs(mesh.volume - full.volume) <= full.area * tolerance
    # every vertex is one of the full mesh's, with its normal
    rows = {tuple(v): k for k, v in enumerate(full.vertices)}
    index = np.array([rows[tuple(v)] for v in mesh.vertices])
    assert np.array_equal(mesh.normals, full.normals[index])
    # within the tolerance of each other, both ways (and the vertices dropped lie on the simplified mesh)
    rng = np.random.default_rng(3)
    dropped = np.setdiff1d(np.arange(len(full.vertices)), index)
    far = full.vertices[rng.choice(dropped, min(300, len(dropped)), replace=False)]
    assert farthest(far, mesh, 2 * cell) <= tolerance * (1 + 1e-6)
    assert farthest(samples_on(mesh, 300, rng), full, 2 * cell) <= tolerance * (1 + 1e-6)


def test_a_surface_without_flat_parts_is_left_as_it_is():
    expr, bounds = SURFACES["ball"]
    full = implc.mesh(implc.compile(expr, bounds), 5)
    mesh = full.simplified(1e-3)
    assert np.array_equal(mesh.faces, full.faces) and np.array_equal(mesh.vertices, full.vertices)


@pytest.mark.slow
def test_a_box_keeps_an_eighth_of_its_triangles_at_256():
    """libfive #595's complaint: a box inside the bounds at 256³, its six faces merged (the creases and the
    band of cells beside them keep their triangles), within a hundredth of a cell; the same mesh each time."""
    surface = implc.compile(BOX)
    voxels = implc.voxelize(surface, 8)
    mesh = voxels.mesh(simplify=0.01 * 2 / 256)
    before = mesh.stats.simplified.triangles_before
    assert before > 100_000 and len(mesh.faces) < before / 8
    again = voxels.mesh(simplify=0.01 * 2 / 256)
    assert np.array_equal(mesh.faces, again.faces) and np.array_equal(mesh.vertices, again.vertices)
    u, d = np.unique(np.sort(np.concatenate([mesh.faces[:, [0, 1]], mesh.faces[:, [1, 2]], mesh.faces[:, [2, 0]]]),
                             axis=1), axis=0, return_counts=True)
    assert np.all(d == 2)
    assert mesh.volume == pytest.approx(0.48, abs=0.02 * 4 * 3.76 / 256)


def test_bad_tolerances_are_refused(tmp_path, capsys):
    surface = implc.compile(BOX)
    for bad in (0, -1e-3, float("nan"), float("inf"), True, "0.1"):
        with pytest.raises(ValueError, match="simplify takes"):
            implc.mesh(surface, 4, simplify=bad)
    out = tmp_path / "b.stl"
    assert main(["mesh", "--expr", "Max(Abs(x), Abs(y), Abs(z)) - 0.5", "--depth", "4", "-o", str(out),
                 "--simplify", "-1"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--simplify" in err
    assert not out.exists()
    assert main(["mesh", "--expr", "Max(Abs(x), Abs(y), Abs(z)) - 0.5", "--depth", "6", "-o", str(out),
                 "--simplify", "1e-5"]) == 0
    assert "simplified from" in capsys.readouterr().out
    assert main(["info", str(out)]) == 0
    assert "closed: yes (0 open, 0 non-manifold edges)" in capsys.readouterr().out
