"""The numpy reference evaluator of a tape: point values, intervals and gradients.

This is the living definition of every op. It is slow (one numpy call per node) and exists to be read
and to test the compiled kernels against, op by op.
"""

from __future__ import annotations

import numpy as np

from . import interval as I
from . import rounding as R
from .gradient import with_gradient
from .ir import Tape


def _select(g, cond, a, b):
    """The branch ``cond`` picks; undefined where the condition's value g is."""
    return np.where(np.isnan(g), np.nan, np.where(cond, a, b))


POINT_RULES = {
    "neg": np.negative, "add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide,
    "sqrt": np.sqrt, "cbrt": lambda a: np.where(a < 0, np.nan, np.cbrt(a)), "exp": np.exp, "log": np.log,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan,
    "atan2": lambda yy, xx: np.arctan2(yy + 0.0, xx + 0.0),
    "atan2_wrapped": lambda yy, xx: np.arctan2(yy + 0.0, xx + 0.0),
    "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "abs": np.abs, "min": np.minimum, "max": np.maximum,
    "select_lt": lambda g, a, b: _select(g, g < 0, a, b), "select_le": lambda g, a, b: _select(g, g <= 0, a, b),
    "cut_guard": lambda yy, xx, c: c,
}
"""Point rules of the ops without an attribute (``powi``, ``powf``, ``scale`` take theirs); float64 arrays."""


def _columns(points):
    pts = np.asarray(points, dtype=np.float64)
    return pts[:, 0], pts[:, 1], pts[:, 2]


def eval_point(tape: Tape, points) -> list[np.ndarray]:
    """Every output of ``tape`` at the (N, 3) ``points``."""
    cols = _columns(points)
    n = len(cols[0])
    vals: list = []
    with np.errstate(all="ignore"):
        for op, args, attr in tape.nodes:
            a = [vals[i] for i in args]
            if op == "const":
                v = np.full(n, attr[0])
            elif op == "var":
                v = cols[attr]
            elif op == "powi":
                v = I.powi_point(a[0], attr)
            elif op == "powf":
                v = np.power(a[0], attr)
            elif op == "scale":
                v = attr * a[0]
            else:
                v = POINT_RULES[op](*a)
            vals.append(v)
    return [vals[o] for o in tape.outputs]


def eval_interval(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the first output of ``tape`` over the boxes [lo, hi] ((N, 3) each).

    A possibly undefined result (NaN) is reported as the whole line: it never prunes.
    """
    out_lo, out_hi = _interval_outputs(tape, _columns(lo), _columns(hi))[0]
    return _whole_line_if_undefined(out_lo, out_hi)


def _interval_outputs(tape: Tape, lo_cols, hi_cols) -> list:
    n = len(lo_cols[0])
    vals: list = []
    with np.errstate(all="ignore"):
        for op, args, attr in tape.nodes:
            a = [vals[i] for i in args]
            if op == "const":
                v = (np.full(n, attr[1]), np.full(n, attr[2]))
            elif op == "var":
                v = (lo_cols[attr], hi_cols[attr])
            else:
                v = I.RULES[op](a, attr)
            vals.append(v)
    return [vals[o] for o in tape.outputs]


def _whole_line_if_undefined(lo, hi):
    undefined = np.isnan(lo) | np.isnan(hi)
    return np.where(undefined, -np.inf, lo), np.where(undefined, np.inf, hi)


def eval_interval_mean_value(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The natural enclosure intersected with the mean-value form F(c) + ∇F(B)·(B − c), c the centre.

    Sound where F is continuous on the box; the gradient enclosure is NaN wherever that is in doubt
    (an undecided select that may jump, a box across atan2's cut), and a NaN form is not used.
    """
    lo_cols, hi_cols = _columns(lo), _columns(hi)
    (nat_lo, nat_hi), *grad = _interval_outputs(with_gradient(tape), lo_cols, hi_cols)
    centre = [(a + b) * 0.5 for a, b in zip(lo_cols, hi_cols)]
    with np.errstate(all="ignore"):
        acc = _interval_outputs(tape, centre, centre)[0]
        for axis in range(3):
            offset = (I.widen_down(lo_cols[axis] - centre[axis], R.ARITH),
                      I.widen_up(hi_cols[axis] - centre[axis], R.ARITH))
            acc = I.i_add([acc, I.i_mul([grad[axis], offset], None)], None)
    usable = ~(np.isnan(acc[0]) | np.isnan(acc[1]))
    out_lo = np.where(usable, np.maximum(nat_lo, acc[0]), nat_lo)
    out_hi = np.where(usable, np.minimum(nat_hi, acc[1]), nat_hi)
    return _whole_line_if_undefined(out_lo, out_hi)


def eval_gradient(tape: Tape, points) -> tuple[np.ndarray, np.ndarray]:
    """(values (N,), gradients (N, 3)) of the single output of a value tape."""
    f, gx, gy, gz = eval_point(with_gradient(tape), points)
    return f, np.stack([gx, gy, gz], axis=1)
