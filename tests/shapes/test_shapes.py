"""Shape helpers return SymPy expressions with the promised values and signs."""

import numpy as np
import pytest
import sympy

import implc
from implc import shapes, x, y, z


def at(expr, *p):
    return float(expr.subs({x: p[0], y: p[1], z: p[2]}))


def test_primitives_have_the_right_sign():
    assert at(shapes.sphere(1), 0, 0, 0) == -1
    assert at(shapes.sphere(1, (1, 0, 0)), 3, 0, 0) == pytest.approx(1)
    assert at(shapes.box((1, 2, 3)), 0, 0, 0) == -1
    assert at(shapes.box((1, 2, 3)), 0, 2.5, 0) == pytest.approx(0.5)
    assert at(shapes.torus(1, 0.25), 1, 0, 0) < 0 < at(shapes.torus(1, 0.25), 0, 0, 0)
    assert at(shapes.cylinder(1, 2), 0, 0, 0.5) < 0 < at(shapes.cylinder(1, 2), 0, 0, 1.5)


def test_blend_is_the_papers_polynomial():
    R = sympy.Rational(1, 2)
    g = shapes.blend(x**2, R)
    for d in (0, 0.1, 0.3, 0.49):
        assert float(g.subs(x, d)) == pytest.approx((d**2 - 0.25) ** 4 / 0.25**4)
    assert float(g.subs(x, 0.6)) == 0
    assert float(g.subs(x, 0)) == 1


def test_blobs_field_and_weights():
    f = shapes.blobs([(0, 0, 0), (2, 0, 0)], radius=1, threshold=sympy.Rational(1, 2), weights=[1, 2])
    assert at(f, 0, 0, 0) == pytest.approx(0.5 - 1)
    assert at(f, 2, 0, 0) == pytest.approx(0.5 - 2)
    assert at(f, 1, 0, 0) == pytest.approx(0.5)  # both blobs vanish at distance R
    with pytest.raises(ValueError, match="weights"):
        shapes.blobs([(0, 0, 0)], 1, 0.5, weights=[1, 2])
    with pytest.raises(ValueError, match="at least one"):
        shapes.blobs([], 1, 0.5)


def test_csg_and_transforms():
    a, b = shapes.sphere(1), shapes.sphere(1, (1, 0, 0))
    p = (-0.5, 0, 0)  # inside a only
    assert at(shapes.union(a, b), *p) < 0
    assert at(shapes.intersection(a, b), *p) > 0
    assert at(shapes.difference(a, b), *p) < 0
    assert at(shapes.difference(b, a), *p) > 0
    moved = shapes.translate(shapes.sphere(1), (5, 0, 0))
    assert at(moved, 5, 0, 0) == -1
    turned = shapes.rotate(shapes.box((2, 0.5, 0.5)), sympy.pi / 2, "z")
    assert at(turned, 0, 1.5, 0) < 0 < at(turned, 1.5, 0, 0)
    big = shapes.scale(shapes.sphere(1), 2)
    assert at(big, 1.5, 0, 0) < 0
    with pytest.raises(ValueError, match="axis"):
        shapes.rotate(a, 1, "w")


def test_spherical_shapes_translate_through_cartesian_form():
    moved = shapes.translate(implc.r - 1, (2, 0, 0))
    assert at(moved, 2, 0, 0) == -1


def test_shapes_compile():
    f = shapes.union(shapes.torus(), shapes.difference(shapes.box(), shapes.sphere(1.2)))
    s = implc.compile(f, bounds=((-2, 2),) * 3)
    pts = np.random.default_rng(0).uniform(-2, 2, (50, 3))
    expected = [at(f, *p) for p in pts]
    np.testing.assert_allclose(s.eval(pts), expected, rtol=1e-12, atol=1e-12)
