"""Every rejection path raises its error with a message that names the problem."""

import numpy as np
import pytest
import sympy

import implc
from implc import CompileError, x, y, z


@pytest.mark.parametrize("expr, message", [
    (sympy.besselj(0, x), "unsupported function besselj(0, x)"),
    (sympy.Function("f")(x), "unsupported function f(x)"),
    (x + sympy.Symbol("w"), "unknown symbol w"),
    (x + sympy.I * y, "complex"),
    (x + sympy.I, "complex"),
    (sympy.gamma(x), "unsupported function gamma(x)"),
    (sympy.floor(x), "unsupported function floor(x)"),
    (x + sympy.oo, "non-finite"),
    (x + sympy.zoo, "non-finite"),
    (sympy.Integral(x, y), "unsupported expression"),
    (sympy.Piecewise((x, sympy.Contains(y, sympy.Interval(0, 1))), (y, True)), "unsupported Piecewise condition"),
    (x < y, "real-valued expression"),
])
def test_unsupported_input_is_named(expr, message):
    with pytest.raises(CompileError, match=message.replace("(", r"\(").replace(")", r"\)")):
        implc.compile(expr)


def test_compile_error_is_a_value_error():
    assert issubclass(CompileError, ValueError)


@pytest.mark.parametrize("bad", ["x**2 - 1", 3.0, None, [x, y]])
def test_non_sympy_argument_is_a_type_error(bad):
    with pytest.raises(TypeError, match="expects a SymPy expression"):
        implc.compile(bad)


@pytest.mark.parametrize("bounds, message", [
    (((-1, 1), (-1, 1)), "three"),
    (((-1, 1), (-1, 1), (-1, 1), (0, 1)), "three"),
    (((-1, 1), (-1, 1), (1, 1)), "z bounds .* lo < hi"),
    (((2, 1), (-1, 1), (-1, 1)), "x bounds .* lo < hi"),
    (((-1, 1), (-np.inf, 1), (-1, 1)), "y bounds .* not finite"),
    (((-1, 1), (-1, float("nan")), (-1, 1)), "not finite"),
    (((-1, 1), ("a", 1), (-1, 1)), "not numbers"),
    ((1, 2, 3), "three"),
    (5, "three"),
    (((-1e308, 1e308), (-1, 1), (-1, 1)), "x bounds .* too far apart"),
    (((-1, 1), (0, 1e-310), (-1, 1)), "y bounds .* too close"),
])
def test_bad_bounds_are_named(bounds, message):
    with pytest.raises(CompileError, match=message):
        implc.compile(x + y, bounds=bounds)


def test_bad_vector_width_is_named():
    with pytest.raises(CompileError, match="vector_width must be one of"):
        implc.compile(x + y, vector_width=3)


def test_bad_arrays_are_named():
    s = implc.compile(x**2 + y**2 + z**2 - 1)
    with pytest.raises(ValueError, match=r"points must be an \(N, 3\) array"):
        s.eval(np.zeros((4, 2)))
    with pytest.raises(ValueError, match="lo > hi"):
        s.interval(np.ones((3, 3)), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="differ in shape"):
        s.interval(np.zeros((3, 3)), np.zeros((4, 3)))


def test_empty_batches():
    s = implc.compile(x - y)
    assert s.eval(np.zeros((0, 3))).shape == (0,)
    assert s.gradient(np.zeros((0, 3))).shape == (0, 3)
    lo, hi = s.interval(np.zeros((0, 3)), np.zeros((0, 3)))
    assert lo.shape == hi.shape == (0,)
