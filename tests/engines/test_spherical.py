"""Spherical coordinates over boxes: r, rho and theta are exact, phi wraps across the cut when periodic,
sin/cos ranges detect their peaks, and all of it is tighter than the naive acos(z/r) form."""

import numpy as np
import pytest
import sympy

import implc
from implc import phi, r, theta

from ..support.truth import adversarial_boxes


def grid_samples(lo, hi, n=17):
    """n³ points of each box, faces and corners included: (boxes, n³, 3)."""
    t = np.linspace(0, 1, n)
    g = np.stack(np.meshgrid(t, t, t, indexing="ij"), axis=-1).reshape(-1, 3)
    return lo[:, None, :] + g[None] * (hi - lo)[:, None, :]


def sampled_range(surface, lo, hi):
    pts = grid_samples(lo, hi)
    values = surface.eval(pts.reshape(-1, 3)).reshape(len(lo), -1)
    return values.min(axis=1), values.max(axis=1)


def test_r_is_exact():
    rng = np.random.default_rng(5)
    lo, hi = adversarial_boxes(rng, 400)
    f_lo, f_hi = implc.compile(r).interval(lo, hi)
    nearest = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(np.abs(lo), np.abs(hi)))
    farthest = np.maximum(np.abs(lo), np.abs(hi))
    r_min, r_max = np.sqrt((nearest**2).sum(1)), np.sqrt((farthest**2).sum(1))
    assert np.all(f_lo <= r_min) and np.all(f_hi >= r_max)
    np.testing.assert_allclose(f_lo, r_min, rtol=1e-14, atol=1e-300)
    np.testing.assert_allclose(f_hi, r_max, rtol=1e-14)


@pytest.mark.parametrize("expr", [theta, phi, sympy.sin(4 * theta), sympy.cos(3 * theta), sympy.sin(8 * phi)])
def test_angles_are_tight(expr):
    rng = np.random.default_rng(9)
    lo, hi = adversarial_boxes(rng, 300)
    s = implc.compile(expr)
    f_lo, f_hi = s.interval(lo, hi)
    s_lo, s_hi = sampled_range(s, lo, hi)
    assert np.all(f_lo <= s_lo) and np.all(f_hi >= s_hi)
    tightness = (s_hi - s_lo) / np.maximum(f_hi - f_lo, 1e-300)
    wide = (f_hi - f_lo) > 1e-6  # tiny boxes: tightness is all rounding
    # grid sampling can miss an interior extreme by a little; on average we lose almost nothing
    assert np.median(tightness[wide]) > 0.99, np.median(tightness[wide])
    assert np.mean(tightness[wide]) > 0.9, np.mean(tightness[wide])


def cut_boxes(rng, n):
    lo = np.column_stack([rng.uniform(-1, -0.3, n), -rng.uniform(0.01, 0.2, n), rng.uniform(-0.5, 0, n)])
    hi = lo + np.column_stack([rng.uniform(0.05, 0.2, n), np.zeros(n), rng.uniform(0.05, 0.5, n)])
    hi[:, 1] = rng.uniform(0.0, 0.2, n)
    hi[: n // 4, 1] = 0.0  # touching the cut from below: atan2(+0, x < 0) = +pi must be covered
    return lo, hi


def test_phi_wraps_across_the_cut_when_periodic():
    rng = np.random.default_rng(2)
    lo, hi = cut_boxes(rng, 200)
    periodic = implc.compile(sympy.sin(phi))
    f_lo, f_hi = periodic.interval(lo, hi)
    s_lo, s_hi = sampled_range(periodic, lo, hi)
    assert np.all(f_lo <= s_lo) and np.all(f_hi >= s_hi)
    assert np.all(f_hi - f_lo < 1.9)  # narrower than sin over [-pi, pi] on every box
    np.testing.assert_allclose(f_hi - f_lo, s_hi - s_lo, rtol=0.05, atol=1e-9)
    not_periodic = implc.compile(sympy.sin(phi) + phi / 1000)
    g_lo, g_hi = not_periodic.interval(lo, hi)
    assert np.all(g_hi - g_lo > 1.99)  # [-pi, pi]: the honest fallback


def test_atan2_theta_beats_the_acos_form():
    rng = np.random.default_rng(4)
    lo, hi = adversarial_boxes(rng, 500)
    lo, hi = lo[(hi - lo).max(1) < 1], hi[(hi - lo).max(1) < 1]
    ours = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r).interval(lo, hi)
    x, y, z = implc.x, implc.y, implc.z
    rr = sympy.sqrt(x**2 + y**2 + z**2)
    naive = implc.compile(sympy.sin(4 * sympy.acos(z / rr)) * sympy.sin(8 * sympy.atan2(y, x)) - rr).interval(lo, hi)
    ours_w, naive_w = ours[1] - ours[0], naive[1] - naive[0]
    finite = np.isfinite(naive_w)
    assert np.all(ours_w[finite] <= naive_w[finite] * (1 + 1e-9))
    assert np.mean(naive_w[finite]) > 1.05 * np.mean(ours_w[finite])
