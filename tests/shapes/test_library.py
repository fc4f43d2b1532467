"""The modelling library keeps its promises: the shapes that say they are exact distances equal the distance
to their surface at sampled points (the truth computed here by nearest points in numpy, not through implc),
with |∇F| = 1 by implc's analytic gradient; every shape, and compositions of them, voxelize without a cell
missed against numpy's sampling of the SymPy expression (not implc's compiler); every function says in its
docstring what F is."""

import inspect

import numpy as np
import pytest
import sympy

import implc
from implc import shapes, x, y, z

from ..support.truth import corner_sign_changes

RNG = np.random.default_rng(5)
POINTS = RNG.uniform(-1.5, 1.5, (4000, 3))


def _box_distance(p, h):
    q = np.abs(p) - h
    return np.linalg.norm(np.maximum(q, 0), axis=1) + np.minimum(q.max(axis=1), 0)


def _segment_distance(p, a, b):
    d = b - a
    t = np.clip(((p - a) @ d) / (d @ d), 0, 1)
    return np.linalg.norm(p - (a + t[:, None] * d), axis=1)


def _torus_distance(p, major, minor):
    radial = np.hypot(p[:, 0], p[:, 1])
    return np.hypot(radial - major, p[:, 2]) - minor


def _cylinder_distance(p, r, half):
    radial = np.hypot(p[:, 0], p[:, 1])
    w = np.stack([radial - r, np.abs(p[:, 2]) - half], axis=1)
    return np.linalg.norm(np.maximum(w, 0), axis=1) + np.minimum(w.max(axis=1), 0)


EXACT = {  # name: (expression, the true signed distance at points p by nearest points in numpy)
    "sphere": (shapes.sphere(0.8), lambda p: np.linalg.norm(p, axis=1) - 0.8),
    "box_exact": (shapes.box_exact((0.5, 0.7, 0.3)), lambda p: _box_distance(p, np.array([0.5, 0.7, 0.3]))),
    "rounded_box": (shapes.rounded_box((0.6, 0.5, 0.4), 0.15),
                    lambda p: _box_distance(p, np.array([0.45, 0.35, 0.25])) - 0.15),
    "torus_exact": (shapes.torus_exact(0.7, 0.2), lambda p: _torus_distance(p, 0.7, 0.2)),
    "capsule": (shapes.capsule((-0.5, 0.1, 0), (0.6, -0.2, 0.3), 0.25),
                lambda p: _segment_distance(p, np.array([-0.5, 0.1, 0]), np.array([0.6, -0.2, 0.3])) - 0.25),
    "capped_cylinder": (shapes.capped_cylinder(0.5, 1.2), lambda p: _cylinder_distance(p, 0.5, 0.6)),
    "extruded circle": (shapes.extrude(shapes.circle(0.5), 1.2), lambda p: _cylinder_distance(p, 0.5, 0.6)),
    "revolved circle": (shapes.revolve(shapes.circle(0.2), 0.7), lambda p: _torus_distance(p, 0.7, 0.2)),
    "extruded rectangle": (shapes.extrude(shapes.rectangle((0.5, 0.7)), 0.6),
                           lambda p: _box_distance(p, np.array([0.5, 0.7, 0.3]))),
    "elongated sphere": (shapes.elongate(shapes.sphere(0.25), (0, 0, 0.5)),
                         lambda p: _segment_distance(p, np.array([0, 0, -0.5]), np.array([0, 0, 0.5])) - 0.25),
    "shell of a sphere": (shapes.shell(shapes.sphere(0.8), 0.2),
                          lambda p: np.abs(np.linalg.norm(p, axis=1) - 0.8) - 0.1),
    "half_space": (shapes.half_space((1, 2, 2), 0.3), lambda p: p @ np.array([1, 2, 2]) / 3 - 0.3),
    "slab": (shapes.slab((0, 0, 1), 0.4, 0.1), lambda p: np.abs(p[:, 2] - 0.1) - 0.2),
    "rotated box": (shapes.rotate(shapes.box_exact((0.5, 0.7, 0.3)), 0.4, (1, 1, 0)), None),
}


EXACT_DEFAULT = {"box_exact", "rounded_box", "capsule", "revolved circle", "elongated sphere", "rotated box"}
"""Exact shapes checked in the default run (a primitive, a derived shape, a transform); the rest in the slow set."""


@pytest.mark.parametrize("name", [n if n in EXACT_DEFAULT else pytest.param(n, marks=pytest.mark.slow)
                                  for n in sorted(EXACT)])
def test_exact_shapes_are_the_distance_and_their_gradient_is_a_unit(name):
    expr, truth = EXACT[name]
    surface = implc.compile(expr, ((-1.5, 1.5),) * 3)
    f = surface.eval(POINTS)
    if truth is None:  # a rigid motion of an exact shape: the box's distance at the points rotated back
        axis = np.array([1, 1, 0]) / np.sqrt(2)
        c, s = np.cos(-0.4), np.sin(-0.4)
        back = POINTS * c + np.cross(axis, POINTS) * s + np.outer(POINTS @ axis, axis) * (1 - c)
        truth = _box_distance(back, np.array([0.5, 0.7, 0.3]))
    else:
        truth = truth(POINTS)
    np.testing.assert_allclose(f, truth, atol=1e-12, rtol=0)
    gradient = surface.gradient(POINTS)
    norms = np.linalg.norm(gradient, axis=1)
    usable = np.isfinite(norms)
    assert usable.mean() > 0.95
    # |∇F| = 1 where F is differentiable: everywhere but the measure-zero medial sets, which random points miss
    np.testing.assert_allclose(norms[usable], 1, atol=1e-9)


def _numpy_sign_cells(expr, bounds, depth):
    """Cells whose corners' F, by numpy through sympy.lambdify (not implc's compiler), change sign."""
    f = sympy.lambdify((x, y, z), expr, modules="numpy")
    n = 1 << depth
    axes = [np.linspace(lo, hi, n + 1) for lo, hi in bounds]
    grid = np.meshgrid(*axes, indexing="ij")
    with np.errstate(all="ignore"):
        values = np.broadcast_to(np.asarray(f(*grid), dtype=np.float64), grid[0].shape)
    return corner_sign_changes(values)


R = sympy.Rational
SHAPES = {
    **{name: expr for name, (expr, _) in EXACT.items()},
    "box": shapes.box((0.5, 0.4, 0.3)), "torus": shapes.torus(0.7, 0.2), "cylinder": shapes.cylinder(0.4, 1),
    "cone": shapes.cone(0.6, 1.2), "ellipsoid": shapes.ellipsoid((0.9, 0.5, 0.3)),
    "pyramid": shapes.pyramid(0.7, 1), "tetrahedron": shapes.tetrahedron(0.4), "octahedron": shapes.octahedron(0.6),
    "dodecahedron": shapes.dodecahedron(0.7), "icosahedron": shapes.icosahedron(0.7),
    "regular_polygon extruded": shapes.extrude(shapes.regular_polygon(6, 0.8), 0.5),
    "triangle extruded": shapes.extrude(shapes.triangle((0, 0), (0.9, 0.1), (0.2, 0.8)), 0.3),
    "ring extruded": shapes.extrude(shapes.ring(0.7, 0.2), 0.3),
    "rounded_rectangle extruded": shapes.extrude(shapes.rounded_rectangle((0.8, 0.5), 0.2), 0.4),
    "loft": shapes.loft(shapes.circle(0.8), shapes.rectangle((0.3, 0.3)), -0.8, 0.8),
    "smooth_union": shapes.smooth_union(R(1, 5), shapes.sphere(0.5, (-0.4, 0, 0)), shapes.sphere(0.5, (0.4, 0, 0))),
    "smooth_difference": shapes.smooth_difference(R(1, 10), shapes.box_exact((0.8, 0.8, 0.8)), shapes.sphere(0.95)),
    "smooth_intersection": shapes.smooth_intersection(R(1, 5), shapes.sphere(1), shapes.box_exact((0.7, 0.7, 0.7))),
    "chamfer_union": shapes.chamfer_union(R(1, 5), shapes.box_exact((0.8, 0.2, 0.2)),
                                          shapes.box_exact((0.2, 0.8, 0.2))),
    "chamfer_difference": shapes.chamfer_difference(R(1, 10), shapes.box_exact((0.8, 0.8, 0.8)),
                                                    shapes.capped_cylinder(0.4, 2)),
    "morph": shapes.morph(shapes.sphere(0.8), shapes.box_exact((0.6, 0.6, 0.6)), R(1, 2)),
    "clearance": shapes.clearance(shapes.box_exact((0.9, 0.9, 0.3)), shapes.capped_cylinder(0.3, 1), R(1, 10)),
    "inner_shell": shapes.inner_shell(shapes.sphere(0.9), R(1, 5)),
    "twist": shapes.twist(shapes.box_exact((0.6, 0.2, 0.9)), 1.5),
    "bend": shapes.bend(shapes.box_exact((0.1, 0.3, 0.9)), 0.8),
    "taper": shapes.taper(shapes.capped_cylinder(0.5, 1.6), -0.4),
    "shear": shapes.shear(shapes.box_exact((0.3, 0.3, 0.8)), 0.5, 0.2),
    "array_linear": shapes.array_linear(shapes.sphere(0.2, (-0.9, 0, 0)), 5, (0.45, 0, 0)),
    "array_grid": shapes.array_grid(shapes.box_exact((0.1, 0.1, 0.1), (-0.6, -0.6, -0.6)), (3, 3, 3), (0.6, 0.6, 0.6)),
    "array_polar": shapes.array_polar(shapes.capped_cylinder(0.1, 0.4, (0.7, 0, 0)), 7),
    "mirror": shapes.mirror(shapes.cone(0.5, 1, (0.3, 0, 0)), "x"),
    "symmetric": shapes.symmetric(shapes.sphere(0.3, (0.5, 0.2, 0)), "x"),
    "transform": shapes.transform(shapes.box_exact((0.5, 0.3, 0.2)),
                                  [[0, -1, 0, 0.1], [1, 0, 0, 0], [0, 0, 2, 0], [0, 0, 0, 1]]),
    "gyroid": shapes.gyroid(1, R(3, 10)), "schwarz_p": shapes.schwarz_p(1, R(3, 10)),
    "diamond": shapes.diamond(1, R(3, 10)), "neovius": shapes.neovius(1, 1),
    "infill": shapes.infill(shapes.sphere(1.2), shapes.gyroid(R(1, 2), R(1, 4)), R(1, 10)),
    "blobs": shapes.blobs([(-0.3, 0, 0), (0.3, 0.1, 0)], R(1, 2), R(1, 4)),
}


DEFAULT_RUN = {"box_exact", "capsule", "cone", "dodecahedron", "triangle extruded", "loft", "smooth_union",
               "chamfer_difference", "twist", "array_polar", "transform", "gyroid", "infill"}
"""One shape of each group runs by default; the sweep over the rest is in the slow set."""


@pytest.mark.parametrize("name", [n if n in DEFAULT_RUN else pytest.param(n, marks=pytest.mark.slow)
                                  for n in sorted(SHAPES)])
def test_no_cell_is_missed_against_sampling(name):
    bounds = ((-1.5, 1.5),) * 3
    expr = SHAPES[name]
    depth = 5
    expected = _numpy_sign_cells(expr, bounds, depth)
    voxels = implc.voxelize(implc.compile(expr, bounds), depth)
    kept = np.zeros((1 << depth,) * 3, bool)
    kept[tuple(voxels.coords.astype(np.int64).T)] = True
    missed = expected & ~kept
    assert expected.any() and not missed.any(), f"{int(missed.sum())} of {int(expected.sum())} cells missed"


@pytest.mark.slow  # six compositions voxelized and sampled
def test_random_compositions_miss_no_cell():
    rng = np.random.default_rng(11)
    leaves = [lambda: shapes.sphere(R(int(rng.integers(2, 8)), 10),
                                    tuple(R(int(v), 10) for v in rng.integers(-5, 6, 3))),
              lambda: shapes.rounded_box(tuple(R(int(v), 10) for v in rng.integers(3, 8, 3)), R(1, 10)),
              lambda: shapes.capsule((-0.5, 0, 0), (0.5, R(int(rng.integers(-3, 4)), 10), 0), R(1, 5)),
              lambda: shapes.torus_exact(R(3, 5), R(1, 6))]
    ops = [lambda a, b: shapes.union(a, b), lambda a, b: shapes.difference(a, b),
           lambda a, b: shapes.smooth_union(R(1, 5), a, b), lambda a, b: shapes.chamfer_intersection(R(1, 10), a, b),
           lambda a, b: shapes.shell(shapes.union(a, b), R(1, 10))]
    for _ in range(6):
        expr = leaves[int(rng.integers(len(leaves)))]()
        for _ in range(3):
            expr = ops[int(rng.integers(len(ops)))](expr, leaves[int(rng.integers(len(leaves)))]())
        expected = _numpy_sign_cells(expr, ((-1.5, 1.5),) * 3, 5)
        voxels = implc.voxelize(implc.compile(expr, ((-1.5, 1.5),) * 3), 5)
        kept = np.zeros((32,) * 3, bool)
        kept[tuple(voxels.coords.astype(np.int64).T)] = True
        assert not (expected & ~kept).any(), str(expr)[:200]


def test_every_function_says_what_it_promises():
    for name in shapes.__all__:
        member = getattr(shapes, name)
        if inspect.isfunction(member):
            assert member.__doc__ and len(member.__doc__.split()) >= 5, name


def test_bad_arguments_are_one_clear_error():
    for call, words in ((lambda: shapes.rounded_box((0.1, 1, 1), 0.2), "below every half size"),
                        (lambda: shapes.capsule((0, 0, 0), (1, 0, 0), -1), "above 0"),
                        (lambda: shapes.regular_polygon(2), "at least 3"),
                        (lambda: shapes.array_linear(shapes.sphere(1), 10**6, (1, 0, 0)), "count must be"),
                        (lambda: shapes.transform(x, [[1, 0], [0, 1]]), "4×4"),
                        (lambda: shapes.rotate(x, 1, (0, 0, 0)), "must not be zero")):
        with pytest.raises(ValueError, match=words):
            call()
