"""Property tests: random expressions from the whole supported grammar (every function, Min/Max,
Piecewise with every kind of condition (none holding another Piecewise), integer powers up to the
hundreds, integer-valued Float exponents, rational and irrational powers), compiled with both roundings,
never escape their enclosure over random and adversarial boxes, against 40-digit (and exact rational)
truth."""

from fractions import Fraction

import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import implc
from implc.compiler.rounding import POWI_MAX
from implc.compiler.symbols import phi, r, theta, x, y, z
from implc.native.jit import host_has_avx512

from ..support.truth import adversarial_boxes, assert_encloses

LEAVES = st.sampled_from([x, y, z, r, theta, phi, sympy.Rational(1, 3), sympy.Integer(2), sympy.pi,
                          sympy.Rational(-5, 4), sympy.Float(0.1)])
UNARY = [sympy.sin, sympy.cos, sympy.tan, sympy.atan, sympy.tanh, sympy.sinh, sympy.cosh, sympy.Abs, sympy.exp,
         sympy.sqrt, sympy.log, sympy.cbrt, sympy.asin, sympy.acos, lambda a: -a,
         lambda a: a**2, lambda a: a**3, lambda a: a**22, lambda a: a**-5, lambda a: a**sympy.Float(2.0),
         lambda a: a**sympy.Float(-3.0), lambda a: a**sympy.Rational(3, 4), lambda a: a**sympy.Rational(-1, 2),
         lambda a: sympy.Abs(a)**sympy.pi]


def _piecewise(build):
    """``build(a, b)``, a Piecewise whose conditions compare a and b; x where a or b holds a Piecewise
    already: SymPy folds a condition that holds one through solveset, which can run for hours (a CI run
    hung there, factoring a degree-22 polynomial's complex roots while the strategy drew an example)."""
    return lambda a, b: x if a.has(sympy.Piecewise) or b.has(sympy.Piecewise) else build(a, b)


BINARY = [sympy.Add, sympy.Mul, lambda a, b: a - b, lambda a, b: a / b, sympy.Min, sympy.Max, sympy.atan2,
          _piecewise(lambda a, b: sympy.Piecewise((a, b < 0), (b, True))),
          _piecewise(lambda a, b: sympy.Piecewise((a, a <= b), (b * 2, True))),
          _piecewise(lambda a, b: sympy.Piecewise((a, (a > 0) & (b < 1)), (b, sympy.Ne(a, b)), (-a, True))),
          _piecewise(lambda a, b: sympy.Piecewise((a + 1, (b >= a) | sympy.Eq(a, 0)), (b, True)))]
POWERS = st.sampled_from([2, 3, 4, 7, 21, 22, 33, 64, 100, 255, -2, -3, -32, -63])
ROUNDINGS = ["widen", "directed"] if host_has_avx512() else ["widen"]


def _apply(fn, *args):
    """fn(*args), or x where SymPy refuses to build it (Min of complex numbers, comparing non-reals)."""
    if any(not isinstance(a, sympy.Expr) for a in args):
        return x
    try:
        return fn(*args)
    except (TypeError, ValueError):
        return x


def _expressions():
    def extend(children):
        unary = st.tuples(st.sampled_from(UNARY), children).map(lambda t: _apply(t[0], t[1]))
        binary = st.tuples(st.sampled_from(BINARY), children, children).map(lambda t: _apply(*t))
        power = st.tuples(children, POWERS).map(lambda t: _apply(lambda a, n: a**n, t[0], sympy.Integer(t[1])))
        return unary | binary | power
    return st.recursive(LEAVES, extend, max_leaves=8).filter(
        lambda e: isinstance(e, sympy.Expr) and not e.is_number and e.is_real is not False)


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(expr=_expressions(), seed=st.integers(0, 2**32 - 1), rounding=st.sampled_from(ROUNDINGS))
def test_random_expressions_are_enclosed(expr, seed, rounding):
    try:
        surface = implc.compile(expr, rounding=rounding)
    except implc.CompileError as exc:  # only the documented rejections may happen
        assert any(w in str(exc) for w in ("complex", "non-finite", "beyond ±")), str(exc)
        return
    rng = np.random.default_rng(seed)
    lo, hi = adversarial_boxes(rng, 24)
    assert_encloses(surface, expr, lo, hi, rng, per_box=4)


RATIONAL_BINARY = [sympy.Add, sympy.Mul, lambda a, b: a - b, lambda a, b: a / b]


def _rational_expressions():
    leaves = st.sampled_from([x, y, z, sympy.Rational(1, 3), sympy.Rational(-7, 5), sympy.Integer(3)])

    def extend(children):
        binary = st.tuples(st.sampled_from(RATIONAL_BINARY), children, children).map(lambda t: t[0](t[1], t[2]))
        power = st.tuples(children, st.sampled_from([2, 3, 4, 5, 21, 22, 64, -2, -5])).map(lambda t: t[0] ** t[1])
        return binary | power
    return st.recursive(leaves, extend, max_leaves=6).filter(
        lambda e: not e.is_number and not e.has(sympy.zoo, sympy.nan, sympy.oo)
        # nested powers multiply: ((x**64)**21)**64 is x**86016, which compile refuses (tested on its own)
        and all(abs(int(p.exp)) <= POWI_MAX for p in e.atoms(sympy.Pow) if p.exp.is_Integer))


finite_doubles = st.floats(min_value=-1e3, max_value=1e3, allow_nan=False, allow_infinity=False)


@settings(max_examples=150, deadline=None)
@given(expr=_rational_expressions(), point=st.tuples(finite_doubles, finite_doubles, finite_doubles),
       rounding=st.sampled_from(ROUNDINGS))
def test_point_boxes_enclose_the_exact_rational_value(expr, point, rounding):
    """Degenerate boxes (lo == hi) leave only rounding: the exact rational value must lie inside."""
    surface = implc.compile(expr, rounding=rounding)
    exact = expr.xreplace({s: sympy.Rational(Fraction(v)) for s, v in zip((x, y, z), point)})
    if exact.has(sympy.zoo, sympy.nan, sympy.oo, -sympy.oo):
        return  # a pole at this point: nothing finite to enclose
    pts = np.array([point])
    f_lo, f_hi = surface.interval(pts, pts)
    value = Fraction(int(exact.p), int(exact.q))
    if np.isfinite(f_lo[0]):
        assert Fraction(f_lo[0]) <= value, (expr, point, f_lo[0], float(value))
    if np.isfinite(f_hi[0]):
        assert value <= Fraction(f_hi[0]), (expr, point, f_hi[0], float(value))
