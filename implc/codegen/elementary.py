"""Elementary functions computed in vector registers, each with a proven bound on its absolute error.

The C library computes one lane per call; these compute all lanes at once with plain round-to-nearest
arithmetic. Interval rules widen their results by the bound (:data:`implc.rounding.ATAN2_ERROR`).

``atan2(y, x)`` (the proof of its bound):

1. ``t = min(|x|, |y|) / max(|x|, |y|)`` in [0, 1]: one rounding, relative error <= 2⁻⁵³, and atan is
   1-Lipschitz: <= 1.2e-16 in the angle.
2. ``c = k / 8`` with ``k = floor(8 t + 1/2)``, so ``|t − c| <= 1/16`` (up to an ulp); ``t − c`` is exact
   (Sterbenz: c/2 <= t <= 2c for k >= 1) or within an ulp of 1/16, and ``1 + c·t`` and the quotient
   ``u = (t − c) / (1 + c·t)`` carry <= 3 roundings: ``|u| <= 1/16`` with absolute error below
   1/16 · 2⁻⁵¹ + 2⁻⁵⁷ < 4e-17; atan(t) = atan(c) + atan(u).
3. atan(u) by its odd Taylor series through u¹⁵/15: an alternating series with decreasing terms, so the
   truncation error is below the first omitted term, (1/16)¹⁷ / 17 < 2.1e-22; Horner's rule in u²
   with coefficients rounded to doubles adds a few ulps of |u| <= 1/16: < 3e-17.
4. atan(c) from a table of correctly rounded doubles (tests check them): <= 5.6e-17; the sum rounds by
   <= 5.6e-17.
5. The octant fix-ups π/2 − a and π − a use doubles within 6.2e-17 and 1.3e-16 of π/2 and π, and
   round by <= 2.3e-16 each.

Total: below 1.1e-15 (2.5 ulp of π); :data:`implc.rounding.ATAN2_ERROR` is 2⁻⁴⁵ ≈ 2.8e-14, and the
tests measure the error against 60-digit values. Lanes where both arguments are 0, either is infinite or
NaN take the C library's atan2 instead.
"""

from __future__ import annotations

from llvmlite import ir

from .vector import VectorBuilder

ATAN_TABLE = (  # atan(k / 8), k = 0..8, correctly rounded
    0.0, 0.12435499454676144, 0.24497866312686414, 0.35877067027057225, 0.4636476090008061,
    0.5585993153435624, 0.6435011087932844, 0.7188299996216245, 0.7853981633974483,
)
HALF_PI = 1.5707963267948966
PI = 3.141592653589793
TAYLOR_TERMS = 8
"""u, u³/3, …, u¹⁵/15."""


def atan2(vb: VectorBuilder, y, x):
    """atan2(y, x) lane by lane, within :data:`implc.rounding.ATAN2_ERROR` of the true value."""
    b = vb.b
    ax, ay = vb.fabs(x), vb.fabs(y)
    big, small = vb.maximum(ax, ay), vb.minimum(ax, ay)
    regular = vb.and_(vb.cmp(">", big, vb.splat(0.0)), vb.cmp("<", big, vb.splat(float("inf"))))
    t = vb.div(small, vb.select(regular, big, vb.splat(1.0)))  # special lanes are recomputed below
    k = vb.floor(vb.add(vb.mul(t, vb.splat(8.0)), vb.splat(0.5)))
    c = vb.mul(k, vb.splat(0.125))
    u = vb.div(vb.sub(t, c), vb.add(vb.splat(1.0), vb.mul(c, t)))
    u2 = vb.mul(u, u)
    def coefficient(n):  # of u^(2n) in atan(u) / u
        return (-1.0) ** n / (2 * n + 1)
    series = vb.splat(coefficient(TAYLOR_TERMS - 1))
    for n in range(TAYLOR_TERMS - 2, -1, -1):  # Horner in u²: 1 − u²/3 + u⁴/5 − …
        series = vb.add(vb.splat(coefficient(n)), vb.mul(u2, series))
    table = vb.splat(ATAN_TABLE[0])
    for index in range(1, len(ATAN_TABLE)):
        table = vb.select(vb.cmp("==", k, vb.splat(float(index))), vb.splat(ATAN_TABLE[index]), table)
    angle = vb.add(table, vb.mul(u, series))
    angle = vb.select(vb.cmp(">", ay, ax), vb.sub(vb.splat(HALF_PI), angle), angle)
    angle = vb.select(vb.cmp("<", x, vb.splat(0.0)), vb.sub(vb.splat(PI), angle), angle)
    angle = vb.copysign(angle, y)
    # the rare lanes outside the proof take the C library's value (called for all lanes, but only when
    # some lane needs it: a lane's result never depends on its neighbours)
    all_regular = b.icmp_unsigned("==", b.bitcast(regular, ir.IntType(vb.width)),
                                  ir.Constant(ir.IntType(vb.width), (1 << vb.width) - 1))
    fast_block = b.block
    with b.if_then(b.not_(all_regular)):
        fallback = vb.select(regular, angle, vb.libm("atan2", y, x))
        fallback_block = b.block
    result = b.phi(vb.vtype)
    result.add_incoming(angle, fast_block)
    result.add_incoming(fallback, fallback_block)
    return result
