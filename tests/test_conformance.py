"""Every op through every evaluator: the numpy reference and the compiled kernels agree, intervals enclose
high-precision true values over adversarial boxes, and gradients match differences and the reference.
Kernels compile with the host's default rounding (directed where the CPU has AVX-512); the comparisons
with the reference, which widens, use kernels compiled to widen as well."""

import zlib

import numpy as np
import pytest
import sympy
from sympy import (
    Abs,
    Max,
    Min,
    Piecewise,
    Rational,
    acos,
    asin,
    atan,
    atan2,
    cbrt,
    cos,
    cosh,
    exp,
    log,
    sin,
    sinh,
    sqrt,
    tan,
    tanh,
)

import implc
from implc import ir, reference
from implc.codegen.interval_rules import IntervalEmitter
from implc.gradient import DERIVATIVE_RULES
from implc.jit import host_has_avx512
from implc.reference import INTERVAL_RULES as RULES
from implc.symbols import phi, r, theta, x, y, z

from .truth import TrueValues, adversarial_boxes, assert_encloses

# One or more expressions per op of the IR (the ids name the op they exercise).
OP_CASES = {
    "const": sympy.pi * x + Rational(1, 3),
    "neg": -x + y,
    "add": x + y + z,
    "sub": x - 2 * y,
    "mul": x * y * z,
    "scale": Rational(3, 7) * x + 3 * y,
    "div": x / (y + Rational(1, 2)),
    "div_pole": (x + 1) / y,
    "powi_even": (x - Rational(1, 3)) ** 4 + y**2,
    "powi_odd": (x + y) ** 3 - z**5,
    "powi_neg": 1 / (x**2 + Rational(1, 10)) - (y + 2) ** -3,
    "powf": (x**2 + y**2) ** Rational(3, 4),
    "powf_irrational": Abs(x) ** sympy.pi,
    "sqrt": sqrt(x + Rational(1, 2)) - y,
    "cbrt": cbrt(x**2 + y) * 2,
    "exp": exp(x * 3) - y,
    "log": log(x**2 + y**2) + z,
    "log_domain": log(x + Rational(1, 4)),
    "sin": sin(7 * x + y) - z,
    "cos": cos(5 * x) * cos(3 * y),
    "tan": tan(x + y) - z,
    "asin": asin(x / 2) + y,
    "asin_domain": asin(x + y),
    "acos": acos(y / 2) - x,
    "atan": atan(x * 4) * y,
    "atan2": atan2(y, x) - z,
    "atan2_wrapped": sin(3 * phi) - x,
    "sinh": sinh(x * 2) + y,
    "cosh": cosh(x - y) - 2,
    "tanh": tanh(3 * x) - y,
    "abs": Abs(x) + Abs(y - z) - 1,
    "min": Min(x, y, z + 1),
    "max": Max(x**2, y - z),
    "select_lt": Piecewise((x**2, y < 0), (x + 1, True)),
    "select_le": Piecewise((x - 1, x**2 + y**2 <= Rational(1, 4)), (z, True)),
    "piecewise_and": Piecewise((y, (x > 0) & (z < 0)), (-y, True)),
    "piecewise_or": Piecewise((y + 1, (x > 0) | (z > Rational(1, 2))), (2 * x, True)),
    "piecewise_eq_ne": Piecewise((y, sympy.Eq(x, 0)), (z, sympy.Ne(y, 1)), (x, True)),
    "piecewise_ge_not": Piecewise((y, x >= Rational(1, 3)), (z, ~(y <= 0)), (x, True)),
    "spherical": sin(4 * theta) * sin(8 * phi) - r,
    "spherical_mixed": r - 1 + x * cos(theta),
    "var": x,
}


def test_every_op_has_every_rule():
    ops = set(ir.OPS) - {"const", "var"}
    assert ops == set(RULES), "numpy interval rules"
    assert ops == set(DERIVATIVE_RULES), "derivative rules"
    assert ops <= set(reference.POINT_RULES) | {"powi", "powf", "scale"}, "point rules"
    assert all(hasattr(IntervalEmitter, f"i_{op}") for op in ops), "LLVM interval emitters"


def test_op_cases_cover_every_op():
    covered = set()
    for expr in OP_CASES.values():
        covered.update(op for op, _, _ in implc.compile(expr).gradient_tape.nodes)
    assert covered == set(ir.OPS)


@pytest.fixture(scope="module")
def surfaces():
    return {name: implc.compile(expr) for name, expr in OP_CASES.items()}


@pytest.fixture(scope="module")
def widened():
    """The same surfaces with round-to-nearest-then-widen interval arithmetic, as the reference does."""
    return {name: implc.compile(expr, rounding="widen") for name, expr in OP_CASES.items()}


def seed(name: str) -> int:
    return zlib.crc32(name.encode())  # stable across runs, unlike hash()


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_interval_encloses_true_values(name, surfaces):
    rng = np.random.default_rng(seed(name))
    lo, hi = adversarial_boxes(rng, 60)
    assert_encloses(surfaces[name], OP_CASES[name], lo, hi, rng)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_widened_intervals_enclose_true_values(name, widened):
    rng = np.random.default_rng(seed(name) + 2)
    lo, hi = adversarial_boxes(rng, 40)
    assert_encloses(widened[name], OP_CASES[name], lo, hi, rng)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_directed_rounding_is_never_looser_than_widening(name, surfaces, widened):
    """Each directed bound is the nearest double outward of its operation's exact result; widening moves
    at least as far, and every rule is monotone in its operands' bounds, so the enclosures nest."""
    if not host_has_avx512():
        with pytest.raises(implc.CompileError, match="AVX-512"):
            implc.compile(OP_CASES[name], rounding="directed")
        return
    directed = implc.compile(OP_CASES[name], rounding="directed")
    rng = np.random.default_rng(seed(name) + 3)
    lo, hi = adversarial_boxes(rng, 200)
    for mean_value in (False, True):
        d_lo, d_hi = directed.interval(lo, hi, mean_value)
        w_lo, w_hi = widened[name].interval(lo, hi, mean_value)
        assert np.all(d_lo >= w_lo) and np.all(d_hi <= w_hi), f"mean_value={mean_value}"
    assert_encloses(directed, OP_CASES[name], lo[:40], hi[:40], rng)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_mean_value_form_encloses_and_never_loosens(name, surfaces, widened):
    s = surfaces[name]
    rng = np.random.default_rng(seed(name) + 1)
    lo, hi = adversarial_boxes(rng, 60)
    small = rng.random(60) < 0.5  # the form pays on small boxes: shrink half of them
    hi[small] = lo[small] + (hi[small] - lo[small]) * 1e-3
    assert_encloses(s, OP_CASES[name], lo, hi, rng, mean_value=True)
    n_lo, n_hi = s.interval(lo, hi)
    m_lo, m_hi = s.interval(lo, hi, mean_value=True)
    assert np.all(m_lo >= n_lo) and np.all(m_hi <= n_hi)
    r_lo, r_hi = reference.eval_interval_mean_value(s.tape, lo, hi)
    m_lo, m_hi = widened[name].interval(lo, hi, mean_value=True)
    np.testing.assert_allclose(m_lo, r_lo, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(m_hi, r_hi, rtol=1e-12, atol=1e-12)


def test_mean_value_form_is_tighter_on_small_boxes():
    s = implc.compile(x * (1 - x) + sin(x) * y - x * y)  # x and y repeat: the dependency problem
    rng = np.random.default_rng(0)
    lo = rng.uniform(-1, 1, (500, 3))
    hi = lo + 1e-2
    n_lo, n_hi = s.interval(lo, hi)
    m_lo, m_hi = s.interval(lo, hi, mean_value=True)
    assert np.mean(m_hi - m_lo) < 0.9 * np.mean(n_hi - n_lo)


@pytest.mark.parametrize("name", ["atan2", "atan2_wrapped", "spherical"])
def test_atan2_corners_match_the_reference_on_every_kind_of_box(name, widened):
    """The kernels call atan2 at the two corners where it is extreme; the reference evaluates all four.
    Boxes with every placement of their edges: on, across and beside both axes, tiny, huge, infinite."""
    edges = [-np.inf, -3.0, -1.0, -1e-300, -0.0, 0.0, 1e-300, 0.5, 2.0, np.inf]
    pairs = [(a, b) for a in edges for b in edges if a <= b]
    xs, ys = np.array(pairs * len(pairs)), np.repeat(np.array(pairs), len(pairs), axis=0)
    lo = np.column_stack([xs[:, 0], ys[:, 0], np.full(len(xs), -0.5)])
    hi = np.column_stack([xs[:, 1], ys[:, 1], np.full(len(xs), 0.25)])
    s = widened[name]
    f_lo, f_hi = s.interval(lo, hi)
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    np.testing.assert_allclose(f_lo, r_lo, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f_hi, r_hi, rtol=1e-12, atol=1e-12)


def test_jumps_never_use_the_mean_value_form():
    step = implc.compile(Piecewise((1, x < 0), (-1, True)) + y / 100)
    lo, hi = np.array([[-1e-3, 0, 0]]), np.array([[1e-3, 1e-3, 1e-3]])
    f_lo, f_hi = step.interval(lo, hi, mean_value=True)
    assert f_lo[0] <= -1 and f_hi[0] >= 1  # both sides of the jump
    cut = implc.compile(atan2(y, x))
    lo, hi = np.array([[-1.0, -1e-3, 0]]), np.array([[-0.999, 1e-3, 0]])
    f_lo, f_hi = cut.interval(lo, hi, mean_value=True)
    assert f_lo[0] <= -3.14 and f_hi[0] >= 3.14


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_compiled_matches_reference(name, widened):
    s = widened[name]
    rng = np.random.default_rng(7)
    pts = rng.uniform(-1.5, 1.5, (203, 3))
    np.testing.assert_allclose(s.eval(pts), reference.eval_point(s.tape, pts)[0], rtol=1e-12, atol=1e-12)
    value, grad = s.value_and_gradient(pts)
    ref_value, ref_grad = reference.eval_gradient(s.tape, pts)
    np.testing.assert_allclose(value, ref_value, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(grad, ref_grad, rtol=1e-12, atol=1e-12)
    lo, hi = adversarial_boxes(rng, 203)
    f_lo, f_hi = s.interval(lo, hi)
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    # same rules and rounding; only libm implementations (numpy's vs the C library's) may differ
    np.testing.assert_allclose(f_lo, r_lo, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(f_hi, r_hi, rtol=1e-12, atol=1e-12)


@pytest.mark.parametrize("width", [1, 2, 4])
@pytest.mark.parametrize("name", ["spherical", "select_le", "atan2_wrapped", "powi_even", "div_pole", "min"])
def test_every_vector_width_computes_the_same(name, width, surfaces):
    s8, s = surfaces[name], implc.compile(OP_CASES[name], vector_width=width)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1.5, 1.5, (37, 3))
    np.testing.assert_array_equal(s.eval(pts), s8.eval(pts))
    np.testing.assert_array_equal(s.gradient(pts), s8.gradient(pts))
    lo, hi = adversarial_boxes(rng, 37)
    for mean_value in (False, True):
        np.testing.assert_array_equal(s.interval(lo, hi, mean_value), s8.interval(lo, hi, mean_value))


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_gradient_matches_differences(name, surfaces):
    s = surfaces[name]
    truth = TrueValues(OP_CASES[name])
    rng = np.random.default_rng(11)
    pts = rng.uniform(-1.2, 1.2, (25, 3))
    grad = s.gradient(pts)
    checked = 0
    for p, g in zip(pts, grad):
        expected = truth.gradient(p)
        if expected is None:
            continue  # F is undefined around p (e.g. log of a negative)
        np.testing.assert_allclose(g, expected, rtol=1e-8, atol=1e-8, err_msg=f"{name} at {p}")
        checked += 1
    assert checked >= 5, f"{name}: too few points inside the domain to check"


def test_point_values_match_true_values(surfaces):
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.2, 1.2, (40, 3))
    for name, s in surfaces.items():
        truth = TrueValues(OP_CASES[name])
        values = s.eval(pts)
        for p, v in zip(pts, values):
            t = truth.at(p)
            if t is None or t == "pole":
                assert not np.isfinite(v) or t == "pole", f"{name} at {p}: {v} where undefined"
                continue
            assert abs(v - float(t)) <= 1e-12 * (1 + abs(float(t))), f"{name} at {p}: {v} vs {t}"


def test_an_undefined_condition_makes_the_piecewise_undefined():
    """Found by the property test: cbrt(x) < 0 is undefined for x < 0 (principal root), so the Piecewise
    is, and a box reaching x < 0 must not be pruned, whichever branch the comparison would pick."""
    s = implc.compile(Piecewise((x**3, cbrt(x) < 0), (x, True)))
    lo, hi = np.array([[-2.0, 0, 0], [0.5, 0, 0]]), np.array([[3.0, 1, 1], [1.0, 1, 1]])
    f_lo, f_hi = s.interval(lo, hi)
    assert f_lo[0] == -np.inf and f_hi[0] == np.inf
    assert f_lo[1] <= 0.5 and f_hi[1] >= 1.0 and np.isfinite(f_hi[1])
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    assert r_lo[0] == -np.inf and r_hi[0] == np.inf
    assert np.isnan(s.eval(np.array([[-1.0, 0, 0]]))[0])
    assert np.isnan(reference.eval_point(s.tape, np.array([[-1.0, 0, 0]]))[0][0])
