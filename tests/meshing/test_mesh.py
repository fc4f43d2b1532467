"""Meshes: closed, oriented 2-manifolds without degenerate or intersecting triangles, every vertex on an
edge of its cell where F (sampled by numpy through lambdify, or by the numpy interpreter of .vm text, not
by implc's compiler) changes sign, the volume inside the solid's bounds, the same for every worker count.

The outside validators: edges and fans counted here in numpy, manifold3d's status, pymeshlab's topological
measures and self-intersection selection (its candidates tested again in exact arithmetic: its own test has
tolerances), trimesh's watertightness and winding, tetgen in a subprocess.
"""

from __future__ import annotations

import subprocess
import sys
import threading
from fractions import Fraction
from pathlib import Path

import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given
from hypothesis import settings as hypothesis_settings
from hypothesis import strategies as st

import implc
from implc import x, y, z
from implc.cli.commands import main
from implc.compiler.symbols import cartesian_form
from implc.compiler.vm import parse_vm
from implc.files import voxel_files
from implc.files.scene import load as load_scene
from implc.meshing.contour import contour
from implc.meshing.contour_native import CONTOURING
from implc.meshing.proofs import DIAGONALS
from implc.meshing.triangle_mesh import Mesh, is_mesh_file

from ..support import vm_sampling
from ..support.meshes import (
    BOX_BALL,
    SURFACES,
    assert_closed_manifold,
    assert_on_witness_edges_in_kept_cells,
    assert_selected_faces_do_not_meet,
    assert_vertices_on_sign_changes,
    assert_volume_within,
    exact_volume,
    numpy_f,
    point_triangle_distance,
    triangles_meet,
)
from ..support.models import CSG

MODELS = Path(__file__).resolve().parents[3] / "shared" / "models"
SCENES = ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4", "csg_part", "torus", "tangle_cube", "gyroid_sphere",
          "heart", "spherical_flower")




def vm_f(text):
    rows = vm_sampling.parse(text)
    return lambda p: vm_sampling.evaluate(rows, p[:, 0].copy(), p[:, 1].copy(), p[:, 2].copy())






























def check_mesh(surface, depth, f, solid_voxels=None, effort=None, lean=True):
    """The mesh of ``surface`` at ``depth`` (contoured with ``effort`` where given; ``lean=False``: the
    tetrahedral construction everywhere, feature cells fanned), checked against ``f`` (F by numpy): closed,
    manifold, every vertex on a sign change, the volume within the voxels' bounds."""
    voxels = implc.voxelize(surface, depth, solid=solid_voxels is None or solid_voxels)
    mesh = (voxels.mesh(witnesses=True) if effort is None and lean
            else contour(surface, voxels.coords, voxels.depth, voxels.bounds, witnesses=True, lean=lean,
                         **({} if effort is None else {"effort": effort})))
    assert_closed_manifold(mesh)
    assert_vertices_on_sign_changes(mesh, f, surface.bounds, depth, voxels.coords)
    assert_volume_within(mesh, *voxels.volume_bounds())
    assert mesh.stats.added_cells == 0
    assert np.allclose(np.linalg.norm(mesh.normals, axis=1), 1)
    return mesh


# -- the surfaces ---------------------------------------------------------------------------------------
@pytest.mark.parametrize("name", sorted(SURFACES))
def test_surfaces_mesh_closed_manifold_and_on_the_surface(name):
    expr, bounds = SURFACES[name]
    check_mesh(implc.compile(expr, bounds), 5, numpy_f(expr))


@pytest.mark.parametrize("name", SCENES)
def test_scenes_mesh_closed_manifold_and_on_the_surface(name):
    sc = load_scene(name)
    check_mesh(implc.compile(sc.surface, sc.bounds), 5, numpy_f(sc.surface))


def test_a_vm_model_meshes_on_the_tape_engine():
    model = parse_vm(CSG, name="csg")
    surface = implc.compile(model, engine="tape")
    check_mesh(surface, 6, vm_f(CSG))


@pytest.mark.slow
@pytest.mark.parametrize("name", sorted(SURFACES) + list(SCENES))
def test_at_128(name):
    if name in SURFACES:
        expr, bounds = SURFACES[name]
    else:
        sc = load_scene(name)
        expr, bounds = sc.surface, sc.bounds
    check_mesh(implc.compile(expr, bounds), 7, numpy_f(expr))


@pytest.mark.slow
@pytest.mark.parametrize("name", ["bear", "colonnade"])
def test_peer_models_at_128(name):
    path = MODELS / f"{name}.vm"
    if not path.is_file():
        pytest.skip(f"{path} is not here (the shared models)")
    text = path.read_text()
    assert vm_sampling.uses_z(vm_sampling.parse(text)), "both models are 3D: no extrusion is needed"
    check_mesh(implc.compile(implc.load_vm(str(path))), 7, vm_f(text))




def test_point_triangle_distance_against_dense_sampling():
    rng = np.random.default_rng(1)
    tri = rng.normal(size=(50, 3, 3))
    u, v = np.meshgrid(np.linspace(0, 1, 201), np.linspace(0, 1, 201))
    keep = u + v <= 1
    u, v = u[keep], v[keep]
    for p in rng.normal(size=(5, 3)) * 2:
        d = point_triangle_distance(p, tri)
        for k in range(0, 50, 7):
            samples = tri[k, 0] + u[:, None] * (tri[k, 1] - tri[k, 0]) + v[:, None] * (tri[k, 2] - tri[k, 0])
            dense = np.linalg.norm(samples - p, axis=1).min()
            assert d[k] <= dense + 1e-12 and d[k] >= dense - 0.02 * np.linalg.norm(tri[k, 1] - tri[k, 0])


def crease_points():
    """Points on the creases of BOX_BALL: the box's edges and corner, and the circles where the ball's
    cavity meets the box's faces (radius sqrt(0.75² − 0.6²) = 0.45)."""
    edge = [(0.6, 0.6, t) for t in np.linspace(-0.55, 0.55, 23)] + [(-0.6, t, 0.6) for t in np.linspace(-0.5, 0.5, 9)]
    circle = [(0.6, 0.45 * np.cos(a), 0.45 * np.sin(a)) for a in np.linspace(0, 2 * np.pi, 60, endpoint=False)]
    circle += [(0.45 * np.cos(a), 0.45 * np.sin(a), -0.6) for a in np.linspace(0, 2 * np.pi, 30, endpoint=False)]
    return np.array(edge + circle + [(0.6, 0.6, 0.6), (-0.6, -0.6, 0.6)])


def crease_distances(mesh, cell):
    tri = mesh.vertices[mesh.faces]
    centre = tri.mean(1)
    out = []
    for p in crease_points():
        near = np.linalg.norm(centre - p, axis=1) < 4 * cell
        out.append(point_triangle_distance(p, tri[near]).min() / cell)
    return np.array(out)


def test_creases_and_corners_of_csg_are_sharp():
    """Each crease point of a box minus a ball lies within a fifth of a cell of the mesh (median under a
    twentieth); the same mesh without its feature cells chamfers them by a third of a cell and more."""
    surface = implc.compile(BOX_BALL)
    depth, cell = 6, 2 / 64
    voxels = implc.voxelize(surface, depth)
    sharp = crease_distances(voxels.mesh(), cell)
    chamfered = crease_distances(voxels.mesh(features=False), cell)
    assert sharp.max() < 0.2 and np.median(sharp) < 0.05, (sharp.max(), np.median(sharp))
    assert chamfered.max() > 0.3


def _planes(rng, normals, per_plane=4):
    """Points on planes through one random point c with the given normals (a few points each, spread along
    the plane), the rows' normals, and c."""
    c = rng.uniform(-1, 1, 3)
    points, unit = [], []
    for n in normals:
        n = np.asarray(n, float) / np.linalg.norm(n)
        a = np.cross(n, [1.0, 0, 0] if abs(n[0]) < 0.9 else [0, 1.0, 0])
        a /= np.linalg.norm(a)
        b = np.cross(n, a)
        for u, v in rng.uniform(-0.5, 0.5, (per_plane, 2)):
            points.append(c + u * a + v * b)
            unit.append(n)
    return np.array(points), np.array(unit), c


def test_the_qef_point_is_where_the_planes_meet_and_the_mean_where_they_do_not_constrain():
    """implc_qef against the geometry in closed form: three planes meet at their common point; two planes
    (a crease) at the point of their line nearest the points' mean; one plane at the mean's projection on
    it; a face's 2D QEF (an axis projected out) keeps the mean's coordinate on that axis. Masked-out rows
    carry garbage that must not count."""
    from implc.meshing.features import _qef
    from implc.native.runtime import Runtime

    rng = np.random.default_rng(7)
    runtime = Runtime.shared().library(CONTOURING)
    for trial in range(200):
        count = trial % 3 + 1
        normals = rng.normal(size=(count, 3))
        if count == 2 and abs(np.dot(*normals) / np.prod(np.linalg.norm(normals, axis=1))) > 0.85:
            continue  # planes within 30 degrees: their line is ill-conditioned, not a check of the solver
        if count == 3 and abs(np.linalg.det(normals / np.linalg.norm(normals, axis=1)[:, None])) < 0.3:
            continue
        p, n, c = _planes(rng, normals)
        points = np.concatenate([p, rng.normal(size=(3, 3)) * 100])[None]
        unit = np.concatenate([n, rng.normal(size=(3, 3))])[None]
        mask = np.r_[np.ones(len(p), bool), np.zeros(3, bool)][None]
        got = _qef(runtime, points, unit, mask)[0]
        mean = p.mean(0)
        u = normals / np.linalg.norm(normals, axis=1)[:, None]
        if count == 3:
            want = c
        elif count == 2:
            d = np.cross(u[0], u[1])
            want = np.linalg.solve(np.array([u[0], u[1], d]), [u[0] @ c, u[1] @ c, d @ mean])
        else:
            want = mean - u[0] * (u[0] @ (mean - c))
        assert np.allclose(got, want, atol=1e-9), (count, got, want)
        axis = trial % 3
        flat = _qef(runtime, points, unit, mask, project_out=axis)[0]
        assert flat[axis] == pytest.approx(mean[axis], abs=1e-12)


def edge_parameters(mesh):
    """For the vertices found on an edge (witnesses apart): their rows, the edge's length and the vertex's
    place t along it (0 at the inside end)."""
    a, b = mesh.witnesses[:, 0], mesh.witnesses[:, 1]
    rows = np.flatnonzero(np.any(a != b, axis=1))
    a, b, v = a[rows], b[rows], mesh.vertices[rows]
    length = np.linalg.norm(b - a, axis=1)
    t = np.einsum("ij,ij->i", v - a, b - a) / length**2
    on = np.all(np.abs(a + t[:, None] * (b - a) - v) <= 1e-12, axis=1)  # not a dual vertex (inside its cell)
    return rows[on], length[on], t[on]


@pytest.mark.parametrize("depth", [5, 7])
def test_vertices_lie_on_a_ball_and_their_normals_are_its_normals_near_them(depth):
    """A ball's distance and normal in closed form. The tetrahedral construction's vertices (on edges; the
    dual vertices' QEF points come from them): every vertex on an edge lies on the sphere but for its
    nudge (NUDGE of the edge) and Newton's last step's error, quadratic in that step (at most ROOT_TOLERANCE
    of the edge): F = |p|² − r² is quadratic along an edge of length L, F'' = 2L² per unit of t, so after a
    Newton step s, F = L²s² and the point lies L²s² / 2r from the sphere: within ROOT_TOLERANCE² · L / 2r of
    the edge (measured: up to 0.49 of that); or, where the root
    lies within EDGE_MARGIN of an edge's end, at that margin. Its normal is the sphere's normal at a point at
    most ROOT_TOLERANCE of the edge away (within that distance over r, in radians).
    The dual mesh (every crossed cell of a ball is dual): each vertex, where the tangent planes at its
    cell's crossings meet, lies within the sagitta of a cell's diagonal D = √3·h (D² / 2r: a point of a
    tangent plane that far from its tangency) of the sphere, give or take its crossings' own distance (up
    to EDGE_MARGIN + NUDGE of the edge); its normal is F's gradient there, the sphere's normal there."""
    from implc.meshing.vertices import EDGE_MARGIN, NUDGE, ROOT_TOLERANCE
    r = np.sqrt(0.5)
    surface = implc.compile(x**2 + y**2 + z**2 - sympy.Rational(1, 2))
    mesh = _tetrahedral(surface, depth, witnesses=True)
    rows, length, t = edge_parameters(mesh)
    assert len(rows) == len(mesh.vertices)
    v, n = mesh.vertices[rows], mesh.normals[rows]
    distance = np.abs(np.linalg.norm(v, axis=1) - r)
    at_margin = (t < EDGE_MARGIN + 2 * NUDGE) | (t > 1 - EDGE_MARGIN - 2 * NUDGE)
    assert at_margin.mean() < 0.01
    newton = ROOT_TOLERANCE**2 * length[~at_margin] / (2 * r)
    assert np.all(distance[~at_margin] <= (NUDGE + newton) * length[~at_margin])
    assert np.all(distance[at_margin] <= (EDGE_MARGIN + NUDGE) * length[at_margin])
    angle = np.arccos(np.clip(np.einsum("ij,ij->i", n, v / np.linalg.norm(v, axis=1)[:, None]), -1, 1))
    assert np.all(angle <= ROOT_TOLERANCE * length / r)
    dual = implc.mesh(surface, depth)
    h = 2 / 2**depth
    assert dual.stats.dual_cells == dual.stats.crossed_cells == len(dual.vertices)
    radius = np.linalg.norm(dual.vertices, axis=1)
    assert np.all(np.abs(radius - r) <= 3 * h * h / (2 * r) + (EDGE_MARGIN + NUDGE) * h)
    cosine = np.einsum("ij,ij->i", dual.normals, dual.vertices / radius[:, None])
    assert np.all(cosine >= 1 - 1e-12)


def test_a_face_on_a_grid_plane_keeps_its_vertices_at_the_edges_margin():
    """A box whose face x = 1/2 lies on a plane of the grid (F = 0 at those corners, taken as outside): every
    vertex of that face lies at the margin of its edge next to the plane, however the root search went."""
    from implc.meshing.vertices import EDGE_MARGIN, NUDGE
    box = sympy.Max(sympy.Abs(x) - sympy.Rational(1, 2), sympy.Abs(y) - sympy.Rational(2, 5),
                    sympy.Abs(z) - sympy.Rational(3, 10))
    voxels = implc.voxelize(implc.compile(box), 6)
    mesh = contour(voxels.surface, voxels.coords, 6, voxels.bounds, witnesses=True, lean=False)
    rows, length, _ = edge_parameters(mesh)
    face = np.abs(mesh.normals[rows, 0]) == 1
    assert face.sum() > 1000
    gap = np.abs(np.abs(mesh.vertices[rows[face], 0]) - 0.5)
    assert np.all(gap <= (EDGE_MARGIN + NUDGE) * length[face])


# -- the native pieces ------------------------------------------------------------------------------------
def test_the_key_index_numbers_keys_in_first_seen_order_as_it_grows():
    from implc.meshing.grid import KeyIndex as _KeyIndex
    from implc.native.runtime import Runtime
    rng = np.random.default_rng(3)
    keys = rng.integers(0, 1 << 40, 50_000) * 1_000_003 % (1 << 50)
    keys = np.concatenate([keys, keys[::7]])  # repeats
    index = _KeyIndex(Runtime.shared().library(CONTOURING), 16)  # grows many times
    numbers = np.concatenate([index.number(chunk) for chunk in np.array_split(keys, 13)])
    first = np.unique(keys, return_index=True)[1]
    assert np.array_equal(index.keys(), keys[np.sort(first)])  # first-seen order, each once
    assert np.array_equal(index.keys()[numbers], keys)
    absent = np.array([5, (1 << 50) + 1])
    assert np.array_equal(index.number(absent, insert=False), [-1, -1]) or 5 in keys
    # a table sized by the keys it holds, not by the repeats shown
    shown = _KeyIndex(Runtime.shared().library(CONTOURING), 16)
    distinct = np.arange(5000, dtype=np.int64) * 7919
    assert np.array_equal(shown.number(np.tile(distinct, 40)), np.tile(np.arange(5000), 40))
    assert shown.count == 5000 and shown.limit == 8192


# -- properties of the construction ------------------------------------------------------------------
def test_the_exact_intersection_test_finds_crossing_triangles_and_spares_disjoint_ones():
    """The exact test behind the self-intersection check: crossing, touching and disjoint pairs, and
    the nearly coplanar pair (10^-12 apart) that a tolerance calls coplanar, coplanar pairs."""
    t = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert triangles_meet(t, np.array([[0.2, 0.2, -1], [0.2, 0.2, 1], [0.3, 0.1, 1]]))  # pierces it
    assert triangles_meet(t, np.array([[1.0, 0, 0], [1, 1, 1], [2, 0, 1]]))  # touches a corner
    assert not triangles_meet(t, t + [0, 0, 1e-12])  # parallel, disjoint
    assert not triangles_meet(t, np.array([[0.6, 0.6, 0], [1, 1, 0], [1, 0.6, 1e-12]]))  # an edge in its plane
    assert not triangles_meet(t, np.array([[0.6, 0.6, 0], [1, 1, 0], [1, 0.6, 0]]))  # coplanar, beside it
    assert triangles_meet(t, np.array([[0.4, 0.4, 0], [1, 1, 0], [1, 0.6, 0]]))  # coplanar, overlapping
    assert triangles_meet(t, np.array([[0.5, 0.5, 0], [1, 1, 0], [1, 0.6, 0]]))  # coplanar, touching its edge
    with pytest.raises(AssertionError, match="self-intersecting"):
        vertices = np.concatenate([t, [[0.2, 0.2, -1], [0.2, 0.2, 1], [0.3, 0.1, 1]]])
        assert_selected_faces_do_not_meet(vertices, np.array([[0, 1, 2], [3, 4, 5]]), np.array([0, 1]))


def test_a_slab_across_an_axis_mid_cell_passes_the_exact_intersection_test():
    """Found by fuzzing: a slab whose faces cross the y axis between grid planes (odd bounds, 64³) made
    pymeshlab select 360 faces, nearly coplanar and disjoint; the exact test passes every pair."""
    expr = sympy.Abs(y + sympy.Rational(3, 8)) - sympy.Rational(1, 8)
    check_mesh(implc.compile(expr, ((-0.39, 0.55), (-0.75, 0.53), (-0.56, 0.58))), 6, numpy_f(expr))


def test_a_cap_around_an_inside_face_point_where_no_corner_of_the_face_is_inside(monkeypatch):
    """Found by fuzzing (test_fuzz_random_csg_meshes): a crease reaching a face of the bounds where F is
    positive at every grid corner, but negative at the face point of a feature cell's square there. The
    fan's tetrahedra reached the face around that point and the face got no cap (it was skipped for having
    no negative corner): 8 edges in one face only. The cap now closes it. (Points are now moved where
    their sign meets a corner's, which avoids this case here; it remains where no place tried agrees, so
    the points are left where the QEF put them, as then.)"""
    from implc.meshing import features
    monkeypatch.setattr(features, "_joined", lambda grid, points, corners: points)
    r16 = sympy.Rational(1, 16)
    expr = sympy.Max(sympy.Min(sympy.Abs(z + sympy.Rational(3, 8)) - sympy.Rational(1, 32),
                               (43 * x + 43 * y + 38 * z - 3) / 100),
                     sympy.Min((-81 * x + 13 * y + 32 * z + 13) / 100, y**2 + z**2 + (x - 5 * r16) ** 2 - r16,
                               y**2 + z**2 + (x + 3 * r16) ** 2 - r16))
    bounds = ((-0.43, 0.77), (-1.19, 1.04), (-0.37, 1.15))
    surface = implc.compile(expr, bounds)
    corners = np.stack(np.meshgrid(*[np.linspace(lo, hi, 17) for lo, hi in bounds], indexing="ij"), -1)
    assert np.all(numpy_f(expr)(corners[0].reshape(-1, 3)) > 0), "the case: no corner of the face x = lo inside"
    mesh = check_mesh(surface, 4, numpy_f(expr), lean=False)
    assert np.any(mesh.vertices[:, 0] == bounds[0][0]) and mesh.stats.feature_cells > 0


def test_a_solid_filling_odd_bounds_has_their_exact_volume():
    """Found by fuzzing: a plane that misses the bounds, the solid filling them, gives the box's six caps;
    their volume summed in doubles fell an ulp below volume_bounds()' lower bound (the box's exact volume,
    rounded down). The mesh's exact volume is the box's."""
    bounds = ((-0.71, 1.2), (-0.43, 0.61), (-0.56, 0.88))
    expr = -3 * x / 20 - 21 * y / 100 - 23 * z / 100 - sympy.Rational(17, 50)
    mesh = check_mesh(implc.compile(expr, bounds), 5, numpy_f(expr))
    box = Fraction(1)
    for lo, hi in bounds:
        box *= Fraction(hi) - Fraction(lo)
    assert mesh.stats.cells == 0 and exact_volume(mesh) == box


@pytest.mark.parametrize("engine", ["jit", "tape"])
def test_a_plane_through_grid_corners_brackets_its_exact_zeros(engine):
    """Found by fuzzing: where F is exactly 0 at grid corners (a plane with rational coefficients through
    them), a double evaluation may give ±1e-17 there (numpy's lambdify does, the tape engine's order of
    operations too), so numpy's F is no oracle of the signs. In exact rational arithmetic every witness
    pair still brackets a zero of F on its edge (F <= 0 at the inside end, >= 0 at the other) and every
    cap corner has F <= 0; every vertex lies in a kept cell."""
    expr = 7 * x / 20 - 61 * y / 100 - 69 * z / 100 - sympy.Rational(1, 25)
    coefficients = [Fraction(7, 20), Fraction(-61, 100), Fraction(-69, 100)]

    def exact(p):
        return sum(c * Fraction(v) for c, v in zip(coefficients, p)) - Fraction(1, 25)

    surface = implc.compile(expr, ((-1, 1),) * 3, engine=engine)
    voxels = implc.voxelize(surface, 6, solid=True)
    mesh = voxels.mesh(witnesses=True)
    assert_closed_manifold(mesh)
    ends = mesh.witnesses.tolist()
    zeros = 0
    for a, b in ends:
        fa, fb = exact(a), exact(b)
        assert fa <= 0 and (a == b or fb >= 0), (a, b, fa, fb)
        zeros += fa == 0
    assert zeros > 0, "the case the test is for: witnesses where F is exactly 0"
    assert_on_witness_edges_in_kept_cells(mesh, ((-1, 1),) * 3, 6, voxels.coords)


@pytest.mark.parametrize("name", ["paper_blobs", "vm"])
def test_the_same_mesh_for_every_worker_count(name):
    """The mesh does not depend on how many threads make it: with calls of 64 rows (so that the samples,
    the enclosures and the tape engine's groups are shared out over the threads even at 64³), one, two and
    three workers give the same vertices, faces and normals, bit for bit."""
    from implc.common.threads import fewest_rows

    if name == "vm":
        s = implc.compile(parse_vm(CSG, name="csg"), engine="tape")
    else:
        sc = load_scene(name)
        s = implc.compile(sc.surface, sc.bounds)
    with fewest_rows(64):
        one = implc.mesh(s, 6, workers=1)
        for workers in (2, 3):
            other = implc.mesh(s, 6, workers=workers)
            assert np.array_equal(one.vertices, other.vertices) and np.array_equal(one.faces, other.faces)
            assert np.array_equal(one.normals, other.normals)


def test_contouring_runs_on_the_threads_it_is_given(monkeypatch):
    """``workers=1`` keeps the contouring's native calls on the calling thread; ``workers=2`` shares each
    batch of calls out over at most two threads of a pool (recorded by the thread each call runs on)."""
    from implc.common.threads import fewest_rows
    from implc.engines import surface as surface_module

    batches: list[list[str]] = []
    original = surface_module.in_parallel

    def recording(jobs):
        names: list[str] = []
        batches.append(names)

        def wrap(job):
            def run():
                names.append(threading.current_thread().name)
                job()
            return run
        original([wrap(job) for job in jobs])

    monkeypatch.setattr(surface_module, "in_parallel", recording)
    sc = load_scene("paper_blobs")
    voxels = implc.voxelize(implc.compile(sc.surface, sc.bounds), 6)
    with fewest_rows(64):
        voxels.mesh(workers=1)
    assert sum(map(len, batches)) > 10 and {name for names in batches for name in names} == {"MainThread"}
    batches.clear()
    with fewest_rows(64):
        voxels.mesh(workers=2)
    shared = [set(names) for names in batches if len(names) > 1]
    assert shared and all(len(names) <= 2 and "MainThread" not in names for names in shared)


def surface_and_f(name):
    """A test surface by name ("vm": the CSG tape on the tape engine) and F in numpy, not through implc."""
    if name == "vm":
        return implc.compile(parse_vm(CSG, name="csg"), engine="tape"), vm_f(CSG)
    expr, bounds = SURFACES[name]
    return implc.compile(expr, bounds), numpy_f(expr)


@pytest.mark.parametrize("name", ["box_minus_ball", "heightfield", "vm"])
def test_vertices_and_corners_done_in_chunks_keep_every_promise(name, monkeypatch):
    """The vertices are placed, and the cells' corners sampled, a chunk at a time (so that a big mesh's
    memory follows the chunk): with chunks of 97 (creases fanned from cell and face points, caps on the
    bounds, the tape engine's grouped samples all cut across chunks) the mesh passes every check, and is
    the mesh made in one chunk (the model's with the tetrahedral construction everywhere, its feature cells
    fanned)."""
    from implc.meshing.grid import Effort

    s, f = surface_and_f(name)
    lean = name != "vm"
    voxels = implc.voxelize(s, 5, solid=True)
    whole = contour(s, voxels.coords, 5, voxels.bounds, witnesses=True, lean=lean)
    assert whole.stats.dual_cells > 0 if lean else whole.stats.feature_cells > 0
    assert whole.stats.cap_triangles > 0 or name != "heightfield"
    assert len(whole.vertices) > 10 * 97
    chunked = check_mesh(s, 5, f, effort=Effort(vertex_chunk=97), lean=lean)
    for a, b in ((whole.vertices, chunked.vertices), (whole.faces, chunked.faces), (whole.normals, chunked.normals),
                 (whole.witnesses, chunked.witnesses)):
        assert np.array_equal(a, b)


def test_meshes_made_at_once_in_several_threads_are_each_the_mesh_made_alone():
    """Meshing releases the GIL in its native routines, so several threads may mesh at once (a server, a
    notebook's background jobs): each mesh, vertices, normals and triangles, is the mesh made alone, bit
    for bit (test_layers checks that no native routine reads an array freed before the call)."""
    import threading

    s = implc.compile(x**2 + y**2 + z**2 - sympy.Rational(1, 2) + sympy.sin(4 * x) / 8)
    voxels = implc.voxelize(s, 6, **implc.NATURAL)
    alone = voxels.mesh()
    meshes: list = [None] * 3
    threads = [threading.Thread(target=lambda k=k: meshes.__setitem__(k, voxels.mesh())) for k in range(3)]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join()
    for mesh in meshes:
        for a, b in ((alone.vertices, mesh.vertices), (alone.faces, mesh.faces), (alone.normals, mesh.normals)):
            assert np.array_equal(a, b)


@pytest.mark.parametrize("name", ["box_minus_ball", "heightfield", "vm"])
def test_key_indexes_grown_from_their_smallest_give_the_same_mesh(name, monkeypatch):
    """Every key index (the cells', the corners', the vertices') starts at its smallest (2048 keys) and
    grows as the native routines fill it (they stop before a cell when it is full, and go on after it is
    rehashed: the corners' numbering, the Kuhn split, the fans): the mesh passes every check and is, bit for
    bit, the mesh made with indexes sized in advance (keys keep the numbers they were first given)."""
    from implc.meshing.grid import KeyIndex

    s, f = surface_and_f(name)
    depth = 6 if name == "vm" else 5  # the small model's keys outgrow the smallest indexes three times at 64³
    sized = implc.voxelize(s, depth, solid=True).mesh(witnesses=True)
    grows = []
    original_init, original_grow = KeyIndex.__init__, KeyIndex._grow

    def smallest(self, runtime, expected):
        original_init(self, runtime, 1)

    def grow(self):
        grows.append(self.count)
        original_grow(self)

    monkeypatch.setattr(KeyIndex, "__init__", smallest)
    monkeypatch.setattr(KeyIndex, "_grow", grow)
    grown = check_mesh(s, depth, f)
    assert len(grows) >= 3, grows
    for a, b in ((sized.vertices, grown.vertices), (sized.faces, grown.faces), (sized.normals, grown.normals),
                 (sized.witnesses, grown.witnesses)):
        assert np.array_equal(a, b)


@pytest.mark.parametrize("name", ["paper_blobs", "box_minus_ball", "vm"])
def test_the_same_mesh_for_every_tightness(name):
    """A tighter voxelization drops only cells proven not to meet the surface (their sampled corners agree):
    the natural mode's voxels, more cells, give the very mesh of the default's and the tightest's; which is
    why implc.mesh voxelizes in the natural mode."""
    if name == "vm":
        s = implc.compile(parse_vm(CSG, name="csg"), engine="tape")
    else:
        expr, bounds = (load_scene(name).surface, load_scene(name).bounds) if name in SCENES else SURFACES[name]
        s = implc.compile(expr, bounds)
    voxels = [implc.voxelize(s, 6, **mode) for mode in (implc.NATURAL, {}, implc.TIGHTEST)]
    assert len(voxels[0]) >= len(voxels[1]) >= len(voxels[2])
    if name == "paper_blobs":
        assert len(voxels[0]) > len(voxels[1]), "the case the test is for: the natural mode keeps more cells"
    meshes = [v.mesh() for v in voxels]
    for other in meshes[1:]:
        assert np.array_equal(meshes[0].vertices, other.vertices) and np.array_equal(meshes[0].faces, other.faces)
    made = implc.mesh(s, 6)
    assert made.stats.cells == len(voxels[0]) and np.array_equal(made.faces, meshes[0].faces)


def test_the_mesh_command_voxelizes_in_the_natural_mode_unless_told(tmp_path, monkeypatch):
    import implc.voxelizer.voxelize as voxelization
    seen = []
    real = voxelization.voxelize

    def spy(*args, **kwargs):
        seen.append(kwargs.get("refine_leaves", "auto"))
        return real(*args, **kwargs)

    monkeypatch.setattr(voxelization, "voxelize", spy)
    out = str(tmp_path / "t.stl")
    assert main(["mesh", "torus", "--depth", "4", "-o", out, "--quiet"]) == 0
    assert main(["mesh", "torus", "--depth", "4", "-o", out, "--quiet", "--tightness", "default"]) == 0
    assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "t.npz"), "--quiet"]) == 0
    assert seen == [False, "auto", "auto"]


def test_a_solid_filling_the_bounds_is_the_box():
    s = implc.compile(x + y + z - 10, ((-1, 1),) * 3)  # F < 0 everywhere: the mesh is the box itself
    mesh = implc.mesh(s, 3)
    assert_closed_manifold(mesh)
    assert mesh.volume == pytest.approx(8.0, rel=1e-12)
    assert np.all(np.abs(mesh.vertices).max(1) == 1)
    v, n = mesh.vertices, mesh.normals
    on = np.abs(v) == 1
    flat = on.sum(1) == 1  # inside a face: its outward normal; on an edge or a corner: between its faces'
    assert np.array_equal(n[flat], np.where(on[flat], np.sign(v[flat]), 0.0))
    assert np.all(np.einsum("ij,ij->i", n[~flat], np.where(on[~flat], np.sign(v[~flat]), 0.0)) > 1)
    assert np.allclose(np.linalg.norm(n, axis=1), 1)


def test_faces_of_the_bounds_proven_outside_are_not_sampled_unless_a_contoured_cell_reaches_them(monkeypatch):
    """A face of the bounds that no kept cell touches, with F > 0 at its centre, is not sampled (F keeps
    its sign over it); where the cells the samples' signs add reach such a face after all (here: contouring
    from half the kept cells, the surface running on to the face), it is sampled then and capped: the same
    closed mesh as from every kept cell."""
    from implc.meshing.grid import Grid
    s = implc.compile(sympy.Rational(1, 10) - y + x**2 / 8, ((-1, 1),) * 3)  # the solid y > 0.1 + x²/8
    depth = 4
    voxels = implc.voxelize(s, depth)
    sampled = []
    original = Grid.face_values

    def face_values(grid, axis, side, keys):  # a face's values are sampled on its first call, then kept
        if (axis, side) not in grid._faces:
            sampled.append((axis, side))
        return original(grid, axis, side, keys)

    monkeypatch.setattr(Grid, "face_values", face_values)
    whole = voxels.mesh()
    assert (1, 0) not in sampled and sorted(sampled) == [(0, 0), (0, 1), (1, 1), (2, 0), (2, 1)]
    assert_closed_manifold(whole)
    sampled.clear()
    half = voxels.coords[voxels.coords[:, 0] < 1 << (depth - 1)]  # none on the face x = 1
    mesh = contour(s, half, depth)
    assert (0, 1) in sampled and (1, 0) not in sampled
    assert mesh.stats.added_cells > 0
    assert_closed_manifold(mesh)
    assert len(mesh.faces) == len(whole.faces)  # the same triangles, numbered in another order
    assert np.array_equal(np.unique(mesh.vertices[mesh.faces].reshape(-1, 9), axis=0),
                          np.unique(whole.vertices[whole.faces].reshape(-1, 9), axis=0))
    assert mesh.volume == pytest.approx(whole.volume, rel=1e-12)


def test_caps_merge_inside_squares_into_fans_and_stay_closed(monkeypatch):
    """Where the solid fills a face of the bounds, the squares inside throughout are merged into aligned
    blocks, each a fan over its boundary: a box at 64³ costs 11,808 triangles, not 6 · 2 · 64² = 49,152,
    and still meets every validator, edge for edge, with the exact volume; a clipped heightfield loses
    three quarters of its caps' triangles and keeps its volume."""
    s = implc.compile(x + y + z - 10, ((-1, 1),) * 3)
    mesh = implc.mesh(s, 6)
    assert_closed_manifold(mesh)
    assert len(mesh.faces) <= 6 * 2 * 64 * 64 // 4
    assert mesh.volume == pytest.approx(8.0, rel=1e-12)
    expr, bounds = SURFACES["heightfield"]
    surface = implc.compile(expr, bounds)
    merged = check_mesh(surface, 6, numpy_f(expr))
    from implc.meshing import caps
    monkeypatch.setattr(caps, "_cap_blocks", lambda whole: ([], np.zeros_like(whole)))
    square_by_square = implc.mesh(surface, 6)
    assert merged.stats.cap_triangles * 3 < square_by_square.stats.cap_triangles
    assert merged.volume == pytest.approx(square_by_square.volume, rel=1e-13)


def test_caps_merge_beside_the_fanned_squares_of_creases_crossing_the_bounds():
    """A CSG column clipped by the bounds: its four creases cross the top and bottom faces, whose caps hold
    squares fanned from face points (feature cells) next to merged blocks; every validator passes, and the
    volume is the column's (1 × 0.6 × 2) within the voxels' bounds."""
    expr = sympy.Max(sympy.Abs(x) - sympy.Rational(1, 2), sympy.Abs(y) - sympy.Rational(3, 10), z - 2)
    surface = implc.compile(expr, ((-1, 1),) * 3)
    mesh = check_mesh(surface, 6, numpy_f(expr), lean=False)
    assert mesh.stats.feature_cells > 0 and mesh.stats.cap_triangles > 0
    assert mesh.volume == pytest.approx(1.2, abs=2e-3)


def test_nothing_inside_gives_an_empty_mesh():
    mesh = implc.mesh(implc.compile(x**2 + y**2 + z**2 + 1), 4)
    assert len(mesh.faces) == 0 and len(mesh.vertices) == 0


def test_voxels_from_a_file_need_their_surface(tmp_path):
    expr, bounds = SURFACES["ball"]
    s = implc.compile(expr, bounds)
    voxel_files.save(implc.voxelize(s, 4), tmp_path / "b.npz")
    loaded = voxel_files.load_npz(tmp_path / "b.npz")
    with pytest.raises(ValueError, match="do not know their surface"):
        loaded.mesh()
    assert np.array_equal(loaded.mesh(s).faces, implc.mesh(s, 4).faces)


# -- Mesh.check: the counted checks find what they claim to --------------------------------------------
def tetrahedron(offset=0.0):
    v = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], float) + offset
    f = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    return v, f


def test_check_counts_each_defect():
    v, f = tetrahedron()
    good = Mesh(v, f).check()
    assert good == {**good, "open_edges": 0, "overused_edges": 0, "repeated_directed_edges": 0, "degenerate": 0,
                    "split_vertices": 0}
    assert good["volume"] == pytest.approx(1 / 6)
    flipped = f.copy()
    flipped[0] = flipped[0][::-1]
    assert Mesh(v, flipped).check()["repeated_directed_edges"] == 3
    assert Mesh(v, f[1:]).check()["open_edges"] == 3
    assert Mesh(v, np.vstack([f, [[0, 1, 1]]])).check()["degenerate"] == 1
    v2, f2 = tetrahedron(offset=-1.0)  # a second tetrahedron sharing only the corner (0, 0, 0)
    pinched_v = np.vstack([v, v2[:3]])
    f2 = np.where(f2 == 3, 0, f2 + 4)
    assert Mesh(pinched_v, np.vstack([f, f2])).check()["split_vertices"] == 1
    assert Mesh(v, f[1:]).check()["split_vertices"] is None  # fans are not defined on an open mesh
    import trimesh
    ball = trimesh.creation.icosphere(3)  # two balls touching at one vertex: long fans, one pinch
    other = ball.vertices * [-1, 1, 1] + 2 * ball.vertices[0] * [1, 0, 0]
    other_faces = ball.faces[:, ::-1] + len(ball.vertices)
    twins = Mesh(np.vstack([ball.vertices, other]), np.vstack([ball.faces, other_faces]))
    assert twins.check()["split_vertices"] == 0  # not joined yet: two separate balls
    shared = np.where(other_faces == len(ball.vertices), 0, other_faces)
    pinched = Mesh(np.vstack([ball.vertices, other]), np.vstack([ball.faces, shared]))
    assert pinched.check()["split_vertices"] == 1


# -- files and the command -------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".glb", ".3mf"])
def test_files_round_trip_through_trimesh(tmp_path, suffix):
    import trimesh
    expr, bounds = SURFACES["ball"]
    mesh = implc.mesh(implc.compile(expr, bounds), 4)
    path = mesh.save(tmp_path / f"ball{suffix}")
    assert [p.name for p in tmp_path.iterdir()] == [path.name]  # no temporary left
    back = trimesh.load(str(path), force="mesh")
    back.merge_vertices()
    assert len(back.faces) == len(mesh.faces)
    assert back.is_watertight and back.volume == pytest.approx(mesh.volume, rel=1e-5)
    assert is_mesh_file(path)


@pytest.mark.parametrize("name", ["ball", "box_minus_ball", "heightfield"])
def test_stl_ply_and_obj_as_pymeshlab_reads_them(tmp_path, name):
    """implc writes STL, PLY and OBJ itself (trimesh took 1.75, 0.52 and 11.8 s for 3 million triangles):
    pymeshlab reads them back as the mesh written (creases, caps on the bounds). PLY: every vertex bit for
    bit, the faces, the normals to float32; OBJ: vertices and normals within 1e-8 relatively, the faces;
    STL, parsed here record by record: each triangle's corners to float32, in order, with its unit normal
    pointing the way the corners wind (outward)."""
    import pymeshlab

    expr, bounds = SURFACES[name]
    mesh = implc.mesh(implc.compile(expr, bounds), 5)
    sets = {}  # each MeshSet kept: its current mesh's matrices live in it
    for suffix in (".ply", ".obj", ".stl"):
        sets[suffix] = pymeshlab.MeshSet()
        sets[suffix].load_new_mesh(str(mesh.save(tmp_path / f"m{suffix}")))
    ply, obj, stl = (sets[suffix].current_mesh() for suffix in (".ply", ".obj", ".stl"))
    assert np.array_equal(ply.vertex_matrix(), mesh.vertices) and np.array_equal(ply.face_matrix(), mesh.faces)
    assert np.array_equal(ply.vertex_normal_matrix(), mesh.normals.astype(np.float32).astype(np.float64))
    scale = np.maximum(np.abs(mesh.vertices), 1e-300)
    assert np.all(np.abs(obj.vertex_matrix() - mesh.vertices) <= 1e-8 * scale)
    assert np.all(np.abs(obj.vertex_normal_matrix() - mesh.normals) <= 1e-8 * np.maximum(np.abs(mesh.normals), 1e-300))
    assert np.array_equal(obj.face_matrix(), mesh.faces)
    assert stl.face_number() == len(mesh.faces)
    data = (tmp_path / "m.stl").read_bytes()
    record = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
    assert not data.startswith(b"solid") and int(np.frombuffer(data[80:84], "<u4")[0]) == len(mesh.faces)
    records = np.frombuffer(data[84:], record)
    corners = mesh.vertices[mesh.faces]
    assert np.array_equal(records["corners"], corners.astype(np.float32))
    winding = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    assert np.allclose(np.linalg.norm(records["normal"], axis=1), 1, atol=1e-6)
    assert np.all(np.einsum("ij,ij->i", records["normal"], winding) > 0)


def test_area_and_volume_as_trimesh_measures_them():
    """Mesh.area and Mesh.volume (summed a chunk of triangles at a time, from the vertices' columns) agree
    with trimesh's to rounding, with chunks of 1000 triangles; a degenerate triangle is counted."""
    import trimesh

    expr, bounds = SURFACES["box_minus_ball"]
    mesh = implc.mesh(implc.compile(expr, bounds), 6)
    assert len(mesh.faces) > 10 * 1000
    other = trimesh.Trimesh(mesh.vertices, mesh.faces, process=False)
    area, volume = mesh.measures(rows=1000)
    assert volume == pytest.approx(other.volume, rel=1e-12) and area == pytest.approx(other.area, rel=1e-12)
    assert (mesh.area, mesh.volume) == pytest.approx((other.area, other.volume), rel=1e-12)
    n = len(mesh.vertices)  # a triangle of three distinct points on a line: zero area, no repeated vertex
    flat = Mesh(np.vstack([mesh.vertices, [[0, 0, 0], [0.125, 0, 0], [0.25, 0, 0]]]),
                np.vstack([mesh.faces, [[n, n + 1, n + 2]]]))
    assert flat.check()["degenerate"] == 1 and mesh.check()["degenerate"] == 0


def test_glb_as_trimesh_and_the_format_read_it(tmp_path):
    """implc writes glTF binary itself: trimesh reads the triangles as written and the positions to float32;
    parsed here by the format's own layout (the header, a JSON chunk, a BIN chunk, each 4-byte aligned),
    its accessors hold the positions (with their bounds), the unit normals and the indices."""
    import json

    import trimesh
    expr, bounds = SURFACES["box_minus_ball"]
    mesh = implc.mesh(implc.compile(expr, bounds), 5)
    path = mesh.save(tmp_path / "m.glb")
    back = trimesh.load(str(path), force="mesh", process=False)
    assert np.array_equal(back.faces, mesh.faces)
    assert np.array_equal(back.vertices, mesh.vertices.astype(np.float32).astype(np.float64))
    data = path.read_bytes()
    magic, version, length = np.frombuffer(data[:12], "<u4")
    assert (magic, version, length) == (0x46546C67, 2, len(data)) and length % 4 == 0
    json_length, json_type = np.frombuffer(data[12:20], "<u4")
    assert json_type == 0x4E4F534A and json_length % 4 == 0
    document = json.loads(data[20:20 + json_length])
    bin_length, bin_type = np.frombuffer(data[20 + json_length:28 + json_length], "<u4")
    assert bin_type == 0x004E4942 and 28 + json_length + bin_length == len(data)
    body = data[28 + json_length:]
    primitive = document["meshes"][0]["primitives"][0]

    def accessor(k, dtype, width):
        a = document["accessors"][k]
        view = document["bufferViews"][a["bufferView"]]
        raw = np.frombuffer(body[view["byteOffset"]:view["byteOffset"] + view["byteLength"]], dtype)
        return a, raw.reshape(-1, width) if width > 1 else raw

    position, positions = accessor(primitive["attributes"]["POSITION"], "<f4", 3)
    assert np.array_equal(positions, mesh.vertices.astype(np.float32))
    assert position["min"] == positions.min(axis=0).tolist() and position["max"] == positions.max(axis=0).tolist()
    _, normals = accessor(primitive["attributes"]["NORMAL"], "<f4", 3)
    assert np.array_equal(normals, mesh.normals.astype(np.float32))
    assert np.allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-6)
    _, indices = accessor(primitive["indices"], "<u4", 1)
    assert primitive["mode"] == 4 and np.array_equal(indices.reshape(-1, 3), mesh.faces)


@pytest.mark.parametrize("name", ["ball", "box_minus_ball"])
def test_3mf_as_lib3mf_reads_it(tmp_path, name):
    """implc writes 3MF itself (trimesh took 10.3 s for 3 million triangles): lib3mf, the 3MF Consortium's
    own library, reads it without a warning, one object in one build item, manifold and oriented by its
    own check, the triangles as written, the vertices to its float32."""
    import lib3mf

    expr, bounds = SURFACES[name]
    mesh = implc.mesh(implc.compile(expr, bounds), 5)
    path = mesh.save(tmp_path / "m.3mf")
    model = lib3mf.get_wrapper().CreateModel()
    reader = model.QueryReader("3mf")
    reader.ReadFromFile(str(path))
    assert reader.GetWarningCount() == 0 and model.GetBuildItems().Count() == 1
    objects = model.GetMeshObjects()
    assert objects.Count() == 1 and objects.MoveNext()
    read = objects.GetCurrentMeshObject()
    assert read.IsManifoldAndOriented()
    vertices = np.array([list(p.Coordinates) for p in read.GetVertices()])
    triangles = np.array([list(t.Indices) for t in read.GetTriangleIndices()])
    assert np.array_equal(triangles, mesh.faces)
    assert np.all(np.abs(vertices - mesh.vertices) <= 1e-7 * np.maximum(np.abs(mesh.vertices), 1e-30))


@hypothesis_settings(max_examples=300, deadline=None)
@given(st.lists(st.floats(allow_nan=False, allow_infinity=False), min_size=1, max_size=50))
def test_obj_numbers_are_within_1e8_of_the_doubles(values):
    """The OBJ writer's numbers (nine significant digits, in 16 characters), read by Python's own float():
    within 1e-8 of each double relatively, zero exactly, subnormals and the largest doubles included."""
    from implc.meshing.formats import _decimals
    text = _decimals(np.array(values))
    assert text.shape == (len(values), 16)
    for value, row in zip(values, text):
        back = float(row.tobytes().decode())
        assert abs(back - value) <= 1e-8 * abs(value), (value, row.tobytes())


def test_obj_numbers_round_as_written():
    from implc.meshing.formats import _decimals
    values = [9.9999999996, 9.999999994, 0.1, -1 / 3, 1e22, 5e-324, 1.7976931348623157e308, -0.0, 123456789012.0]
    assert [row.tobytes().decode() for row in _decimals(np.array(values))] == [
        " 1.00000000e+001", " 9.99999999e+000", " 1.00000000e-001", "-3.33333333e-001", " 1.00000000e+022",
        " 4.94065646e-324", " 1.79769313e+308", " 0.00000000e+000", " 1.23456789e+011"]


def test_the_mesh_command_writes_and_info_describes(tmp_path, capsys):
    out = tmp_path / "t.stl"
    assert main(["mesh", "torus", "--depth", "5", "-o", str(out), "--quiet"]) == 0
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "closed: yes (0 open, 0 non-manifold edges); orientation: consistent; degenerate triangles: 0" in text
    assert main(["mesh", "--expr", "x**2 + y**2 + z**2 - 0.5", "--depth", "4", "-o", str(tmp_path / "b.glb")]) == 0
    assert "triangles" in capsys.readouterr().out


def test_the_mesh_command_refuses_bad_input_in_one_line(tmp_path, capsys):
    assert main(["mesh", "torus", "-o", str(tmp_path / "t.xyz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "unknown output format" in err
    (tmp_path / "bad.stl").write_bytes(b"solid nothing\nendsolid\n")
    assert main(["info", str(tmp_path / "bad.stl")]) == 2
    assert capsys.readouterr().err.count("\n") == 1
    assert not (tmp_path / "t.xyz").exists()


def test_depths_beyond_the_mesher_are_refused_up_front(tmp_path, capsys):
    with pytest.raises(ValueError, match="depth 1 to 14"):
        implc.mesh(implc.compile(x**2 + y**2 + z**2 - 1), 15)
    assert main(["mesh", "torus", "--depth", "15", "-o", str(tmp_path / "t.stl")]) == 2
    assert "--depth must be an integer from 1 to 14" in capsys.readouterr().err
    assert main(["view", str(tmp_path / "t.stl"), "--no-browser"]) == 2
    assert "mesh" in capsys.readouterr().err
    assert not list(tmp_path.iterdir())


def test_a_voxel_point_cloud_ply_is_still_described_as_voxels(tmp_path, capsys):
    expr, bounds = SURFACES["ball"]
    voxel_files.save(implc.voxelize(implc.compile(expr, bounds), 4), tmp_path / "v.ply")
    assert not is_mesh_file(tmp_path / "v.ply")
    assert main(["info", str(tmp_path / "v.ply")]) == 0
    assert "triangle mesh" not in capsys.readouterr().out


@pytest.mark.slow
def test_tetgen_tetrahedralizes_the_meshes(tmp_path):
    """tetgen (as an FEA user would run it, in a subprocess: it can crash on bad input) accepts the meshes
    and fills them with tetrahedra: its -p mode, the constrained Delaunay tetrahedralization of the facets,
    which stops on facets that intersect; csg_part simplified too (its flat faces' long thin triangles).
    Without the quality refinement (-q, the wrapper's default), which is not reliable on angles this small
    (docs/soundness.md): it failed inside on the torus before the vertices' Newton steps, loops on csg_part
    since; neither says anything of the mesh's validity."""
    pytest.importorskip("tetgen")
    for name, simplify in (("csg_part", None), ("paper_blobs", None), ("csg_part", 1e-3 * 2 / 64)):
        sc = load_scene(name)
        mesh = implc.mesh(implc.compile(sc.surface, sc.bounds), 6, simplify=simplify)
        np.savez(tmp_path / f"{name}.npz", v=mesh.vertices, f=mesh.faces)
        script = ("import sys, numpy as np, tetgen\n"
                  "d = np.load(sys.argv[1])\n"
                  "t = tetgen.TetGen(d['v'], d['f'].astype(np.int32))\n"
                  "nodes, elems = t.tetrahedralize(quality=False)[:2]\n"
                  "print(len(elems))\n")
        run = subprocess.run([sys.executable, "-c", script, str(tmp_path / f"{name}.npz")], capture_output=True,
                             text=True, timeout=300)
        assert run.returncode == 0, run.stderr[-2000:]
        assert int(run.stdout.split()[-1]) > len(mesh.faces) // 4


@pytest.mark.parametrize("engine", ["jit", "tape"])
def test_cells_proven_regular_hold_a_graph_and_a_singular_point_stays_unproven(engine):
    """MeshStats' proof: in every cell counted regular F has at most one zero on each line along some axis
    (F = 0 there is a graph over a face), at a dense sample of lines (F through numpy, not implc's
    compiler), and the cell holding the apex of a double cone (a singular point of F = 0) is counted
    unproven, with the cells of a crease."""
    cone = sympy.Min(x**2 + y**2 - (z - sympy.Rational(1, 5))**2, sympy.Abs(y + sympy.Rational(1, 2)) - 0.3)
    surface = implc.compile(cone, ((-1, 1),) * 3, engine=engine)
    depth = 5
    m = implc.mesh(surface, depth)
    stats = m.stats
    assert stats.regular_cells + stats.unproven_cells == stats.crossed_cells
    assert len(m.unproven_cells) == stats.unproven_cells
    unproven = {tuple(c) for c in m.unproven_cells.tolist()}
    n = 1 << depth
    apex_cells = {(i, j, 19) for i in (15, 16) for j in (15, 16)}  # the apex (0, 0, 0.2) is their corner
    assert apex_cells <= unproven, "a cell at the cone's apex counted regular"
    crossed = _crossed_cells(_tetrahedral(surface, depth), n)
    regular = np.array([c for c in crossed if c not in unproven])
    assert len(regular) == stats.regular_cells
    graph = _graph_along_some_direction(numpy_f(cone), regular, np.full(3, -1.0), np.full(3, 2 / n))
    bubble = numpy_f((x + 1 / 32)**2 + (y + 1 / 32)**2 + (z + 1 / 32)**2 - 0.02**2)  # inside cell (15, 15, 15)
    assert not _graph_along_some_direction(bubble, np.array([[15, 15, 15]]), np.full(3, -1.0), np.full(3, 2 / n))[0]
    bad = regular[~graph]
    assert not len(bad), f"cells {bad[:5].tolist()} counted regular but F has two zeros on a line along each axis"


_DIRECTIONS = np.concatenate([np.eye(3), DIAGONALS])
"""The directions the proof of regular cells tries: the axes, then the face and body diagonals."""


def _graph_along_some_direction(f, cells, lo, step, lines: int = 4, samples: int = 49) -> np.ndarray:
    """For each cell ((k, 3) grid indices of the grid lo + i·step): whether, along one of the
    :data:`_DIRECTIONS`, every line across the cell through a point of a ``lines``³ lattice in it has at
    most one change of F's sign among ``samples`` points (a zero sample takes the sign before it), the
    line clipped to the cell. ``f``: F on (N, 3) points, not through implc."""
    g = (np.arange(lines) + 0.5) / lines
    through = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)  # in the cell, [0, 1]³
    ok = np.zeros(len(cells), bool)
    for direction in _DIRECTIONS:
        todo = np.flatnonzero(~ok)  # the cells no direction has shown a graph along yet
        if not len(todo):
            break
        u = direction / step  # the world direction in cell units
        with np.errstate(divide="ignore", invalid="ignore"):
            t0, t1 = -through / u, (1 - through) / u
        t_lo = np.max(np.where(u != 0, np.minimum(t0, t1), -np.inf), axis=1)
        t_hi = np.min(np.where(u != 0, np.maximum(t0, t1), np.inf), axis=1)
        t = t_lo[:, None] + (t_hi - t_lo)[:, None] * np.linspace(0, 1, samples)[None]
        offsets = through[:, None, :] + t[..., None] * u  # (lines³, samples, 3), in the cell
        p = lo + (cells[todo, None, None, :] + offsets[None]) * step
        signs = np.sign(np.broadcast_to(f(p.reshape(-1, 3)), (p.size // 3,)))
        signs = signs.reshape(len(todo), len(through), samples)
        held = signs[..., 0].copy()
        changes = np.zeros(held.shape, int)
        for k in range(1, samples):
            now = signs[..., k]
            changes += (now != 0) & (held != 0) & (now != held)
            held = np.where(now != 0, now, held)
        ok[todo] = np.all(changes <= 1, axis=1)
    return ok


def test_a_boxs_edges_and_corners_are_proven_regular_by_the_diagonals():
    """On the tape engine a box's crease cells are proven regular by F's derivatives along the cell's face
    and body diagonals (both sides of an edge rise along one, the three faces of a corner along a body
    diagonal), where every partial's hull straddles 0 (the compiled kernels, which seek the partials
    alone, leave them open); every crossed cell then holds at most one zero on each line along one of the
    13 directions (F through numpy, not implc's compiler)."""
    box = sympy.Max(sympy.Abs(x) - 0.43, sympy.Abs(y) - 0.37, sympy.Abs(z) - 0.29)
    depth, n = 5, 32
    tape = implc.mesh(implc.compile(box, engine="tape"), depth)
    jit = implc.mesh(implc.compile(box, engine="jit"), depth)
    assert tape.stats.crossed_cells == jit.stats.crossed_cells
    assert jit.stats.unproven_cells >= 100, "the case the test is for: creases the partials leave open"
    assert tape.stats.unproven_cells == 0
    crossed = np.array(sorted(_crossed_cells(_tetrahedral(implc.compile(box, engine="tape"), depth), n)))
    graph = _graph_along_some_direction(numpy_f(box), crossed, np.full(3, -1.0), np.full(3, 2 / n))
    assert graph.all(), crossed[~graph][:5].tolist()


def test_a_smooth_f_is_fanned_only_where_its_gradient_may_vanish():
    """Feature cells (fanned from QEF points) keep creases, which a smooth F (no Min, Max, abs or select)
    has only where its gradient vanishes: the torus's bent cells at 32³ are all proven regular and split
    the Kuhn way (written with a Max that never wins they are fanned: the case the rule is for), while the
    double cone's apex cells, unproven, are fanned and put a vertex nearer the apex than the Kuhn split
    does; every mesh stays closed and manifold."""
    torus = (sympy.sqrt(x**2 + y**2) - 0.5)**2 + z**2 - 0.15**2
    smooth, kinked = implc.compile(torus), implc.compile(sympy.Max(torus, z - 5))
    assert not smooth.has_kinks and kinked.has_kinks
    plain, fanned = _tetrahedral(smooth, 5), _tetrahedral(kinked, 5)
    assert fanned.stats.feature_cells > 100 and plain.stats.feature_cells == 0
    assert plain.stats.unproven_cells == 0
    cone = x**2 + y**2 - (z - sympy.Rational(1, 5))**2
    s = implc.compile(cone)
    sharp, chamfered = _tetrahedral(s, 5), _tetrahedral(s, 5, features=False)
    assert 0 < sharp.stats.feature_cells <= sharp.stats.unproven_cells
    apex = np.array([0, 0, 0.2])
    nearest = [np.min(np.linalg.norm(m.vertices - apex, axis=1)) / (2 / 32) for m in (sharp, chamfered)]
    assert nearest[0] < 0.1 < nearest[1], nearest
    for m in (plain, fanned, sharp):
        check = m.check()
        assert check["open_edges"] == check["overused_edges"] == check["degenerate"] == 0, check


def _tetrahedral(surface, depth, **options):
    """The mesh of the tetrahedral construction everywhere (no dual cells): each triangle in one cell."""
    voxels = implc.voxelize(surface, depth, **implc.NATURAL)
    return contour(surface, voxels.coords, depth, voxels.bounds, lean=False, **options)


def _crossed_cells_in(mesh, lo, step):
    """:func:`_crossed_cells` on the grid lo + i·step (the caps are on the bounds)."""
    centroids = mesh.vertices[mesh.faces].mean(1)
    bounds = np.array(mesh.bounds)
    on_bounds = np.any((centroids == bounds[:, 0]) | (centroids == bounds[:, 1]), axis=1)
    return {tuple(c) for c in np.floor((centroids[~on_bounds] - lo) / step).astype(int).tolist()}


def _crossed_cells(mesh, n):
    """The cells holding a triangle's centroid, but the caps' (on the bounds' faces): each other triangle lies
    in its cell's tetrahedron with a vertex off every face of the cell, so its centroid is inside the cell."""
    centroids = mesh.vertices[mesh.faces].mean(1)
    on_bounds = np.any(np.abs(centroids) == 1, axis=1)
    return {tuple(c) for c in np.floor((centroids[~on_bounds] + 1) / 2 * n).astype(int).tolist()}


def test_the_proof_looks_below_the_grid_where_a_cells_enclosures_are_too_wide():
    """Two levels of sub-boxes below the grid prove cells that their own enclosures leave open (Scene 1 at
    16³: 336 unproven without them, 48 with them), and in each cell they add F has at most one zero on
    each line along some axis, at a dense sample of lines (F through numpy, not implc's compiler)."""
    from implc.meshing.grid import Effort
    sc = load_scene("paper_blobs")
    surface = implc.compile(sc.surface, sc.bounds)
    depth, n = 4, 16
    voxels = implc.voxelize(surface, depth, **implc.NATURAL)
    coarse = contour(surface, voxels.coords, depth, voxels.bounds, effort=Effort(proof_levels=0))
    fine = implc.mesh(surface, depth)
    assert np.array_equal(coarse.faces, fine.faces) and coarse.stats.crossed_cells == fine.stats.crossed_cells
    before = {tuple(c) for c in coarse.unproven_cells.tolist()}
    after = {tuple(c) for c in fine.unproven_cells.tolist()}
    assert after < before and len(after) <= 0.6 * len(before), (len(after), len(before))
    added = np.array(sorted(before - after))
    lo = np.array([b[0] for b in sc.bounds], float)
    step = (np.array([b[1] for b in sc.bounds], float) - lo) / n
    graph = _graph_along_some_direction(numpy_f(cartesian_form(sc.surface)), added, lo, step)
    assert graph.all(), f"cells {added[~graph][:5].tolist()} proven regular, but F has two zeros on a line each way"


@pytest.mark.parametrize("engine", ["jit", "tape"])
def test_a_partial_needs_its_sign_only_where_the_surface_may_be(engine):
    """In the cell [0, 1]³ of F = (z - 0.2)(1.6 - z) + ((x - 0.5)² + (y - 0.5)²)/10 every partial changes
    sign (sampled through numpy), yet the cell is proven regular: over its lower half ∂F/∂z > 0, and over
    its upper half F > 0, so the surface there is a graph over the xy face (checked on lines along z)."""
    expr = (z - 0.2) * (1.6 - z) + ((x - 0.5) ** 2 + (y - 0.5) ** 2) / 10
    m = _tetrahedral(implc.compile(expr, ((0, 4),) * 3, engine=engine), 2)
    cell = np.array([[0, 0, 0]])
    assert (0, 0, 0) in _crossed_cells_in(m, np.zeros(3), np.ones(3))
    g = np.linspace(0, 1, 11)
    p = np.stack(np.meshgrid(g, g, g, indexing="ij"), -1).reshape(-1, 3)
    for v in (x, y, z):
        d = np.broadcast_to(sympy.lambdify((x, y, z), sympy.diff(expr, v), "numpy")(*p.T), (len(p),))
        assert d.min() < 0 < d.max(), f"the partial along {v} keeps its sign in the cell"
    assert not any((c == cell[0]).all() for c in m.unproven_cells), "the cell counted unproven"
    assert _graph_along_some_direction(numpy_f(expr), cell, np.zeros(3), np.ones(3)).all()



def test_the_proof_below_the_grid_tries_a_sample_first():
    """The first level below the grid, given many cells, is tried on every ``proof_sample``-th first: where
    the sample gains enough the others follow and the proof is the one without a sample (each box's
    enclosures are its own); where it does not (here forced), only the sample's cells can be added."""
    from implc.meshing.grid import Effort
    sc = load_scene("paper_blobs")
    surface = implc.compile(sc.surface, sc.bounds)
    voxels = implc.voxelize(surface, 4)
    unproven = {}
    for name, effort in {"whole": Effort(proof_sample_min=10**9), "sampled": Effort(proof_sample_min=1),
                         "sample only": Effort(proof_sample_min=1, proof_yield=1.5),
                         "none": Effort(proof_levels=0)}.items():
        mesh = contour(surface, voxels.coords, voxels.depth, voxels.bounds, effort=effort)
        unproven[name] = {tuple(c) for c in mesh.unproven_cells.tolist()}
    assert unproven["sampled"] == unproven["whole"] < unproven["none"]
    assert unproven["whole"] < unproven["sample only"] < unproven["none"]
    gained = len(unproven["none"]) - len(unproven["sample only"])
    assert gained <= len(unproven["none"]) / Effort().proof_sample + 1


# -- random surfaces ------------------------------------------------------------------------------------
def random_surface(rng):
    """A random CSG surface: spheres, boxes, tori, cylinders, cones, blobs, planes (some through grid
    corners, some on grid planes), tangent spheres and slabs, joined by Min, Max and differences."""
    def ratio(lo, hi):
        return sympy.Rational(rng.randint(int(lo * 100), int(hi * 100)), 100)

    def primitive():
        c = [ratio(-0.8, 0.8) for _ in range(3)]
        v, g = rng.choice([x, y, z]), sympy.Rational(rng.randint(-8, 8), 16)
        kind = rng.randrange(11)
        if kind == 0:
            return (x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2 - ratio(0.05, 0.6) ** 2
        if kind == 1:
            return sympy.Max(*(sympy.Abs(u - w) - ratio(0.05, 0.6) for u, w in zip((x, y, z), c)))
        if kind == 2:
            ring = sympy.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2) - ratio(0.2, 0.5)
            return ring**2 + (z - c[2]) ** 2 - ratio(0.02, 0.15) ** 2
        if kind == 3:
            return ratio(-1, 1) * x + ratio(-1, 1) * y + ratio(-1, 1) * z + ratio(-0.5, 0.5)
        if kind == 4:
            disc = (x - c[0]) ** 2 + (y - c[1]) ** 2 - ratio(0.05, 0.4) ** 2
            return sympy.Max(disc, sympy.Abs(z - c[2]) - ratio(0.1, 0.7))
        if kind == 5:
            return ratio(0.1, 0.9) - sympy.exp(-ratio(2, 20) * ((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2))
        if kind == 6:
            return (v - g) * rng.choice([1, -1])
        if kind == 7:
            return (x - c[0]) ** 2 + (y - c[1]) ** 2 - (z - c[2]) ** 2 * ratio(0.2, 2)
        if kind == 8:
            return sympy.Min((x - g) ** 2 + y**2 + z**2 - sympy.Rational(1, 16),
                             (x - g - sympy.Rational(1, 2)) ** 2 + y**2 + z**2 - sympy.Rational(1, 16))
        if kind == 9:
            return sympy.Abs(v - g) - sympy.Rational(rng.randint(0, 4), 64)
        return sympy.Max(sympy.Abs(x - g) - sympy.Rational(rng.randint(1, 8), 16),
                         sympy.Abs(y) - sympy.Rational(rng.randint(1, 8), 16),
                         sympy.Abs(z + g) - sympy.Rational(rng.randint(1, 8), 16))

    def tree(level=0):
        if level >= 2 or rng.random() < 0.3:
            return primitive()
        a, b = tree(level + 1), tree(level + 1)
        return rng.choice([sympy.Min(a, b), sympy.Max(a, b), sympy.Max(a, -b)])

    if rng.random() < 0.5:
        bounds = ((-1.0, 1.0),) * 3
    else:
        bounds = tuple((float(ratio(-1.2, -0.3)), float(ratio(0.3, 1.2))) for _ in range(3))
    return tree(), bounds


@pytest.mark.slow
# derandomized: the same 40 surfaces every run, so that a red run is a bug, never the draw (the harness it
# comes from ran 1,500 random ones; to explore, run the body over other seeds)
@hypothesis_settings(max_examples=40, deadline=None, derandomize=True,
                     suppress_health_check=[HealthCheck.too_slow])
@given(seed=st.integers(0, 2**32 - 1), engine=st.sampled_from(["jit", "tape"]), depth=st.sampled_from([4, 5, 6]))
def test_fuzz_random_csg_meshes(seed, engine, depth):
    """Random CSG surfaces over random bounds keep every promise: closed, oriented, manifold, no two faces
    meeting (pymeshlab's candidates tested exactly), every vertex in a kept cell with witnesses that bracket
    a zero of F (exactly, where numpy's F lies within 1e-9 of 0: it rounds where F is exactly 0 at grid
    corners), the exact volume within volume_bounds()."""
    import random

    expr, bounds = random_surface(random.Random(seed))
    surface = implc.compile(expr, bounds, engine=engine)
    voxels = implc.voxelize(surface, depth, solid=True)
    mesh = voxels.mesh(witnesses=True)
    if not len(mesh.faces):
        return  # nothing inside the bounds: the empty mesh (tested elsewhere)
    assert_closed_manifold(mesh)
    assert_on_witness_edges_in_kept_cells(mesh, bounds, depth, voxels.coords)
    assert_volume_within(mesh, *voxels.volume_bounds())
    assert mesh.stats.added_cells == 0
    f = numpy_f(expr)

    def sign(p, value):
        if abs(value) > 1e-9:
            return np.sign(value)
        exact = sympy.N(expr.subs({x: sympy.Rational(p[0]), y: sympy.Rational(p[1]), z: sympy.Rational(p[2])}), 60)
        return 0 if abs(exact) < 1e-50 else (1 if exact > 0 else -1)  # 60 digits: 0 where F is exactly 0

    w = mesh.witnesses
    fa, fb = f(w[:, 0]), f(w[:, 1])
    itself = np.all(w[:, 0] == w[:, 1], axis=1)
    for i in np.flatnonzero(~((fa < 0) & (itself | (fb >= 0)))):
        assert sign(w[i, 0], fa[i]) <= 0 and (itself[i] or sign(w[i, 1], fb[i]) >= 0), (seed, w[i])
