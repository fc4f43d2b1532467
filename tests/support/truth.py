"""Ground truth for the tests: exact-enough values of an expression (mpmath at 40 digits) and test boxes."""

from __future__ import annotations

import signal
import sys

import mpmath
import numpy as np
import sympy

from implc.compiler.symbols import cartesian_form, x, y, z

from . import vm_sampling

DPS = 40
TRUTH_SECONDS = 2.0
"""Budget for one 40-digit evaluation. mpmath can take minutes (or overflow Python's integers) on rare
random expressions such as exp(exp(exp(x))), whose values have exponents of millions of digits; the
check of such an expression stops there ("slow"): the oracle, not implc, is the limit."""


sys.set_int_max_str_digits(0)  # lambdify prints the expression: random ones hold integers of 10^4 digits


class _TooSlow(Exception):
    pass


def _alarm(signum, frame):
    raise _TooSlow


class TrueValues:
    """F evaluated in high precision at float64 points; None where F is undefined (complex, NaN)."""

    def __init__(self, expr):
        self.cart = cartesian_form(expr)
        self.fn = sympy.lambdify((x, y, z), self.cart, modules="mpmath")

    def at(self, point):
        """The value at ``point``; "pole", None (undefined) or "slow" (over :data:`TRUTH_SECONDS`)."""
        previous = signal.signal(signal.SIGALRM, _alarm)
        signal.setitimer(signal.ITIMER_REAL, TRUTH_SECONDS)
        try:
            return self._at(point)
        except (_TooSlow, OverflowError):  # OverflowError: Python refuses an integer of >4300 digits
            return "slow"
        finally:
            signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, previous)

    def _at(self, point):
        """The value at DPS digits, certified by an evaluation at twice as many agreeing with it (else the
        precision doubles again: a huge constant inside a periodic function, sin(pi**64), loses its leading
        digits to the argument's size); "slow" where no two agree by 16 times DPS."""
        previous = None
        for digits in (DPS, 2 * DPS, 4 * DPS, 8 * DPS, 16 * DPS):
            v = self._at_digits(point, digits)
            if not isinstance(v, mpmath.mpf):
                return v
            if previous is not None and abs(v - previous) <= mpmath.mpf(10) ** (-DPS + 5) * (1 + abs(v)):
                return v
            previous = v
        return "slow"

    def _at_digits(self, point, digits):
        with mpmath.workdps(digits):
            try:
                v = self.fn(*[mpmath.mpf(float(c)) for c in point])
            except ZeroDivisionError:
                return "pole"
            except (TypeError, ValueError, AttributeError):
                return None  # a complex intermediate reached a real-only function or comparison
            if isinstance(v, mpmath.mpc):
                if abs(v.imag) > mpmath.mpf(10) ** (-digits + 5) * (1 + abs(v.real)):
                    return None
                v = v.real
            v = mpmath.mpf(v)
            if mpmath.isnan(v):
                return None
            return v

    def gradient(self, point, h=mpmath.mpf(10) ** -18):
        """Central differences at 40 digits (accurate to ~1e-20 away from kinks); None where undefined."""
        out = []
        with mpmath.workdps(DPS):
            base = [mpmath.mpf(float(c)) for c in point]
            for axis in range(3):
                up, down = list(base), list(base)
                up[axis] += h
                down[axis] -= h
                f_up, f_down = self.fn(*up), self.fn(*down)
                if isinstance(f_up, mpmath.mpc) or isinstance(f_down, mpmath.mpc):
                    return None
                out.append(float((mpmath.mpf(f_up) - mpmath.mpf(f_down)) / (2 * h)))
        return np.array(out)


def adversarial_boxes(rng, n):
    """(lo, hi) arrays of n boxes: ordinary ones plus boxes touching or straddling the axes, the origin and
    the phi branch cut (x < 0, y across 0), tiny (1e-9) and large ones."""
    kinds = rng.integers(0, 7, n)
    center = rng.uniform(-1.5, 1.5, (n, 3))
    width = 10.0 ** rng.uniform(-3, 0.3, (n, 3))
    lo, hi = center - width / 2, center + width / 2
    for i, kind in enumerate(kinds):
        if kind == 1:  # touches an axis plane from one side
            axis = rng.integers(0, 3)
            if rng.random() < 0.5:
                lo[i, axis], hi[i, axis] = 0.0, width[i, axis]
            else:
                lo[i, axis], hi[i, axis] = -width[i, axis], 0.0
        elif kind == 2:  # contains the origin
            lo[i], hi[i] = -width[i] * rng.uniform(0.1, 0.9, 3), width[i] * rng.uniform(0.1, 0.9, 3)
        elif kind == 3:  # straddles the phi cut: x < 0, y across 0 (or touching it from below)
            lo[i, 0], hi[i, 0] = -1.2, -rng.uniform(0.01, 0.5)
            lo[i, 1] = -rng.uniform(0.01, 0.5)
            hi[i, 1] = 0.0 if rng.random() < 0.3 else rng.uniform(0.01, 0.5)
        elif kind == 4:  # tiny
            hi[i] = lo[i] + 1e-9
        elif kind == 5:  # large
            lo[i], hi[i] = center[i] * 100 - 300, center[i] * 100 + 300
        elif kind == 6:  # straddles the z axis (theta's singular line)
            lo[i, :2], hi[i, :2] = -width[i, :2] / 2, width[i, :2] / 2
    return lo, hi


def sample_points(rng, lo, hi, per_box):
    """Corners and random points of each box: (n, per_box + 8, 3)."""
    n = len(lo)
    corners = np.array([[(i >> a) & 1 for a in range(3)] for i in range(8)], dtype=float)
    t = np.concatenate([np.broadcast_to(corners, (n, 8, 3)), rng.random((n, per_box, 3))], axis=1)
    pts = lo[:, None, :] + t * (hi - lo)[:, None, :]
    return np.minimum(np.maximum(pts, lo[:, None, :]), hi[:, None, :])


def assert_encloses(surface, expr, lo, hi, rng, per_box=6, **form):
    """Every true value of expr at sampled points of each box lies in surface.interval of that box (with
    ``form``: e.g. mean_value=True); where the true value is undefined, the enclosure must be the whole
    line."""
    f_lo, f_hi = surface.interval(lo, hi, **form)
    truth = TrueValues(expr)
    pts = sample_points(rng, lo, hi, per_box)
    for i in range(len(lo)):
        for p in pts[i]:
            v = truth.at(p)
            if v == "slow":  # the oracle, not implc, is the limit here: the points checked so far stand
                return
            if v == "pole":
                continue
            if v is None:
                assert f_lo[i] == -np.inf and f_hi[i] == np.inf, (
                    f"{expr}: undefined at {p.tolist()} but box {lo[i].tolist()}..{hi[i].tolist()} "
                    f"gives [{f_lo[i]!r}, {f_hi[i]!r}]")
                continue
            assert mpmath.mpf(f_lo[i]) <= v <= mpmath.mpf(f_hi[i]), (
                f"{expr}: F({p.tolist()}) = {mpmath.nstr(v, 20)} outside [{f_lo[i]!r}, {f_hi[i]!r}] "
                f"for box {lo[i].tolist()}..{hi[i].tolist()}")


def corner_sign_changes(f: np.ndarray) -> np.ndarray:
    """The cells of a grid whose eight corner values ``f`` ((n + 1)³, computed by the caller without
    implc's compiler) change sign, touch 0 or include NaN: the cells a sound voxelization must keep (the
    same rule the benchmarks count peer models' cells with)."""
    return vm_sampling.sign_change_cells(f)
