"""The numpy reference: the executable specification of every op, and an evaluator of tapes over it.

Per op, side by side: a point rule (:data:`POINT_RULES`, float64 arrays) and an interval rule
(:data:`INTERVAL_RULES`). An interval rule takes the argument intervals as ``(lo, hi)`` pairs of float64
arrays, and the node's attr, and returns ``(lo, hi)`` enclosing every real value of the op over the
argument boxes, rounded outward per :mod:`implc.compiler.rounding`. NaN means "possibly undefined here": a domain
violation (sqrt or log of negatives, asin beyond ±1) gives NaN, NaN propagates (np.minimum/np.maximum,
never fmin/fmax), and a NaN result never prunes a box. The derivative rules live with the gradient
transform (:mod:`implc.compiler.gradient`), which works on tapes and so serves every evaluator.

The evaluators (:func:`eval_point`, :func:`eval_interval`, :func:`eval_interval_mean_value`,
:func:`eval_gradient`) are slow (one numpy call per node): they exist to be read and to test the
compiled kernels against, op by op (the LLVM emitters in :mod:`implc.compiler.llvm` mirror these rules).
"""

from __future__ import annotations

from typing import Any

import numpy as np

from . import rounding as R
from .gradient import with_gradient
from .ir import Tape


# -- point rules -------------------------------------------------------------------------------------
def _point_select(g, cond, a, b):
    """The branch ``cond`` picks; undefined where the condition's value g is."""
    return np.where(np.isnan(g), np.nan, np.where(cond, a, b))


POINT_RULES: dict[str, Any] = {
    "neg": np.negative, "add": np.add, "sub": np.subtract, "mul": np.multiply, "div": np.divide,
    "sqrt": np.sqrt, "cbrt": lambda a: np.where(a < 0, np.nan, np.cbrt(a)), "exp": np.exp, "log": np.log,
    "sin": np.sin, "cos": np.cos, "tan": np.tan, "asin": np.arcsin, "acos": np.arccos, "atan": np.arctan,
    "atan2": lambda yy, xx: np.arctan2(yy + 0.0, xx + 0.0),
    "atan2_wrapped": lambda yy, xx: np.arctan2(yy + 0.0, xx + 0.0),
    "sinh": np.sinh, "cosh": np.cosh, "tanh": np.tanh, "abs": np.abs, "min": np.minimum, "max": np.maximum,
    "select_lt": lambda g, a, b: _point_select(g, g < 0, a, b),
    "select_le": lambda g, a, b: _point_select(g, g <= 0, a, b),
    "cut_guard": lambda yy, xx, c: c,
}
"""Point rules of the ops without an attribute (``powi``, ``powf``, ``scale`` take theirs); float64 arrays."""


# -- interval rules ----------------------------------------------------------------------------------
NAN = np.nan
INF = np.inf


def widen_down(v, c, tiny=R.TINY):
    return (v - np.abs(v) * c) - tiny


def widen_up(v, c, tiny=R.TINY):
    return (v + np.abs(v) * c) + tiny


def powi_point(a, n: int):
    """a ** n by repeated squaring: the exact product sequence the compiled kernels use."""
    result = None
    base = a
    while n:
        if n & 1:
            result = base if result is None else result * base
        n >>= 1
        if n:
            base = base * base
    return result


def _monotone(f, lo, hi, c=R.LIBM, increasing=True):
    if increasing:
        return widen_down(f(lo), c), widen_up(f(hi), c)
    return widen_down(f(hi), c), widen_up(f(lo), c)


def _nan_where(mask, pair):
    lo, hi = pair
    return np.where(mask, NAN, lo), np.where(mask, NAN, hi)


def i_neg(args, attr):
    (a,) = args
    return -a[1], -a[0]


def i_add(args, nonnegative):
    a, b = args
    lo = widen_down(a[0] + b[0], R.ARITH)
    if nonnegative:  # both terms are provably >= 0 (see Tape.is_nonnegative): keeps sqrt(x² + y²) defined at 0
        lo = np.maximum(lo, 0.0)
    return lo, widen_up(a[1] + b[1], R.ARITH)


def i_scale(args, c: float):
    (a,) = args
    lo, hi = (a[0], a[1]) if c >= 0 else (a[1], a[0])
    return widen_down(c * lo, R.ARITH), widen_up(c * hi, R.ARITH)


def i_sub(args, attr):
    a, b = args
    return widen_down(a[0] - b[1], R.ARITH), widen_up(a[1] - b[0], R.ARITH)


def i_mul(args, attr):
    a, b = args
    p = (a[0] * b[0], a[0] * b[1], a[1] * b[0], a[1] * b[1])
    lo = np.minimum(np.minimum(p[0], p[1]), np.minimum(p[2], p[3]))
    hi = np.maximum(np.maximum(p[0], p[1]), np.maximum(p[2], p[3]))
    return widen_down(lo, R.ARITH), widen_up(hi, R.ARITH)


def i_div(args, attr):
    a, b = args
    # the corners holding the extremes, picked by sign before dividing (two divisions, not four; rounding
    # is monotone, so they are also the extremes of the four rounded quotients)
    positive = b[0] > 0
    lo_num, hi_num = np.where(positive, a[0], a[1]), np.where(positive, a[1], a[0])
    lo_den, hi_den = np.where(lo_num >= 0, b[1], b[0]), np.where(hi_num >= 0, b[0], b[1])
    undefined = np.isnan(a[0]) | np.isnan(a[1]) | np.isnan(b[0]) | np.isnan(b[1])
    lo = widen_down(np.where(undefined, np.nan, lo_num / lo_den), R.ARITH)
    hi = widen_up(np.where(undefined, np.nan, hi_num / hi_den), R.ARITH)
    across_zero = (b[0] <= 0) & (b[1] >= 0)
    keep_nan = (a[0] + a[1]) * 0.0  # NaN when a is (partly) undefined or unbounded
    return np.where(across_zero, -INF + keep_nan, lo), np.where(across_zero, INF + keep_nan, hi)


def i_powi(args, n: int):
    (a,) = args
    c, tiny = R.powi_slack(n), R.powi_tiny(n)
    plo, phi = powi_point(a[0], n), powi_point(a[1], n)
    if n % 2:
        return widen_down(plo, c, tiny), widen_up(phi, c, tiny)
    lo = np.maximum(widen_down(np.minimum(plo, phi), c, tiny), 0.0)
    lo = np.where((a[0] <= 0) & (a[1] >= 0), 0.0, lo)
    return lo, widen_up(np.maximum(plo, phi), c, tiny)


def i_powf(args, e: float):
    (a,) = args
    with np.errstate(all="ignore"):
        lo, hi = _monotone(lambda v: np.power(v, e), a[0], a[1], R.POWF, increasing=e > 0)
    return _nan_where(a[0] < 0, (np.maximum(lo, 0.0), hi))


def i_sqrt(args, attr):
    (a,) = args
    with np.errstate(invalid="ignore"):
        lo, hi = _monotone(np.sqrt, a[0], a[1], R.ARITH)
    return _nan_where(a[0] < 0, (np.maximum(lo, 0.0), hi))


def i_cbrt(args, attr):
    (a,) = args
    lo, hi = _monotone(np.cbrt, a[0], a[1])
    return _nan_where(a[0] < 0, (np.maximum(lo, 0.0), hi))


def i_exp(args, attr):
    (a,) = args
    lo, hi = _monotone(np.exp, a[0], a[1])
    return np.maximum(lo, 0.0), hi


def i_log(args, attr):
    (a,) = args
    with np.errstate(all="ignore"):
        return _nan_where(a[0] < 0, _monotone(np.log, a[0], a[1]))


def _contains_peak(a, b, offset, period=2 * np.pi):
    """Whether some offset + period * j lies in [a, b] (counted generously: a false yes only loosens)."""
    m = 1e-12 * (1.0 + np.abs(a) + np.abs(b))
    k = np.ceil((a - offset) / period)
    found = np.zeros(np.shape(a), dtype=bool)
    for j in (-1.0, 0.0, 1.0):
        p = offset + period * (k + j)
        found |= (p >= a - m) & (p <= b + m)
    return found


def _sin_like(f, a, max_offset, min_offset):
    lo0, hi0 = a
    with np.errstate(invalid="ignore"):
        fa, fb = f(lo0), f(hi0)
    lo = widen_down(np.minimum(fa, fb), R.LIBM)
    hi = widen_up(np.maximum(fa, fb), R.LIBM)
    hi = np.where(_contains_peak(lo0, hi0, max_offset), 1.0, np.minimum(hi, 1.0))
    lo = np.where(_contains_peak(lo0, hi0, min_offset), -1.0, np.maximum(lo, -1.0))
    full = (hi0 - lo0 >= 2 * np.pi) | (np.abs(lo0) > R.TRIG_MAX_ARG) | (np.abs(hi0) > R.TRIG_MAX_ARG)
    lo, hi = np.where(full, -1.0, lo), np.where(full, 1.0, hi)
    return _nan_where(np.isinf(lo0) | np.isinf(hi0), (lo, hi))  # sin(±inf) is undefined


def i_sin(args, attr):
    (a,) = args
    return _sin_like(np.sin, a, np.pi / 2, -np.pi / 2)


def i_cos(args, attr):
    (a,) = args
    return _sin_like(np.cos, a, 0.0, np.pi)


def i_tan(args, attr):
    (a,) = args
    with np.errstate(invalid="ignore"):
        lo, hi = _monotone(np.tan, a[0], a[1])
    pole = _contains_peak(a[0], a[1], np.pi / 2, np.pi)
    pole |= (a[1] - a[0] >= np.pi) | (np.abs(a[0]) > R.TRIG_MAX_ARG) | (np.abs(a[1]) > R.TRIG_MAX_ARG)
    lo, hi = np.where(pole, -INF, lo), np.where(pole, INF, hi)
    return _nan_where(np.isinf(a[0]) | np.isinf(a[1]), (lo, hi))  # tan(±inf) is undefined


def i_asin(args, attr):
    (a,) = args
    with np.errstate(invalid="ignore"):
        return _nan_where((a[0] < -1) | (a[1] > 1), _monotone(np.arcsin, a[0], a[1]))


def i_acos(args, attr):
    (a,) = args
    with np.errstate(invalid="ignore"):
        lo, hi = _monotone(np.arccos, a[0], a[1], increasing=False)
    return _nan_where((a[0] < -1) | (a[1] > 1), (np.maximum(lo, 0.0), hi))


def i_atan(args, attr):
    (a,) = args
    return _monotone(np.arctan, a[0], a[1])


def i_sinh(args, attr):
    (a,) = args
    with np.errstate(over="ignore"):
        return _monotone(np.sinh, a[0], a[1])


def i_tanh(args, attr):
    (a,) = args
    lo, hi = _monotone(np.tanh, a[0], a[1])
    return np.maximum(lo, -1.0), np.minimum(hi, 1.0)


def i_cosh(args, attr):
    (a,) = args
    with np.errstate(over="ignore"):
        ca, cb = np.cosh(a[0]), np.cosh(a[1])
    lo = np.maximum(widen_down(np.minimum(ca, cb), R.LIBM), 1.0)
    lo = np.where((a[0] <= 0) & (a[1] >= 0), 1.0, lo)
    return lo, widen_up(np.maximum(ca, cb), R.LIBM)


def i_abs(args, attr):
    (a,) = args
    lo = np.where(a[0] >= 0, a[0], np.where(a[1] <= 0, -a[1], 0.0))
    return lo, np.maximum(-a[0], a[1])


def i_min(args, attr):
    a, b = args
    return np.minimum(a[0], b[0]), np.minimum(a[1], b[1])


def i_max(args, attr):
    a, b = args
    return np.maximum(a[0], b[0]), np.maximum(a[1], b[1])


def _select(true_for_sure, false_for_sure, a, b, attr):
    """The decided branch, else the union of both ("jump" selects: NaN where undecided)."""
    union_lo, union_hi = np.minimum(a[0], b[0]), np.maximum(a[1], b[1])
    if attr == "jump":
        union_lo, union_hi = union_lo + NAN, union_hi + NAN
    lo = np.where(true_for_sure, a[0], np.where(false_for_sure, b[0], union_lo))
    hi = np.where(true_for_sure, a[1], np.where(false_for_sure, b[1], union_hi))
    return lo, hi


def _undecidable(g, pair):
    """A condition that may be undefined (NaN) somewhere in the box makes the select's value undefined."""
    undefined = np.isnan(g[0]) | np.isnan(g[1])
    return np.where(undefined, NAN, pair[0]), np.where(undefined, NAN, pair[1])


def i_select_lt(args, attr):
    g, a, b = args
    return _undecidable(g, _select(g[1] < 0, g[0] >= 0, a, b, attr))


def i_select_le(args, attr):
    g, a, b = args
    return _undecidable(g, _select(g[1] <= 0, g[0] > 0, a, b, attr))


def straddles_cut(yy, xx):
    """Boxes crossing atan2's branch cut (x < 0, y from below 0 to 0 or above)."""
    return (xx[1] < 0) & (yy[0] + 0.0 < 0) & (yy[1] + 0.0 >= 0)


def i_cut_guard(args, attr):
    yy, xx, c = args
    return _nan_where(straddles_cut(yy, xx), c)


def _atan2(yy, xx, wrapped: bool):
    y0, y1 = yy[0] + 0.0, yy[1] + 0.0  # + 0.0 turns -0.0 into +0.0: atan2(-0.0, x < 0) would be -pi
    x0, x1 = xx
    corners = [np.arctan2(yv, xv) for yv in (y0, y1) for xv in (x0, x1)]
    lo = widen_down(np.minimum(np.minimum(corners[0], corners[1]), np.minimum(corners[2], corners[3])), R.LIBM)
    hi = widen_up(np.maximum(np.maximum(corners[0], corners[1]), np.maximum(corners[2], corners[3])), R.LIBM)
    lo, hi = np.maximum(lo, -R.PI_HI), np.minimum(hi, R.PI_HI)
    origin = (x0 <= 0) & (x1 >= 0) & (y0 <= 0) & (y1 >= 0)
    cut = straddles_cut(yy, xx)
    if wrapped:
        cut_lo = widen_down(np.arctan2(y1, x1), R.LIBM)
        cut_hi = widen_up(R.TWO_PI_HI + widen_up(np.arctan2(y0, x1), R.LIBM), R.ARITH)
    else:
        cut_lo, cut_hi = -R.PI_HI, R.PI_HI
    lo = np.where(cut, cut_lo, lo)
    hi = np.where(cut, cut_hi, hi)
    lo = np.where(origin, np.where(y0 >= 0, 0.0, -R.PI_HI), lo)
    hi = np.where(origin, R.PI_HI, hi)
    return lo, hi


def i_atan2(args, attr):
    yy, xx = args
    return _atan2(yy, xx, wrapped=False)


def i_atan2_wrapped(args, attr):
    yy, xx = args
    return _atan2(yy, xx, wrapped=True)


INTERVAL_RULES = {
    "neg": i_neg, "scale": i_scale, "powi": i_powi, "powf": i_powf, "add": i_add, "sub": i_sub, "mul": i_mul,
    "div": i_div, "sqrt": i_sqrt, "cbrt": i_cbrt, "exp": i_exp, "log": i_log, "sin": i_sin, "cos": i_cos, "tan": i_tan,
    "asin": i_asin, "acos": i_acos,
    "atan": i_atan, "atan2": i_atan2, "atan2_wrapped": i_atan2_wrapped, "sinh": i_sinh, "cosh": i_cosh,
    "tanh": i_tanh, "abs": i_abs, "min": i_min, "max": i_max, "select_lt": i_select_lt,
    "select_le": i_select_le, "cut_guard": i_cut_guard,
}
"""One interval rule per op: (argument intervals, the node's attr) -> (lo, hi)."""


# -- evaluators --------------------------------------------------------------------------------------
def _columns(points):
    pts = np.asarray(points, dtype=np.float64)
    return pts[:, 0], pts[:, 1], pts[:, 2]


def eval_point(tape: Tape, points) -> list[np.ndarray]:
    """Every output of ``tape`` at the (N, 3) ``points``."""
    vals = point_nodes(tape, points)
    return [vals[o] for o in tape.outputs]


def point_nodes(tape: Tape, points) -> list[np.ndarray]:
    """The value of every node of ``tape`` at the (N, 3) ``points``, in tape order."""
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
                v = powi_point(a[0], attr)
            elif op == "powf":
                v = np.power(a[0], attr)
            elif op == "scale":
                v = attr * a[0]
            else:
                v = POINT_RULES[op](*a)
            vals.append(v)
    return vals


def eval_interval(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """Enclosure of the first output of ``tape`` over the boxes [lo, hi] ((N, 3) each).

    A possibly undefined result (NaN) is reported as the whole line: it never prunes.
    """
    out_lo, out_hi = _interval_outputs(tape, _columns(lo), _columns(hi))[0]
    return _whole_line_if_undefined(out_lo, out_hi)


def _interval_outputs(tape: Tape, lo_cols, hi_cols) -> list:
    vals = _interval_nodes(tape, lo_cols, hi_cols)
    return [vals[o] for o in tape.outputs]


def interval_nodes(tape: Tape, lo, hi) -> list[tuple[np.ndarray, np.ndarray]]:
    """The enclosure of every node of ``tape`` over the boxes [lo, hi], in tape order (NaN kept)."""
    return _interval_nodes(tape, _columns(lo), _columns(hi))


def _interval_nodes(tape: Tape, lo_cols, hi_cols) -> list:
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
                v = INTERVAL_RULES[op](a, attr)
            vals.append(v)
    return vals


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
            offset = (widen_down(lo_cols[axis] - centre[axis], R.ARITH),
                      widen_up(hi_cols[axis] - centre[axis], R.ARITH))
            acc = i_add([acc, i_mul([grad[axis], offset], None)], None)
    usable = ~(np.isnan(acc[0]) | np.isnan(acc[1]))
    out_lo = np.where(usable, np.maximum(nat_lo, acc[0]), nat_lo)
    out_hi = np.where(usable, np.minimum(nat_hi, acc[1]), nat_hi)
    return _whole_line_if_undefined(out_lo, out_hi)


def eval_interval_monotone(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The natural enclosure intersected with the monotonicity form (:func:`monotone_bounds`), dropped
    where the form is NaN."""
    nat_lo, nat_hi = eval_interval_natural_nan(tape, lo, hi)
    form_lo, form_hi = monotone_bounds(tape, lo, hi)
    usable = ~(np.isnan(form_lo) | np.isnan(form_hi))
    out_lo = np.where(usable, np.maximum(nat_lo, form_lo), nat_lo)
    out_hi = np.where(usable, np.minimum(nat_hi, form_hi), nat_hi)
    return _whole_line_if_undefined(out_lo, out_hi)


def eval_interval_natural_nan(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The natural enclosure of the first output over the boxes, NaN kept (as the gradient tape's first
    output gives it)."""
    return _interval_outputs(with_gradient(tape), _columns(lo), _columns(hi))[0]


def monotone_bounds(tape: Tape, lo, hi) -> tuple[np.ndarray, np.ndarray]:
    """The monotonicity form's two bounds over each box (NaN where it is undefined): per axis where
    ∇ₐF(B) ≥ 0 the lower bound is taken on the box's low face and the upper on its high face (where
    ∇ₐF(B) ≤ 0 the other way round), the axis adding nothing; the other axes add ∇ₐF(B)·(Bₐ − cₐ) from the
    centre, as the mean-value form. So lower = F(c⁻) + Σ lowₐ, upper = F(c⁺) + Σ highₐ, c⁻ and c⁺ the
    corners (or centre coordinates) that choice gives. Sound under the mean-value form's conditions (F
    continuous on the box, its gradient's enclosure NaN wherever that is in doubt), and only where every
    partial's enclosure is finite (F Lipschitz on the box: a pole inside it makes the form NaN)."""
    lo_cols, hi_cols = _columns(lo), _columns(hi)
    _, *grad = _interval_outputs(with_gradient(tape), lo_cols, hi_cols)
    centre = [(a + b) * 0.5 for a, b in zip(lo_cols, hi_cols)]
    least, most, lower, upper = [], [], [], []
    with np.errstate(all="ignore"):
        for axis in range(3):
            rising, falling = grad[axis][0] >= 0, grad[axis][1] <= 0
            monotone = rising | falling
            bounded = (np.abs(grad[axis][0]) < np.inf) & (np.abs(grad[axis][1]) < np.inf)  # F Lipschitz on B
            least.append(np.where(rising, lo_cols[axis], np.where(falling, hi_cols[axis], centre[axis])))
            most.append(np.where(rising, hi_cols[axis], np.where(falling, lo_cols[axis], centre[axis])))
            offset = (widen_down(lo_cols[axis] - centre[axis], R.ARITH),
                      widen_up(hi_cols[axis] - centre[axis], R.ARITH))
            term_lo, term_hi = i_mul([grad[axis], offset], None)
            lower.append(np.where(bounded, np.where(monotone, 0.0, term_lo), np.nan))
            upper.append(np.where(bounded, np.where(monotone, 0.0, term_hi), np.nan))
        acc_lo = _interval_outputs(tape, least, least)[0][0]
        acc_hi = _interval_outputs(tape, most, most)[0][1]
        for axis in range(3):
            acc_lo = widen_down(acc_lo + lower[axis], R.ARITH)
            acc_hi = widen_up(acc_hi + upper[axis], R.ARITH)
    return acc_lo, acc_hi


def eval_gradient(tape: Tape, points) -> tuple[np.ndarray, np.ndarray]:
    """(values (N,), gradients (N, 3)) of the single output of a value tape."""
    f, gx, gy, gz = eval_point(with_gradient(tape), points)
    return f, np.stack([gx, gy, gz], axis=1)
