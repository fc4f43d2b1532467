"""The region plan: which terms can be dropped per octant, and how the tape is split around them."""

import sympy
from sympy import Rational

from implc import scene, shapes, x, y, z
from implc.lower import lower
from implc.regions import plan_regions


def test_blend_sum_terms_are_found_and_self_contained():
    tape = lower(scene.load("paper_blobs").surface)
    plan = plan_regions(tape)
    assert len(plan.terms) == 10 and all(t.kind == "sum" and t.zero_when == "false" for t in plan.terms)
    roots = {t.root for t in plan.terms}
    for term in plan.terms:
        assert term.root in term.private and term.condition in term.private
        assert not roots & (set(term.private) - {term.root})  # no term inside another
    # everything before the terms is an input or a constant: a dead term costs nothing
    assert {tape.nodes[i][0] for i in plan.before} <= {"var", "const"}
    assert tape.outputs[0] in plan.after


def test_min_chain_leaves_are_terms():
    f = shapes.union(*[shapes.sphere(Rational(1, 5), (Rational(k, 5), 0, 0)) for k in range(-2, 3)])
    plan = plan_regions(lower(f))
    assert len(plan.terms) == 5 and {t.kind for t in plan.terms} == {"min"}
    assert len(plan.chain_leaves) == 5


def test_nothing_to_prune():
    assert not plan_regions(lower(x**2 + y**2 + z**2 - 1)).enabled
    assert not plan_regions(lower(sympy.sin(4 * sympy.Symbol("theta")) - sympy.Symbol("r"))).enabled


def test_gradient_over_all_terms_is_the_full_gradient():
    """implc_gradient_live with every term live computes the full gradient; with none live, the part of F
    outside the terms (here a constant: zero gradient)."""
    import ctypes

    import numpy as np

    import implc
    from implc.codegen.kernels import GRADIENT_LIVE_KERNEL
    P, N = ctypes.c_void_p, ctypes.c_int64
    rng = np.random.default_rng(4)
    pts = np.ascontiguousarray(rng.uniform(-1, 1, (64, 3)))
    union = shapes.union(*[shapes.sphere(Rational(1, 5), (Rational(k, 5), 0, 0)) for k in range(-2, 3)])
    for expr in (scene.load("paper_blobs").surface, union):
        s = implc.compile(expr)
        live = s.native.function(GRADIENT_LIVE_KERNEL, [P, P, P, N, N])
        value, grad = np.empty(64), np.empty((64, 3))
        live(pts.ctypes.data, value.ctypes.data, grad.ctypes.data, 64, -1)
        np.testing.assert_allclose(value, s.eval(pts), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(grad, s.gradient(pts), rtol=1e-12, atol=1e-15)
    s = implc.compile(scene.load("paper_blobs").surface)
    s.native.function(GRADIENT_LIVE_KERNEL, [P, P, P, N, N])(pts.ctypes.data, value.ctypes.data, grad.ctypes.data, 64, 0)
    np.testing.assert_array_equal(value, 0.25)
    np.testing.assert_array_equal(grad, 0.0)


def test_normals_kernel_without_terms_matches_the_gradient():
    """With nothing to prune, implc_gradient_live evaluates the gradient tape with the vector sin, cos and
    atan2: within rounding of Surface.gradient (C library) away from the z axis, where theta's
    derivatives blow up."""
    import ctypes

    import numpy as np

    import implc
    from implc.codegen.kernels import GRADIENT_LIVE_KERNEL
    from implc.symbols import phi, r, theta
    P, N = ctypes.c_void_p, ctypes.c_int64
    rng = np.random.default_rng(5)
    pts = np.ascontiguousarray(rng.uniform(-1, 1, (256, 3)))
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 0.05][:200]
    s = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r + sympy.cos(3 * phi) / 4)
    value, grad = np.empty(len(pts)), np.empty((len(pts), 3))
    s.native.function(GRADIENT_LIVE_KERNEL, [P, P, P, N, N])(pts.ctypes.data, value.ctypes.data, grad.ctypes.data,
                                                             len(pts), -1)
    np.testing.assert_allclose(value, s.eval(pts), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(grad, s.gradient(pts), rtol=1e-10, atol=1e-11)
