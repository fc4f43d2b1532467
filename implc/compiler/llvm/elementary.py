"""Elementary functions computed in vector registers, each with a proven bound on its error.

The C library computes one lane per call; these compute all lanes at once with plain round-to-nearest
arithmetic. Interval rules widen their results by a margin far above the proven bound (absolute:
:data:`implc.compiler.rounding.ATAN2_ERROR`, :data:`implc.compiler.rounding.SIN_ERROR`; relative:
:data:`implc.compiler.rounding.EXP_ERROR`, :data:`implc.compiler.rounding.LOG_ERROR`). Lanes outside a function's proof
(infinities, NaN, zeros for atan2, huge arguments for sin and cos, results or arguments beyond the normal
doubles for exp and log) take the C library's value.

Below, u = 2⁻⁵³ (half an ulp: the relative error of one rounding). Each step of Horner's rule is a
multiply-add that LLVM fuses where the CPU has FMA (one rounding) and leaves as two elsewhere; the
bounds count two roundings a step, so they hold for either.

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

Total: below 1.1e-15 (2.5 ulp of π); :data:`implc.compiler.rounding.ATAN2_ERROR` is 2⁻⁴⁵ ≈ 2.8e-14, and the
tests measure the error against 200-bit values.

``sin(x)`` and ``cos(x)`` for |x| <= :data:`TRIG_MAX` (the proof of their bound):

1. ``k = rint(x · 2/π)`` (|k| < 2¹⁷), ``r = ((x − k·P1) − k·P2) − k·P3`` with P1 and P2 the first two
   33-bit pieces of π/2 and P3 the rest rounded to a double (|π/2 − P1 − P2 − P3| < 1.1e-37): k·P1 and
   k·P2 are exact (17 + 33 bits), x − k·P1 is exact (Sterbenz), the two other subtractions and k·P3 round
   by at most 0.5 ulp of |r| <= 0.8 each: |r − (x − k·π/2)| < 1.2e-16 + 2¹⁷ · 1.1e-37.
2. sin r = r + r³·S(r²) and cos r = 1 + r²·C(r²), S and C the Taylor series through r¹⁷/17! and
   r¹⁶/16!: alternating with decreasing terms for |r| < 1, so truncation is below 0.8¹⁹/19! < 1e-19 and
   0.8¹⁸/18! < 1e-17; the correction terms (< 0.1 and < 0.33) carry a few ulps of themselves,
   < 2e-16, and the final sum rounds by <= 1.1e-16.
3. The quadrant k mod 4 picks ±sin r or ±cos r: exact. sin and cos are 1-Lipschitz, so step 1 adds its
   error once.

Total: below 5e-16; :data:`implc.compiler.rounding.SIN_ERROR` is 2⁻⁴⁵ ≈ 2.8e-14.

``exp(x)`` for |x| <= :data:`EXP_MAX` (the proof of its relative bound):

1. ``k = rint(x · (1/ln 2))``, so |k| <= 1021 and |x/ln 2 − k| <= 1/2 + 1e-12; ``r = (x − k·L1) − k·L2``
   with L1 = ln 2 to 32 bits and L2 the rest rounded (|ln 2 − L1 − L2| < 2⁻⁸⁶): k·L1 is exact (10 + 32
   bits), x − k·L1 is exact (Sterbenz), k·L2 and the last subtraction round: |r| < 0.3466 and
   |r − (x − k·ln 2)| <= 0.35u + 2⁻⁷⁵, which moves exp(r) by a relative 0.36u.
2. exp(r) by its Taylor polynomial through r¹³/13!, coefficients rounded to doubles (relative u each),
   by Horner's rule: truncation <= 0.35¹⁴/14! · e^0.35 < 7e-18; Horner's error <= γ₂₆ · Σ|cᵢ||r|ⁱ <=
   27.1u · e^0.35 (Higham, Thm 5.3), the coefficients' <= u · e^0.35: together <= 38.5u absolute, over
   exp(r) >= e^-0.35: a relative 54.7u.
3. ``exp(x) = exp(r) · 2ᵏ``, 2ᵏ built from its exponent bits (k >= −1021: the product is a normal
   double): exact.

Total: relative error below 55.1u ≈ 6.2e-15; :data:`implc.compiler.rounding.EXP_ERROR` is 2⁻⁴⁵ ≈ 2.8e-14.

``log(x)`` for normal positive finite x (the proof of its relative bound):

1. ``x = 2ᵉ · m`` with m in [√2/2, √2] (exponent and mantissa bits, m halved and e raised above √2):
   exact. ``s = (m − 1) / (m + 1)``: m − 1 exact (Sterbenz), the sum and the quotient round: s carries a
   relative 2.0u, |s| <= (√2 − 1)/(√2 + 1) < 0.1716.
2. log m = 2s · T(s²), T = Σ s²ⁿ/(2n + 1) through n = 10: truncation below s²²/23 / (1 − s²) < 7e-19 of
   T >= 1; T's terms are all positive, so Horner's error with rounded coefficients is <= (γ₂₀ + u) T
   <= 21.1u T, and s² (relative 5u) moves T by a relative s²/3 · 5u < 0.05u: log m carries a relative
   <= 2.0u + 21.2u + u (the product) < 24.3u, and |log m| <= 0.3466.
3. ``e·L1 + (e·L2 + log m)``: e·L1 is exact (|e| <= 1024), e·L2 is off by < 2⁻⁶⁷ (its rounding and the
   split of ln 2), the two sums round by u of their results. For e = 0 the result is log m: 24.3u. For
   e ≠ 0, |log x| >= ln 2 − 0.3466 >= 0.3466, so log m's absolute error is at most 24.3u of the result,
   the inner sum's rounding at most 1.001u of it, the outer sum's u.

Total: relative error below 26.4u ≈ 2.9e-15; :data:`implc.compiler.rounding.LOG_ERROR` is 2⁻⁴⁵ ≈ 2.8e-14.
"""

from __future__ import annotations

import math

from llvmlite import ir

from .vector import VectorBuilder, broadcast

ATAN_TABLE = (  # atan(k / 8), k = 0..8, correctly rounded
    0.0, 0.12435499454676144, 0.24497866312686414, 0.35877067027057225, 0.4636476090008061,
    0.5585993153435624, 0.6435011087932844, 0.7188299996216245, 0.7853981633974483,
)
HALF_PI = 1.5707963267948966
PI = 3.141592653589793
TAYLOR_TERMS = 8
"""u, u³/3, …, u¹⁵/15."""

LN2_1 = 0.6931471806019545
"""ln 2 rounded to 32 significant bits (tests check it)."""
LN2_2 = -4.2009150726810846e-11
"""ln 2 − LN2_1, rounded to a double (tests check it)."""
INV_LN2 = 1.4426950408889634
SQRT2 = 1.4142135623730951
EXP_MAX = 708.0
"""Largest |x| whose exp is computed in vector registers (then the result is a normal double)."""
EXP_TERMS = 13
"""exp(r) through r¹³/13!."""
LOG_TERMS = 10
"""log m = 2s · Σ s²ⁿ/(2n + 1) through n = 10."""

TRIG_MAX = 1e5
"""Largest |x| whose sin and cos are computed in vector registers (then |k| < 2¹⁷)."""
TWO_OVER_PI = 0.6366197723675814
PIO2_1, PIO2_2, PIO2_3 = 1.5707963267341256, 6.077100506303966e-11, 2.0222662487959506e-21
"""π/2 in three pieces: the first two have 33 significant bits, the third is the rest, rounded."""


OUTLINE_ABOVE = 8
"""A tape with more sin, cos and atan2 nodes than this calls them as functions of its module (one copy
each, never inlined) instead of expanding ~40-80 instructions at every use: its IR, and LLVM's time, stay
proportional to the tape (expanded, a sum of many sines compiles for seconds)."""


def outlined(name: str, arity: int, body):
    """``body(vb, *args)`` as an internal, never-inlined function of the vector builder's module, called
    where ``vb.outline_elementary`` is set; expanded in place otherwise."""
    def call(vb: VectorBuilder, *args):
        if not vb.outline_elementary:
            return body(vb, *args)
        symbol = f"implc.elementary.{name}.w{vb.width}"
        fn = vb.module.globals.get(symbol)
        if fn is None:
            fn = ir.Function(vb.module, ir.FunctionType(vb.vtype, [vb.vtype] * arity), name=symbol)
            fn.linkage = "internal"
            fn.attributes.add("noinline")
            inner = VectorBuilder(ir.IRBuilder(fn.append_basic_block("entry")), vb.width)
            inner.b.ret(body(inner, *fn.args))
        return vb.b.call(fn, list(args))
    call.__doc__ = body.__doc__
    return call


def _atan2(vb: VectorBuilder, y, x):
    """atan2(y, x) lane by lane, within :data:`implc.compiler.rounding.ATAN2_ERROR` of the true value."""
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
        series = vb.horner_step(u2, series, vb.splat(coefficient(n)))
    table = vb.splat(ATAN_TABLE[0])
    for index in range(1, len(ATAN_TABLE)):
        table = vb.select(vb.cmp("==", k, vb.splat(float(index))), vb.splat(ATAN_TABLE[index]), table)
    angle = vb.add(table, vb.mul(u, series))
    angle = vb.select(vb.cmp(">", ay, ax), vb.sub(vb.splat(HALF_PI), angle), angle)
    angle = vb.select(vb.cmp("<", x, vb.splat(0.0)), vb.sub(vb.splat(PI), angle), angle)
    return _c_library_where_irregular(vb, vb.copysign(angle, y), regular, "atan2", y, x)


def _sin(vb: VectorBuilder, x):
    """sin(x) lane by lane, within :data:`implc.compiler.rounding.SIN_ERROR` of the true value."""
    return _sin_cos(vb, x, 0, "sin")


def _cos(vb: VectorBuilder, x):
    """cos(x) lane by lane, within :data:`implc.compiler.rounding.SIN_ERROR` of the true value."""
    return _sin_cos(vb, x, 1, "cos")


def _exp(vb: VectorBuilder, x):
    """exp(x) lane by lane, within a relative :data:`implc.compiler.rounding.EXP_ERROR` of the true value."""
    b = vb.b
    i64 = ir.VectorType(ir.IntType(64), vb.width)
    regular = vb.cmp("<=", vb.fabs(x), vb.splat(EXP_MAX))  # false for NaN
    reduced = vb.select(regular, x, vb.splat(0.0))  # other lanes are recomputed below
    k = vb.rint(vb.mul(reduced, vb.splat(INV_LN2)))
    r = vb.sub(vb.sub(reduced, vb.mul(k, vb.splat(LN2_1))), vb.mul(k, vb.splat(LN2_2)))
    poly = vb.splat(1.0 / math.factorial(EXP_TERMS))
    for n in range(EXP_TERMS - 1, -1, -1):
        poly = vb.horner_step(r, poly, vb.splat(1.0 / math.factorial(n)))
    biased = b.add(b.fptosi(k, i64), broadcast(b, ir.Constant(ir.IntType(64), 1023), vb.width))
    scale = b.bitcast(b.shl(biased, broadcast(b, ir.Constant(ir.IntType(64), 52), vb.width)), vb.vtype)
    return _c_library_where_irregular(vb, vb.mul(poly, scale), regular, "exp", x)


def _log(vb: VectorBuilder, x):
    """log(x) lane by lane, within a relative :data:`implc.compiler.rounding.LOG_ERROR` of the true value."""
    b = vb.b
    i64 = ir.VectorType(ir.IntType(64), vb.width)

    def ints(v):
        return broadcast(b, ir.Constant(ir.IntType(64), v), vb.width)
    regular = vb.and_(vb.cmp(">=", x, vb.splat(2.0**-1022)), vb.cmp("<", x, vb.splat(math.inf)))  # NaN: false
    bits = b.bitcast(vb.select(regular, x, vb.splat(1.0)), i64)
    exponent = b.sub(b.lshr(bits, ints(52)), ints(1023))
    m = b.bitcast(b.or_(b.and_(bits, ints((1 << 52) - 1)), ints(1023 << 52)), vb.vtype)  # in [1, 2)
    big = vb.cmp(">", m, vb.splat(SQRT2))
    m = vb.select(big, vb.mul(m, vb.splat(0.5)), m)
    e = b.sitofp(b.add(exponent, b.zext(big, i64)), vb.vtype)
    s = vb.div(vb.sub(m, vb.splat(1.0)), vb.add(m, vb.splat(1.0)))
    s2 = vb.mul(s, s)
    series = vb.splat(1.0 / (2 * LOG_TERMS + 1))
    for n in range(LOG_TERMS - 1, -1, -1):
        series = vb.horner_step(s2, series, vb.splat(1.0 / (2 * n + 1)))
    log_m = vb.mul(vb.add(s, s), series)
    value = vb.add(vb.mul(e, vb.splat(LN2_1)), vb.add(vb.mul(e, vb.splat(LN2_2)), log_m))
    return _c_library_where_irregular(vb, value, regular, "log", x)


atan2 = outlined("atan2", 2, _atan2)
sin = outlined("sin", 1, _sin)
cos = outlined("cos", 1, _cos)
exp = outlined("exp", 1, _exp)
log = outlined("log", 1, _log)


def outlines(tape) -> bool:
    """Whether a module for ``tape`` calls the vector functions outlined: more than :data:`OUTLINE_ABOVE`
    of its nodes (the gradient tape's, for both the value and the derivatives) are computed by them."""
    return sum(op in ("sin", "cos", "atan2", "atan2_wrapped", "exp", "log") for op, _, _ in tape.nodes) > OUTLINE_ABOVE


def _sin_cos(vb: VectorBuilder, x, quarter_turns: int, name: str):
    """sin(x + quarter_turns · π/2), the shift applied exactly to the quadrant."""
    b = vb.b
    regular = vb.cmp("<=", vb.fabs(x), vb.splat(TRIG_MAX))  # false for NaN
    reduced = vb.select(regular, x, vb.splat(0.0))  # other lanes are recomputed below
    k = vb.rint(vb.mul(reduced, vb.splat(TWO_OVER_PI)))
    r = vb.sub(vb.sub(vb.sub(reduced, vb.mul(k, vb.splat(PIO2_1))), vb.mul(k, vb.splat(PIO2_2))),
               vb.mul(k, vb.splat(PIO2_3)))
    r2 = vb.mul(r, r)

    def series(first, count):  # Σ (-1)^n r2^n / (first + 2n)!, n = 1..count, by Horner in r2
        coefficients = [(-1.0) ** n / math.factorial(first + 2 * n) for n in range(1, count + 1)]
        acc = vb.splat(coefficients[-1])
        for c in reversed(coefficients[:-1]):
            acc = vb.horner_step(r2, acc, vb.splat(c))
        return acc
    sine = vb.add(r, vb.mul(vb.mul(r, r2), series(1, 8)))  # through r¹⁷/17!
    cosine = vb.add(vb.splat(1.0), vb.mul(r2, series(0, 8)))  # through r¹⁶/16!
    quadrant = b.and_(b.add(b.fptosi(k, ir.VectorType(ir.IntType(64), vb.width)),
                            broadcast(b, ir.Constant(ir.IntType(64), quarter_turns), vb.width)),
                      broadcast(b, ir.Constant(ir.IntType(64), 3), vb.width))
    odd = b.trunc(quadrant, ir.VectorType(ir.IntType(1), vb.width))
    negative = b.icmp_unsigned(">=", quadrant, broadcast(b, ir.Constant(ir.IntType(64), 2), vb.width))
    value = vb.select(odd, cosine, sine)
    value = vb.select(negative, vb.neg(value), value)
    return _c_library_where_irregular(vb, value, regular, name, x)


def _c_library_where_irregular(vb: VectorBuilder, value, regular, name, *args):
    """``value`` where ``regular`` holds, the C library's ``name(*args)`` elsewhere: called for the whole
    vector, but only when some lane needs it (a lane's result never depends on its neighbours)."""
    b = vb.b
    all_regular = b.icmp_unsigned("==", b.bitcast(regular, ir.IntType(vb.width)),
                                  ir.Constant(ir.IntType(vb.width), (1 << vb.width) - 1))
    fast_block = b.block
    with b.if_then(b.not_(all_regular)):
        fallback = vb.select(regular, value, vb.libm(name, *args))
        fallback_block = b.block
    result = b.phi(vb.vtype)
    result.add_incoming(value, fast_block)
    result.add_incoming(fallback, fallback_block)
    return result
