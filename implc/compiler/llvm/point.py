"""Point emitter: a tape becomes straight-line vector code computing its outputs at W points at once.

Mirrors :data:`implc.compiler.reference.POINT_RULES` op for op (same product order for powers, same NaN rules).
"""

from __future__ import annotations

from . import elementary
from .vector import VectorBuilder

_LIBM_UNARY = {"exp": "exp", "log": "log", "sin": "sin", "cos": "cos", "tan": "tan", "asin": "asin",
               "acos": "acos", "atan": "atan", "sinh": "sinh", "cosh": "cosh", "tanh": "tanh"}


def powi(vb: VectorBuilder, a, n: int):
    """a ** n by repeated squaring, the product order of :func:`implc.compiler.reference.powi_point`."""
    result = None
    base = a
    while n:
        if n & 1:
            result = base if result is None else vb.mul(result, base)
        n >>= 1
        if n:
            base = vb.mul(base, base)
    return result


def _point(vb: VectorBuilder, op: str, a: list, attr, vector_elementary: bool):
    if op == "neg":
        return vb.neg(a[0])
    if op in ("add", "sub", "mul", "div"):
        return getattr(vb, op)(a[0], a[1])
    if op == "scale":
        return vb.mul(vb.splat(attr), a[0])
    if op == "powi":
        return powi(vb, a[0], attr)
    if op == "powf":
        return vb.libm("pow", a[0], vb.splat(attr))
    if op == "sqrt":
        return vb.sqrt(a[0])
    if op == "cbrt":
        return vb.select(vb.cmp("<", a[0], vb.splat(0.0)), vb.splat(float("nan")), vb.libm("cbrt", a[0]))
    if vector_elementary and op in ("sin", "cos", "exp", "log"):
        return getattr(elementary, op)(vb, a[0])
    if op in _LIBM_UNARY:
        return vb.libm(_LIBM_UNARY[op], a[0])
    if op in ("atan2", "atan2_wrapped"):
        zero = vb.splat(0.0)
        y, x = vb.add(a[0], zero), vb.add(a[1], zero)
        return elementary.atan2(vb, y, x) if vector_elementary else vb.libm("atan2", y, x)
    if op == "abs":
        return vb.fabs(a[0])
    if op == "min":
        return vb.minimum(a[0], a[1])
    if op == "max":
        return vb.maximum(a[0], a[1])
    if op in ("select_lt", "select_le"):  # undefined where the condition's value is
        chosen = vb.select(vb.cmp("<" if op == "select_lt" else "<=", a[0], vb.splat(0.0)), a[1], a[2])
        return vb.select(vb.isnan(a[0]), vb.splat(float("nan")), chosen)
    if op == "cut_guard":
        return a[2]
    raise NotImplementedError(f"no point emitter for op {op}")


def emit_point(vb: VectorBuilder, tape, coords, vector_elementary: bool = False) -> list:
    """Emit the tape at points ``coords = (x, y, z)`` (vectors); returns the output vectors.

    ``vector_elementary``: sin, cos, exp, log and atan2 from :mod:`implc.compiler.llvm.elementary` (all lanes at
    once, within the bounds proven there) instead of the C library (within an ulp or two, one lane per call)."""
    vals: list = []
    for op, args, attr in tape.nodes:
        if op == "const":
            vals.append(vb.splat(attr[0]))
        elif op == "var":
            vals.append(coords[attr])
        else:
            vals.append(_point(vb, op, [vals[i] for i in args], attr, vector_elementary))
    return [vals[o] for o in tape.outputs]
