"""The tape: sharing on insert, exact folding, printing, verification, the gradient's reuse of nodes."""

import pytest
import sympy

from implc.compiler.gradient import with_gradient
from implc.compiler.ir import Tape
from implc.compiler.lower import is_periodic_in_phi, lower
from implc.compiler.symbols import phi, r, theta, x, y, z


def ops(tape):
    return [op for op, _, _ in tape.nodes]


def test_common_subexpressions_are_shared():
    t = lower(sympy.sin(x * y) + sympy.sin(x * y) ** 2 + sympy.cos(y * x))
    assert ops(t).count("mul") == 1
    assert ops(t).count("sin") == 1


def test_commutative_operands_share_a_node():
    t = Tape()
    a, b = t.var(0), t.var(1)
    assert t.add(a, b) == t.add(b, a)
    assert t.node("min", (a, b)) == t.node("min", (b, a))
    assert t.sub(a, b) != t.sub(b, a)


def test_exact_folding_only():
    t = Tape()
    a = t.var(0)
    assert t.add(a, t.const(0)) == a
    assert t.mul(a, t.const(1)) == a
    assert t.exact_value(t.add(t.const(1), t.const(2))) == 3
    third = t.const_bounds(1 / 3, 0.333333333333333314829616256247,
                           0.33333333333333337034076748750521801412105560302734375)
    assert t.exact_value(third) is None  # an inexact constant is never folded
    square = t.mul(a, a)
    assert t.nodes[square][0] == "powi"  # x * x is a (tight) square


def test_spherical_symbols_share_their_pieces():
    t = lower(r + theta + phi)
    assert ops(t).count("sqrt") == 2  # r and rho
    assert ops(t).count("powi") == 3  # x², y², z² once each
    assert ops(t).count("atan2") == 2  # theta and phi (not periodic here)


def test_phi_wraps_only_when_periodic():
    assert is_periodic_in_phi(sympy.sin(8 * phi) * sympy.sin(4 * theta) - r)
    assert is_periodic_in_phi(sympy.cos(3 * phi + 1) + sympy.sin(phi) ** 2)
    assert not is_periodic_in_phi(phi - 1)
    assert not is_periodic_in_phi(sympy.sin(phi / 2))
    assert "atan2_wrapped" in ops(lower(sympy.sin(8 * phi) - r))
    assert "atan2_wrapped" not in ops(lower(phi * x - r))


def test_printer_and_verifier():
    t = lower(sympy.exp(x) - sympy.Rational(1, 3) * y)
    text = str(t)
    assert "%0 = x" in text and "exp" in text and "return" in text
    assert "in [-0.33333333333333337, -0.3333333333333333]" in text  # inexact constants print with their enclosure
    t.verify()
    t.nodes.append(("add", (0, 99), None))
    with pytest.raises(AssertionError, match="defined before use"):
        t.verify()


def test_gradient_shares_the_value_nodes():
    value = lower(sympy.sin(x * y) * z)
    grad = with_gradient(value)
    assert ops(grad).count("sin") == 1 and ops(grad).count("cos") == 1
    assert len(grad.outputs) == 4


def test_a_partial_along_an_axis_the_value_ignores_is_zero():
    """sin(8·phi) with phi = atan2(y, x) does not depend on z: its z-partial is the constant 0, not the
    chain rule's 0 / (x² + y²), which is work, and NaN over a box on the z-axis. With the compiled kernels,
    over such a box, the z-partial of sin(8·phi) + z is exactly 1."""
    import implc
    grad = with_gradient(lower(sympy.sin(8 * phi) + z))
    assert grad.nodes[grad.outputs[3]] == ("const", (), (1.0, 1.0, 1.0))  # d/dz: the z term's 1 alone
    s = implc.compile(sympy.sin(8 * phi) + z, engine="jit")
    enclosures = s.gradient_enclosures([[-0.1, -0.1, 0.4]], [[0.1, 0.1, 0.6]])[0]
    assert enclosures[6] == enclosures[7] == 1.0  # the z-partial over a box around the z-axis


def test_partials_along_ignored_axes_are_zero_on_every_evaluator():
    """rho = sqrt(x² + y²) does not depend on z: on the z axis, where the chain rule's 0 / (2·rho) is NaN,
    the z-partial of F = rho + z − 1/2 is exactly 1 (F(0, 0, z) = z − 1/2) and its x- and y-partials are
    undefined (a cone's tip): so in the gradient tape, in the compiled kernels' and the tape engine's
    gradients at points on the axis, and in both engines' interval gradients over a box around it (the
    derivative along (0, 0, 2) there: exactly 2)."""
    import numpy as np

    import implc
    expr = sympy.sqrt(x**2 + y**2) + z - sympy.Rational(1, 2)
    grad = with_gradient(lower(expr))
    assert grad.nodes[grad.outputs[3]] == ("const", (), (1.0, 1.0, 1.0))
    points = np.array([[0.0, 0.0, 0.3], [0.0, 0.0, -0.7]])
    lo, hi = np.array([[-0.1, -0.1, 0.4]]), np.array([[0.1, 0.1, 0.6]])
    for engine in ("jit", "tape"):
        s = implc.compile(expr, engine=engine)
        value, gradient = s.value_and_gradient(points)
        assert list(value) == [-0.2, -1.2] and list(gradient[:, 2]) == [1.0, 1.0], engine
        assert np.isnan(gradient[:, :2]).all(), engine
        enclosures = s.gradient_enclosures(lo, hi)[0]
        assert enclosures[6] == enclosures[7] == 1.0, engine
        if engine == "tape":  # derivatives along directions: the engine's
            along = s.gradient_enclosures(lo, hi, directions=np.array([[0.0, 0.0, 2.0], [1, 0, 0], [0, 1, 0]]))[0]
            assert along[2] == along[3] == 2.0


def test_nonnegative_analysis():
    t = lower(x**2 + y**2 + z**2)
    assert t.is_nonnegative(t.outputs[0])
    add_node = t.nodes[t.outputs[0]]
    assert add_node[0] == "add" and add_node[2] is True
    t2 = lower(x**2 - y**2)
    assert not t2.is_nonnegative(t2.outputs[0])


def test_fingerprint_is_stable_and_distinguishes():
    assert lower(x + y).fingerprint() == lower(y + x).fingerprint()
    assert lower(x + y).fingerprint() != lower(x - y).fingerprint()
