"""The analytic gradient: extends a tape with the derivative of its output along x, y and z.

Forward mode over the tape: each node gets three derivative nodes built from one rule per op, on the
same hash-consed tape, so the gradient shares every subexpression with the value (cos(u) of a sin(u)
node, the quotient of a division, ...). The result has outputs ``[F, dF/dx, dF/dy, dF/dz]``.
"""

from __future__ import annotations

from fractions import Fraction

from .ir import Tape


def _d_neg(t, f, a, attr, d):
    return t.neg(d[0])


def _d_scale(t, f, a, attr, d):
    return t.scale(d[0], attr)


def _d_add(t, f, a, attr, d):
    return t.add(d[0], d[1])


def _d_sub(t, f, a, attr, d):
    return t.sub(d[0], d[1])


def _d_mul(t, f, a, attr, d):
    return t.add(t.mul(d[0], a[1]), t.mul(a[0], d[1]))


def _d_div(t, f, a, attr, d):  # (du - f dv) / v
    return t.div(t.sub(d[0], t.mul(f, d[1])), a[1])


def _d_powi(t, f, a, attr, d):
    return t.mul(t.mul(t.const(attr), t.powi(a[0], attr - 1)), d[0])


def _d_powf(t, f, a, attr, d):
    e = attr - 1.0
    lower = t.const(1) if e == 0 else t.node("powf", (a[0],), e)
    return t.mul(t.mul(t.const(Fraction(attr)), lower), d[0])


def _d_sqrt(t, f, a, attr, d):
    return t.div(d[0], t.mul(t.const(2), f))


def _d_cbrt(t, f, a, attr, d):
    return t.div(d[0], t.mul(t.const(3), t.powi(f, 2)))


def _d_exp(t, f, a, attr, d):
    return t.mul(f, d[0])


def _d_log(t, f, a, attr, d):
    return t.div(d[0], a[0])


def _d_sin(t, f, a, attr, d):
    return t.mul(t.unary("cos", a[0]), d[0])


def _d_cos(t, f, a, attr, d):
    return t.neg(t.mul(t.unary("sin", a[0]), d[0]))


def _d_tan(t, f, a, attr, d):
    return t.mul(t.add(t.const(1), t.powi(f, 2)), d[0])


def _one_minus_square_root(t, u):
    return t.unary("sqrt", t.sub(t.const(1), t.powi(u, 2)))


def _d_asin(t, f, a, attr, d):
    return t.div(d[0], _one_minus_square_root(t, a[0]))


def _d_acos(t, f, a, attr, d):
    return t.neg(t.div(d[0], _one_minus_square_root(t, a[0])))


def _d_atan(t, f, a, attr, d):
    return t.div(d[0], t.add(t.const(1), t.powi(a[0], 2)))


def _d_atan2_wrapped(t, f, a, attr, d):  # d atan2(p, q) = (q dp - p dq) / (p² + q²)
    p, q = a
    return t.div(t.sub(t.mul(q, d[0]), t.mul(p, d[1])), t.add(t.powi(p, 2), t.powi(q, 2)))


def _d_atan2(t, f, a, attr, d):
    """As the wrapped form, guarded: the value jumps by 2π across the cut, where no derivative bounds it."""
    return t.node("cut_guard", (a[0], a[1], _d_atan2_wrapped(t, f, a, attr, d)))


def _d_cut_guard(t, f, a, attr, d):
    return t.node("cut_guard", (a[0], a[1], d[2]))


def _d_sinh(t, f, a, attr, d):
    return t.mul(t.unary("cosh", a[0]), d[0])


def _d_cosh(t, f, a, attr, d):
    return t.mul(t.unary("sinh", a[0]), d[0])


def _d_tanh(t, f, a, attr, d):
    return t.mul(t.sub(t.const(1), t.powi(f, 2)), d[0])


def _d_abs(t, f, a, attr, d):
    return t.node("select_lt", (a[0], t.neg(d[0]), d[0]))


def _d_min(t, f, a, attr, d):
    return t.node("select_le", (t.sub(a[0], a[1]), d[0], d[1]))


def _d_max(t, f, a, attr, d):
    return t.node("select_le", (t.sub(a[0], a[1]), d[1], d[0]))


def _d_select(op):
    def rule(t, f, a, attr, d):
        # a possibly discontinuous select's derivative is unusable where the condition is undecided
        return t.node(op, (a[0], d[1], d[2]), None if attr == "continuous" else "jump")
    return rule


DERIVATIVE_RULES = {
    "neg": _d_neg, "scale": _d_scale, "add": _d_add, "sub": _d_sub, "mul": _d_mul, "div": _d_div, "powi": _d_powi,
    "powf": _d_powf, "sqrt": _d_sqrt, "cbrt": _d_cbrt, "exp": _d_exp, "log": _d_log, "sin": _d_sin,
    "cos": _d_cos, "tan": _d_tan, "asin": _d_asin, "acos": _d_acos, "atan": _d_atan, "atan2": _d_atan2,
    "atan2_wrapped": _d_atan2_wrapped, "cut_guard": _d_cut_guard, "sinh": _d_sinh, "cosh": _d_cosh, "tanh": _d_tanh,
    "abs": _d_abs,
    "min": _d_min, "max": _d_max, "select_lt": _d_select("select_lt"), "select_le": _d_select("select_le"),
}
"""One derivative rule per op: (tape, node, args, attr, derivatives of args) -> derivative node."""


def with_gradient(tape: Tape) -> Tape:
    """A new tape with outputs [F, dF/dx, dF/dy, dF/dz] for the single output F of ``tape``.

    A node's partial along an axis its value does not depend on is the constant 0, not its rule's: the rule
    would compute 0 there too, but NaN where it multiplies that 0 by an infinity or divides it by 0 (the
    spherical scenes' rho = sqrt(x² + y²) along z: 0 / (2·rho), NaN on the z axis; phi's atan2 along z,
    unbounded across its cut). Such a node is constant along the axis wherever it is defined, so its
    partial there is 0 exactly; the rule's arithmetic was work for nothing (the spherical scenes' gradient
    tapes 71 -> 68 nodes, the second look's monotonicity bound over a box about a third cheaper) that also
    left that bound NaN over every box on the axis. The tape engine's dual numbers and interval
    gradients zero the same partials (:attr:`implc.engines.tape.program.TapeProgram.zeros`), bit for bit the same
    (tests/test_conformance.py)."""
    if len(tape.outputs) != 1:
        raise ValueError("with_gradient expects a tape with one output")
    out = Tape()
    remap: list[int] = []  # original node -> node of the new tape
    derivs: dict[int, tuple[int, int, int]] = {}  # node of the new tape -> its three derivatives
    for op, args, attr in tape.nodes:
        new_args = tuple(remap[a] for a in args)
        i = out.node(op, new_args, attr)
        remap.append(i)
        if i in derivs:
            continue
        if op == "const":
            derivs[i] = (out.const(0),) * 3
        elif op == "var":
            derivs[i] = (out.const(int(attr == 0)), out.const(int(attr == 1)), out.const(int(attr == 2)))
        else:
            rule = DERIVATIVE_RULES[op]
            axes = out.axes()[i]
            dx, dy, dz = (rule(out, i, new_args, attr, [derivs[a][k] for a in new_args]) if axes >> k & 1
                          else out.const(0) for k in range(3))
            derivs[i] = (dx, dy, dz)
    f = remap[tape.outputs[0]]
    out.outputs = [f, *derivs[f]]
    out = out.compacted()
    out.verify()
    return out
