"""The region plan: which terms can be dropped per octant, and how the tape is split around them."""

import pytest
import sympy
from sympy import Rational

from implc import shapes, x, y, z
from implc.compiler.lower import lower
from implc.engines.compiled.plan import plan_regions
from implc.files import scene


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
    import numpy as np

    import implc
    from implc.native import abi
    rng = np.random.default_rng(4)
    pts = np.ascontiguousarray(rng.uniform(-1, 1, (64, 3)))
    union = shapes.union(*[shapes.sphere(Rational(1, 5), (Rational(k, 5), 0, 0)) for k in range(-2, 3)])
    for expr in (scene.load("paper_blobs").surface, union):
        s = implc.compile(expr)
        live = s.kernel(abi.GRADIENT_LIVE)
        value, grad = np.empty(64), np.empty((64, 3))
        live(pts.ctypes.data, value.ctypes.data, grad.ctypes.data, 64, -1)
        np.testing.assert_allclose(value, s.eval(pts), rtol=1e-12, atol=1e-15)
        np.testing.assert_allclose(grad, s.gradient(pts), rtol=1e-12, atol=1e-15)
    s = implc.compile(scene.load("paper_blobs").surface)
    s.kernel(abi.GRADIENT_LIVE)(pts.ctypes.data, value.ctypes.data, grad.ctypes.data, 64, 0)
    np.testing.assert_array_equal(value, 0.25)
    np.testing.assert_array_equal(grad, 0.0)


def test_normals_kernel_without_terms_matches_the_gradient():
    """With nothing to prune, implc_gradient_live evaluates the gradient tape with the vector sin, cos and
    atan2: within rounding of Surface.gradient (C library) away from the z axis, where theta's
    derivatives blow up."""
    import numpy as np

    import implc
    from implc.compiler.symbols import phi, r, theta
    from implc.native import abi
    rng = np.random.default_rng(5)
    pts = np.ascontiguousarray(rng.uniform(-1, 1, (256, 3)))
    pts = pts[np.hypot(pts[:, 0], pts[:, 1]) > 0.05][:200]
    s = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r + sympy.cos(3 * phi) / 4)
    value, grad = np.empty(len(pts)), np.empty((len(pts), 3))
    s.kernel(abi.GRADIENT_LIVE)(pts.ctypes.data, value.ctypes.data, grad.ctypes.data,
                                                             len(pts), -1)
    np.testing.assert_allclose(value, s.eval(pts), rtol=1e-12, atol=1e-13)
    np.testing.assert_allclose(grad, s.gradient(pts), rtol=1e-10, atol=1e-11)


@pytest.mark.parametrize("case", ["paper_blobs", "sphere_union"])
def test_mean_value_form_over_the_live_terms_encloses_and_never_loosens(case):
    """implc_interval_mvf given the live mask of the boxes' parent folds over the live terms only: its
    enclosures still hold every sampled value of F, and are never looser than with every term live."""
    import numpy as np

    import implc
    from implc.native import abi
    if case == "paper_blobs":
        expr = scene.load("paper_blobs").surface
    else:
        expr = shapes.union(*[shapes.sphere(Rational(1, 5), (Rational(k, 5), Rational(k % 2, 7), 0))
                              for k in range(-3, 4)])
    s = implc.compile(expr)
    natural, mvf = s.kernel(abi.INTERVAL), s.kernel(abi.INTERVAL_MVF)
    every_term = (1 << len(plan_regions(s.tape).terms)) - 1
    rng = np.random.default_rng(6)
    size = 1 / 16
    parents = rng.uniform(-0.9, 0.9 - size, (400, 3))
    one = np.array([-1], dtype=np.int64)
    parent_mask, scratch = np.empty(8, dtype=np.int64), np.empty(8)
    pruned_somewhere = 0
    for corner in parents:
        lo, hi = np.tile(corner, (8, 1)), np.tile(corner + size, (8, 1))  # the parent box, 8 times
        natural(lo.ctypes.data, hi.ctypes.data, scratch.ctypes.data, scratch.ctypes.data, 8, one.ctypes.data,
                parent_mask.ctypes.data)
        mask = parent_mask[:1].copy()
        bits = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)])
        c_lo = np.ascontiguousarray(corner + bits * size / 2)
        c_hi = np.ascontiguousarray(c_lo + size / 2)
        out = {}
        for label, live in (("pruned", mask), ("all", one)):
            f_lo, f_hi, masks = np.empty(8), np.empty(8), np.empty(8, dtype=np.int64)
            mvf(c_lo.ctypes.data, c_hi.ctypes.data, f_lo.ctypes.data, f_hi.ctypes.data, 8, live.ctypes.data,
                masks.ctypes.data)
            out[label] = (f_lo, f_hi)
        f_lo, f_hi = out["pruned"]
        a_lo, a_hi = out["all"]
        slack = 1e-12 * (1 + np.abs(a_lo) + np.abs(a_hi))
        assert np.all(f_lo >= a_lo - slack) and np.all(f_hi <= a_hi + slack)
        for c in range(8):
            pts = c_lo[c] + rng.random((16, 3)) * (c_hi[c] - c_lo[c])
            values = s.eval(pts)
            assert np.all(values >= f_lo[c]) and np.all(values <= f_hi[c]), f"{case}: box {c_lo[c]}"
        pruned_somewhere += (int(mask[0]) & every_term) != every_term
    assert pruned_somewhere > 100  # the parents' masks did drop terms
