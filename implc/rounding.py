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
"""Absolute widening of the vector atan2 (:mod:`implc.codegen.elementary`), proven within 1.1e-15."""

SIN_ERROR = 2.0**-45
"""Absolute widening of the vector sin and cos (:mod:`implc.codegen.elementary`), proven within 5e-16."""

TINY = 2.0**-1074
"""The smallest subnormal: the absolute part of every move, so that results near zero widen too."""

PI_LO = 3.141592653589793  # the double nearest pi lies below pi
PI_HI = math.nextafter(PI_LO, math.inf)
TWO_PI_HI = math.nextafter(2 * PI_LO, math.inf)

TRIG_MAX_ARG = 1e9
"""Beyond this |argument|, sin/cos/tan intervals are [-1, 1] / the whole line (period reduction loses digits)."""


def powi_slack(n: int) -> float:
    """Widening constant for a ** n computed by repeated squaring (k products, relative error ~ k u)."""
    products = n.bit_length() - 1 + bin(n).count("1") - 1
    return ARITH * 2.0 ** math.ceil(math.log2(products + 1))
