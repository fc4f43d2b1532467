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


def test_substitution_equals_sympys_and_survives_a_deep_part():
    """The builders' substitution (Min/Max/Abs kept as built) has SymPy's own xreplace's values, and a
    part nested thousands of operations deep transforms without exhausting Python's stack."""
    from implc.shapes.vectors import substitute
    rng = np.random.default_rng(7)
    part = shapes.difference(shapes.smooth_union(0.1, shapes.sphere(0.5), shapes.box((0.3, 0.6, 0.2))),
                             shapes.capsule((0, 0, -1), (0, 0, 1), 0.1))
    mapping = {x: 0.8 * x - 0.6 * y + 0.1, y: 0.6 * x + 0.8 * y, z: sympy.Abs(z) - 0.2}
    ours = sympy.lambdify((x, y, z), substitute(part, mapping), "numpy")
    theirs = sympy.lambdify((x, y, z), part.xreplace(mapping), "numpy")
    p = rng.uniform(-1, 1, (3, 500))
    np.testing.assert_array_equal(ours(*p), theirs(*p))
    chain = shapes.sphere(1)
    for k in range(500):  # 500 smooth unions deep (each node several levels), each sharing its operands
        chain = shapes.smooth_union(0.01, chain, shapes.sphere(0.1, (k / 500, 0, 0)))
    moved = shapes.translate(chain, (0, 0, 1))
    p = rng.uniform(-1, 1, (8, 3))
    np.testing.assert_allclose(implc.compile(moved, ((-1, 1), (-1, 1), (0, 2))).eval(p + [0, 0, 1]),
                               implc.compile(chain).eval(p), rtol=0, atol=1e-12)


def test_a_size_that_is_a_number_must_be_above_zero():
    """A negative or zero radius is a mistake (an empty solid), refused in one line; a size that varies over
    space (an expression) is the user's to keep positive."""
    for build, name in ((lambda: shapes.sphere(-1), "radius"), (lambda: shapes.torus(1, 0), "minor"),
                        (lambda: shapes.cylinder(0.5, -2), "height"), (lambda: shapes.cylinder(0, 1), "radius")):
        with pytest.raises(ValueError, match=f"{name} must be above 0"):
            build()
    tapered = shapes.sphere(sympy.Rational(1, 2) + z / 10)
    assert at(tapered, 0, 0, 0) == -0.5 and at(tapered, 0, 0, 1) == pytest.approx(1 - 0.6)
