"""The outward-rounding contract shared by the numpy reference and the LLVM kernels.

Every bound is computed in round-to-nearest and then moved outward by ``|v| * c + 2**-1074``
(``widen_down``/``widen_up``), where ``c`` is a power of two chosen per kind of operation so that the move
covers that operation's error: ``|v| * 2**-52`` is at least one ulp of ``v``. Both evaluators use exactly
these formulas, so their bounds agree bit for bit wherever they call the same functions. A bound that
overflows to infinity on the wrong side becomes NaN, and NaN never prunes.

On CPUs with AVX-512 the kernels instead round add, sub, mul and sqrt bounds directly toward -inf / +inf
with the instructions' embedded rounding (``implc.compile(..., rounding="directed")``, the default there):
each bound is then the nearest double outward of the exact result, never further out than the widening
would put it; libm results are still widened by ``LIBM`` (and ``pow`` by ``POWF``).
Both schemes assume the default floating-point environment (no flush-to-zero of subnormals).
"""

import math

ARITH = 2.0**-52
"""add, sub, mul, div, sqrt: correctly rounded, error <= 0.5 ulp."""

LIBM = 2.0**-50
"""C math library functions (exp, log, sin, atan2, ...): at least 3 ulps, above glibc's documented bounds."""

POWF = 2.0**-40
"""pow(a, e) with e rounded to a double: |e - e_true| <= 2**-53 |e| costs up to ~745 * 2**-53 relative."""

ATAN2_ERROR = 2.0**-45
"""Absolute widening of the vector atan2 (:mod:`implc.compiler.llvm.elementary`), proven within 1.1e-15."""

SIN_ERROR = 2.0**-45
"""Absolute widening of the vector sin and cos (:mod:`implc.compiler.llvm.elementary`), proven within 5e-16."""

EXP_ERROR = 2.0**-45
"""Relative widening of the vector exp (:mod:`implc.compiler.llvm.elementary`), proven within 6.2e-15."""

LOG_ERROR = 2.0**-45
"""Relative widening of the vector log (:mod:`implc.compiler.llvm.elementary`), proven within 2.9e-15."""

TINY = 2.0**-1074
"""The smallest subnormal: the absolute part of every move, so that results near zero widen too."""

PI_LO = 3.141592653589793  # the double nearest pi lies below pi
PI_HI = math.nextafter(PI_LO, math.inf)
TWO_PI_HI = math.nextafter(2 * PI_LO, math.inf)

TRIG_MAX_ARG = 1e9
"""Beyond this |argument|, sin/cos/tan intervals are [-1, 1] / the whole line (period reduction loses digits)."""


POWI_MAX = 1 << 16
"""The largest |n| of an integer power a ** n that is compiled (beyond it: a CompileError)."""


def powi_slack(n: int) -> float:
    """Relative widening ``c`` for a ** n (2 <= n <= POWI_MAX) computed by repeated squaring in
    round-to-nearest, where no product underflows.

    Proof. Each product rounds once: fl(p·q) = p·q·(1 + δ), |δ| <= u = 2^-53. Following the rounding
    factors through the chain, the computed value is v = aⁿ · Π (1 + δᵢ)^cᵢ, where cᵢ is how often
    product i's result is a factor of the final one; a squaring doubles the count of what it squares, a
    product adds its operands' counts plus one, so Σ cᵢ = n − 1 (the exponent of a, less the one input).
    Hence |v − aⁿ| <= γ·|aⁿ| with γ = (n − 1)u / (1 − (n − 1)u) (Higham's γ_{n−1}) and
    |aⁿ| <= |v| / (1 − γ). The widened bound (v ∓ |v|·c) is itself computed in round-to-nearest: the
    product |v|·c and the subtraction each add at most u of their results. It is outward of aⁿ when
    c(1 − 2u) >= γ / (1 − γ) + u, which holds for every c >= γ / (1 − γ) + 2u with c <= 1/2 (true for
    n <= POWI_MAX: c <= 2^-36). ``c`` is that bound rounded up to a power of two.

    (The former bound counted products, not the exponent they build: 6 products for a²² claimed
    2^-49 where γ is 21u ≈ 2^-48.6, and a 64th power was wrong at one box in three.)
    """
    w = n - 1
    gamma = w * 2.0**-53 / (1 - w * 2.0**-53)
    return 2.0 ** math.ceil(math.log2(gamma / (1 - gamma) + 2.0**-52))


def powi_tiny(n: int) -> float:
    """Absolute widening for a ** n (added to :func:`powi_slack`'s relative one), covering underflow.

    Proof. If |a| >= 1 no product underflows. If |a| < 1 every partial product has magnitude <= 1, so
    an error made by a product whose result is subnormal (at most 2^-1075, half the subnormal spacing) is
    only ever multiplied by factors <= 1 afterwards: all of them together stay below P·2^-1075, P the
    number of products. (P + 1)·2^-1074 covers them and the rounding of |v|·c; near and below the
    subnormal range the widened bound's subtraction is exact.
    """
    products = n.bit_length() - 1 + bin(n).count("1") - 1
    return (products + 1) * TINY
