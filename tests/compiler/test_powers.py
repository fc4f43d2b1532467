"""Integer powers are enclosed for every exponent implc accepts, in both rounding modes, against an
independent truth (mpmath at 300 bits), including results near overflow and in the subnormal range; and
integer-valued Float exponents are integer powers."""

import mpmath
import numpy as np
import pytest
import sympy

import implc
from implc import x, y, z
from implc.compiler import reference
from implc.compiler.rounding import POWI_MAX
from implc.native.jit import host_has_avx512

EXPONENTS = [2, 3, 5, 21, 22, 31, 32, 63, 64, 100, 255, 256, 1000, 4097, POWI_MAX - 1, POWI_MAX,
             -2, -3, -32, -63, -1000, -POWI_MAX]
ROUNDINGS = ["widen", pytest.param("directed", marks=pytest.mark.skipif(
    not host_has_avx512(), reason="directed rounding needs AVX-512F; this CPU has none"))]


def bases(n: int, rng) -> np.ndarray:
    """Points where |x|^n spans the doubles: ordinary values, results near the largest double, in and
    below the subnormal range, both signs, and the ±3 range the issue's reproduction used."""
    k = abs(n)
    logs = np.concatenate([rng.uniform(-700, 700, 120),  # ln |x|^n in the normal range
                           rng.uniform(-745, -708, 40),  # subnormal results (and their underflow)
                           rng.uniform(700, 709.7, 20)])  # close to the largest double
    mags = np.exp(logs / k)
    mags = np.concatenate([mags, rng.uniform(0, 3, 40), [1.0, np.nextafter(1.0, 2), np.nextafter(1.0, 0)]])
    signs = np.where(rng.random(len(mags)) < 0.5, -1.0, 1.0)
    return mags * signs


def truth(v: float, n: int):
    with mpmath.workprec(300):
        return mpmath.mpf(v) ** n


def assert_holds(f_lo, f_hi, xs, n, what):
    for v, lo, hi in zip(xs, f_lo, f_hi):
        t = truth(float(v), n)
        ok = mpmath.mpf(lo) <= t <= mpmath.mpf(hi) if np.isfinite(v) else True
        if not ok and not (np.isinf(lo) or np.isinf(hi)):
            raise AssertionError(f"{what}: x = {float(v)!r}, x**{n} = {mpmath.nstr(t, 25)} outside "
                                 f"[{lo!r}, {hi!r}]")
        assert ok, f"{what}: x = {float(v)!r}: [{lo!r}, {hi!r}] misses {mpmath.nstr(t, 25)}"


@pytest.mark.parametrize("rounding", ROUNDINGS)
@pytest.mark.parametrize("n", EXPONENTS)
def test_point_boxes_enclose_the_power(n, rounding):
    s = implc.compile(x**n, rounding=rounding)
    xs = bases(n, np.random.default_rng(abs(n)))
    pts = np.column_stack([xs, np.zeros_like(xs), np.zeros_like(xs)])
    f_lo, f_hi = s.interval(pts, pts)
    assert_holds(f_lo, f_hi, xs, n, f"{rounding} kernel")
    if rounding == "widen":  # the numpy reference shares the widening: it must hold too
        r_lo, r_hi = reference.eval_interval(s.tape, pts, pts)
        assert_holds(r_lo, r_hi, xs, n, "numpy reference")


def test_the_reported_box():
    """The issue's reproduction: x**22 at x = -1.4208034792810413 (true 2268.5495138638137...)."""
    v = -1.4208034792810413
    f_lo, f_hi = implc.compile(x**22, rounding="widen").interval(np.array([[v, 0, 0]]), np.array([[v, 0, 0]]))
    assert mpmath.mpf(f_lo[0]) <= truth(v, 22) <= mpmath.mpf(f_hi[0])


def test_exponents_beyond_the_limit_are_refused():
    with pytest.raises(implc.CompileError, match=f"beyond ±{POWI_MAX}"):
        implc.compile(x ** (POWI_MAX + 1))
    with pytest.raises(implc.CompileError, match=f"beyond ±{POWI_MAX}"):
        implc.compile(y ** -(POWI_MAX + 1) - x)


@pytest.mark.parametrize("exponent", [2.0, 3.0, -2.0, 4.0])
def test_integer_valued_float_exponents_are_integer_powers(exponent):
    """x**2.0 is x**2: defined for negative x in both evaluators (it used to go to pow(), which calls
    every negative base undefined, and turned a sphere into a cube)."""
    e = sympy.Float(exponent)
    s = implc.compile(x**e + y**e + z**e - 3 * sympy.Rational(1, 4) ** e)
    exact = implc.compile(x ** int(exponent) + y ** int(exponent) + z ** int(exponent)
                          - 3 * sympy.Rational(1, 4) ** int(exponent))
    assert s.ir == exact.ir
    pts = np.array([[-0.5, -0.5, -0.5], [-0.25, 0.1, -0.3]])
    np.testing.assert_array_equal(s.eval(pts), exact.eval(pts))


def test_a_sphere_written_with_float_exponents_stays_a_sphere():
    sphere = implc.voxelize(implc.compile(x**2.0 + y**2.0 + z**2.0 - 0.25), 7, storage="coords")
    exact = implc.voxelize(implc.compile(x**2 + y**2 + z**2 - 0.25), 7, storage="coords")
    np.testing.assert_array_equal(sphere.coords, exact.coords)
