"""The vector elementary functions against 60-digit values: their error stays within the proven bound,
far inside the widening the interval rules apply, and special inputs get the C library's answer."""

import mpmath
import numpy as np
import pytest
from llvmlite import ir

from implc.compiler import rounding
from implc.compiler.llvm import elementary
from implc.compiler.llvm.control import define, for_range
from implc.compiler.llvm.vector import VectorBuilder
from implc.native import abi
from implc.native.jit import NativeModule

PROVEN_ATAN2 = 1.1e-15  # the bounds derived in implc/compiler/llvm/elementary.py
PROVEN_SIN = 5e-16


def _run(name, width, *args):
    """elementary.<name> over the lanes of ``args`` (equal-length arrays, a multiple of width long)."""
    arity = len(args)
    entry = abi.Entry("f", tuple((f"in{k}", "f64*") for k in range(arity)) + (("out", "f64*"), ("n", "i64")))

    def build():
        module = ir.Module(name="elementary_test")
        double = ir.DoubleType()
        i64 = ir.IntType(64)
        fn, b = define(module, entry)
        *inputs, out, n = fn.args
        vector = ir.PointerType(ir.VectorType(double, width))
        with for_range(b, b.sdiv(n, ir.Constant(i64, width))) as i:
            at = [b.bitcast(b.gep(p, [b.mul(i, ir.Constant(i64, width))]), vector) for p in (*inputs, out)]
            value = getattr(elementary, name)(VectorBuilder(b, width), *[b.load(p, align=8) for p in at[:-1]])
            b.store(value, at[-1], align=8)
        b.ret_void()
        return str(module)
    native = NativeModule(build, source_key=f"elementary-{name}-test-w{width}")
    f = native.bind(entry)
    arrays = [np.ascontiguousarray(a, dtype=np.float64) for a in args]
    out = np.empty_like(arrays[0])
    f(*[a.ctypes.data for a in arrays], out.ctypes.data, len(out))
    return out


def test_atan_table_is_correctly_rounded():
    mpmath.mp.prec = 200
    for k, value in enumerate(elementary.ATAN_TABLE):
        assert value == float(mpmath.atan(mpmath.mpf(k) / 8)), k
    assert elementary.HALF_PI == float(mpmath.pi / 2) and elementary.PI == float(mpmath.pi)


@pytest.mark.parametrize("width", [8, 1])
def test_atan2_error_is_within_the_proven_bound(width):
    rng = np.random.default_rng(width)
    n = 4000
    scale = 10.0 ** rng.integers(-300, 300, n)
    y = rng.standard_normal(n) * scale
    x = rng.standard_normal(n) * np.where(rng.random(n) < 0.5, scale, 10.0 ** rng.integers(-300, 300, n))
    # near the octant borders and the table's breakpoints, where the reductions switch
    t = np.repeat(np.arange(0, 17) / 16, 16) * (1 + rng.uniform(-1e-12, 1e-12, 17 * 16))
    y = np.concatenate([y, t, -np.ones_like(t), t])
    x = np.concatenate([x, np.ones_like(t), -t, -np.ones_like(t)])
    got = _run("atan2", width, y, x)
    mpmath.mp.prec = 200
    worst = max(abs(mpmath.atan2(mpmath.mpf(a), mpmath.mpf(b)) - mpmath.mpf(g)) for a, b, g in zip(y, x, got))
    assert worst <= PROVEN_ATAN2
    assert PROVEN_ATAN2 < rounding.ATAN2_ERROR / 16


def test_atan2_special_inputs_take_the_c_library_value_lane_by_lane():
    inf, nan = np.inf, np.nan
    y = np.array([0, -0.0, 0, -0.0, inf, -inf, nan, 1, inf, 0, 1e-310, 2, 3, -5, 1e300, 7])
    x = np.array([0, 0, -0.0, -0.0, 1, -inf, 1, nan, inf, inf, 1e-310, 3, -4, 5, 1e-300, -1e-320])
    got = _run("atan2", 8, y, x)
    np.testing.assert_array_equal(got[:10], np.arctan2(y[:10], x[:10]))  # 0/0, infinities, NaN
    assert np.max(np.abs(got[10:] - np.arctan2(y[10:], x[10:]))) <= PROVEN_ATAN2  # regular, same vectors


@pytest.mark.parametrize("name", ["sin", "cos"])
@pytest.mark.parametrize("width", [8, 1])
def test_sin_cos_error_is_within_the_proven_bound(name, width):
    rng = np.random.default_rng(len(name) + width)
    n = 3000
    x = rng.uniform(-1, 1, n) * 10.0 ** rng.integers(-12, 6, n)
    # around multiples of pi/4, where the quadrant and the reduction switch, up to the range's end
    quarters = np.arange(-400, 401) * (np.pi / 4)
    x = np.concatenate([x, quarters, np.nextafter(quarters, np.inf), [elementary.TRIG_MAX, -elementary.TRIG_MAX]])
    x = x[: len(x) - len(x) % 8]
    got = _run(name, width, x)
    mpmath.mp.prec = 200
    exact = getattr(mpmath, name)
    worst = max(abs(exact(mpmath.mpf(a)) - mpmath.mpf(g)) for a, g in zip(x, got))
    assert worst <= PROVEN_SIN
    assert PROVEN_SIN < rounding.SIN_ERROR / 16


@pytest.mark.parametrize("name", ["sin", "cos"])
def test_sin_cos_beyond_their_range_take_the_c_library_value(name):
    x = np.array([np.inf, -np.inf, np.nan, 2e5, -1e300, 1e17, np.nextafter(elementary.TRIG_MAX, np.inf), 3.0])
    got = _run(name, 8, x)
    with np.errstate(invalid="ignore"):
        expected = getattr(np, name)(x)
    np.testing.assert_array_equal(got[:7], expected[:7])
    assert abs(got[7] - expected[7]) <= PROVEN_SIN


@pytest.mark.slow  # two compiles of a long tape with its kernels, 10 s
def test_outlined_vector_functions_compute_what_expanded_ones_do(monkeypatch):
    """A tape with many sin, cos and atan2 nodes calls one copy of each (small IR, fast compiles); the
    results are bit-identical to expanding them at every use."""
    import sympy

    import implc
    from implc.compiler.symbols import phi, r, theta, x, y
    from implc.native import abi
    monkeypatch.setenv("IMPLC_CACHE_DIR", "off")  # the two builds share a cache key
    expr = sum(sympy.sin(k * x + y) / k for k in range(1, 8)) + sympy.cos(3 * phi) * sympy.sin(2 * theta) - r
    assert elementary.outlines(implc.compile(expr).gradient_tape)
    outlined = implc.compile(expr)
    assert "implc.elementary.sin.w8" in outlined.llvm_ir
    monkeypatch.setattr(elementary, "OUTLINE_ABOVE", 10**6)
    expanded = implc.compile(expr)
    assert "implc.elementary.sin.w8" not in expanded.llvm_ir
    rng = np.random.default_rng(3)
    lo = rng.uniform(-1, 1, (256, 3))
    hi = lo + rng.uniform(0, 0.3, (256, 3))
    for mean_value in (False, True):
        np.testing.assert_array_equal(outlined.interval(lo, hi, mean_value), expanded.interval(lo, hi, mean_value))
    value, grad = np.empty(256), np.empty((256, 3))
    results = []
    for s in (outlined, expanded):
        s.kernel(abi.GRADIENT_LIVE)(lo.ctypes.data, value.ctypes.data, grad.ctypes.data, 256, -1)
        results.append((value.copy(), grad.copy()))
    np.testing.assert_array_equal(results[0][0], results[1][0])
    np.testing.assert_array_equal(results[0][1], results[1][1])


PROVEN_EXP = 6.2e-15  # relative, the bounds derived in implc/compiler/llvm/elementary.py
PROVEN_LOG = 2.9e-15


def test_ln2_pieces_and_constants_are_as_stated():
    mpmath.mp.prec = 200
    ln2 = mpmath.log(2)
    hi = elementary.LN2_1
    assert mpmath.mpf(hi) * 2**32 == int(mpmath.mpf(hi) * 2**32), "32 significant bits"
    assert abs(mpmath.mpf(hi) - ln2) < 2.0**-32
    assert elementary.LN2_2 == float(ln2 - mpmath.mpf(hi))
    assert abs(ln2 - mpmath.mpf(hi) - mpmath.mpf(elementary.LN2_2)) < mpmath.mpf(2) ** -86
    assert elementary.SQRT2 == float(mpmath.sqrt(2)) and elementary.INV_LN2 == float(1 / ln2)


@pytest.mark.parametrize("width", [8, 1])
def test_exp_relative_error_is_within_the_proven_bound(width):
    rng = np.random.default_rng(11 + width)
    x = np.concatenate([rng.uniform(-1, 1, 1500) * 10.0 ** rng.integers(-15, 3, 1500),
                        rng.uniform(-elementary.EXP_MAX, elementary.EXP_MAX, 1000),
                        np.arange(-1021, 1022) * np.log(2) + 0.5 * np.log(2),  # where k switches
                        [elementary.EXP_MAX, -elementary.EXP_MAX, 0.0, -0.0]])
    x = x[: len(x) - len(x) % 8]
    got = _run("exp", width, x)
    mpmath.mp.prec = 200
    worst = max(abs(mpmath.mpf(g) / mpmath.exp(mpmath.mpf(a)) - 1) for a, g in zip(x, got))
    assert worst <= PROVEN_EXP
    assert PROVEN_EXP < rounding.EXP_ERROR / 4


@pytest.mark.parametrize("width", [8, 1])
def test_log_relative_error_is_within_the_proven_bound(width):
    rng = np.random.default_rng(17 + width)
    x = np.concatenate([10.0 ** rng.uniform(-307, 308, 1500), rng.uniform(0.5, 2, 1000),
                        1 + rng.uniform(-1e-6, 1e-6, 200),  # near 1, where log is near 0
                        np.sqrt(2) * 2.0 ** np.arange(-60, 60), np.nextafter(np.sqrt(2), 0) * 2.0 ** np.arange(-60, 60),
                        [2.0**-1022, np.finfo(float).max, 1.0, 2.0, 0.5]])
    x = x[: len(x) - len(x) % 8]
    got = _run("log", width, x)
    mpmath.mp.prec = 200
    worst = max(abs(mpmath.mpf(g) - mpmath.log(mpmath.mpf(a)))
                / max(abs(mpmath.log(mpmath.mpf(a))), mpmath.mpf(2)**-1074)
                for a, g in zip(x, got) if a != 1.0)
    assert worst <= PROVEN_LOG
    assert got[np.flatnonzero(x == 1.0)][0] == 0.0
    assert PROVEN_LOG < rounding.LOG_ERROR / 4


@pytest.mark.parametrize("name, x", [
    ("exp", [np.inf, -np.inf, np.nan, 709.5, -745.0, -720.0, 1e300, 1.0]),
    ("log", [0.0, -0.0, -1.0, np.inf, np.nan, 1e-310, 5e-324, 3.0]),
])
def test_exp_log_beyond_their_range_take_the_c_library_value(name, x):
    x = np.array(x)
    got = _run(name, 8, x)
    with np.errstate(all="ignore"):
        expected = getattr(np, name)(x)
    np.testing.assert_array_equal(got[:7], expected[:7])
    assert abs(got[7] / expected[7] - 1) <= PROVEN_EXP
