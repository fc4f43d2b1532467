"""Numeric constants are only as good as their certified digits: each becomes an interval that provably
holds the exact value, or a CompileError naming it; numbers beyond the doubles get infinite bounds."""

import subprocess
import sys

import mpmath
import numpy as np
import pytest
import sympy

import implc
from implc import CompileError, x
from implc.compiler.lower import is_periodic_in_phi, number_bounds
from implc.compiler.symbols import phi, r, theta

t, n = sympy.symbols("t n")


def encloses(bounds, exact) -> bool:
    _, lo, hi = bounds
    return mpmath.mpf(lo) <= exact <= mpmath.mpf(hi)


def test_a_numeric_integral_is_its_closed_form():
    """∫₀¹ sin(1/t) dt: SymPy's 60-digit evalf of the integral had 2 correct digits (0.50 for
    0.504067...); the closed form sin(1) − Ci(1) is exact. The truth here: ∫₁^∞ sin(u)/u² du by mpmath's
    oscillatory quadrature, at 30 digits."""
    with mpmath.workdps(30):
        exact = mpmath.quadosc(lambda u: mpmath.sin(u) / u**2, [1, mpmath.inf], omega=1)
    bounds = number_bounds(sympy.Integral(sympy.sin(1 / t), (t, 0, 1)))
    assert encloses(bounds, exact) and bounds[2] - bounds[1] <= 2 * np.spacing(0.5)
    s = implc.compile(x - sympy.Integral(sympy.sin(1 / t), (t, 0, 1)), bounds=((0, 1),) * 3)
    cells = np.unique(implc.voxelize(s, 8, storage="coords").coords[:, 0])
    np.testing.assert_array_equal(cells, [int(float(exact) * 256)])  # x-cell 129, not 128 (0.50)


@pytest.mark.parametrize("number", [
    sympy.Integral(sympy.exp(-t**t), (t, 0, 1)),
    sympy.Sum(1 / sympy.factorial(n) ** n, (n, 1, sympy.oo)),
])
def test_a_number_without_closed_form_is_refused_by_name(number):
    with pytest.raises(CompileError, match="no closed form") as info:
        implc.compile(x - number)
    assert "Integral" in str(info.value) or "Sum" in str(info.value)


def test_an_infinite_sum_with_a_closed_form_is_that_number():
    bounds = number_bounds(sympy.Sum(1 / n**2, (n, 1, sympy.oo)))  # pi²/6, not "non-finite"
    with mpmath.workdps(40):
        assert encloses(bounds, mpmath.pi**2 / 6)


@pytest.mark.parametrize("number, sign", [(sympy.exp(1000), 1), (-(sympy.Integer(2)**64)**64, -1),
                                          (((sympy.Integer(2)**64)**64)**64, 1)])
def test_numbers_beyond_the_doubles_get_an_infinite_bound(number, sign):
    nearest, lo, hi = number_bounds(number)
    if sign > 0:
        assert (lo, hi) == (sys.float_info.max, np.inf)
    else:
        assert (lo, hi) == (-np.inf, -sys.float_info.max)
    s = implc.compile(x - number)  # compiles; F - huge is below (above) every double
    f_lo, f_hi = s.interval(np.zeros((1, 3)), np.ones((1, 3)))
    assert (f_hi[0] <= -1e308) if sign > 0 else (f_lo[0] >= 1e308)  # the box is pruned, soundly


def test_a_number_too_large_to_evaluate_is_an_infinite_bound():
    """exp(exp(exp(exp(10)))) is beyond SymPy's evaluation: it is built from exp of an enclosed constant,
    whose upper bound is infinite (such a constant must not be refused or hang). F = x − it is −inf at a
    point; its enclosure over a box is the whole line (exp of an infinite bound counts as undefined), which
    keeps every cell: sound, not tight."""
    surface = implc.compile(x - sympy.exp(sympy.exp(sympy.exp(sympy.exp(10)))))
    constants = [attr for op, _, attr in surface.tape.nodes if op == "const"]
    assert [(c[1], c[2]) for c in constants] == [(sys.float_info.max, np.inf)]  # exp(exp(exp(10))), enclosed
    lo, hi = surface.interval(np.full((1, 3), -1.0), np.full((1, 3), 1.0))
    assert lo[0] == -np.inf
    assert surface.eval(np.zeros((1, 3)))[0] == -np.inf


@pytest.mark.parametrize("expr, periodic", [
    (sympy.sin(4 * theta) * sympy.sin(8 * phi) - r, True),
    (sympy.cos(3 * phi + theta) * r, True),
    (sympy.sin(3 * phi) ** 2 + sympy.tan(2 * phi), True),
    (sympy.sin(phi / 2), False),
    (phi - r, False),
    (sympy.sinh(phi**4), False),
    (sympy.sin(phi**2), False),
])
def test_periodicity_in_phi_is_structural(expr, periodic):
    assert is_periodic_in_phi(expr) is periodic


@pytest.mark.parametrize("formula", ["sinh(phi**4)", "cosh(phi**4)", "sinh(cosh(sin(2*atan(phi))))"])
def test_periodicity_detection_never_hangs(formula, tmp_path):
    """These hung for minutes in SymPy's expand_trig; the structural test answers at once."""
    proc = subprocess.run([sys.executable, "-m", "implc", "voxelize", "--expr", formula, "--depth", "5", "--quiet",
                           "-o", str(tmp_path / "h.npz")], capture_output=True, text=True, timeout=60)
    assert proc.returncode == 0, proc.stderr


def test_messages_about_huge_integers_still_print():
    """An exponent or a constant with more digits than Python prints (4,300) is named, not a ValueError."""
    huge = sympy.Integer(2) ** 20000
    with pytest.raises(CompileError, match=r"the exponent (<a Integer too large to print>|\d+\.\.\.) of x is "
                                           "beyond ±65536"):  # cut, or named where Python may not print it
        implc.compile(x ** (huge + 1) + x)
