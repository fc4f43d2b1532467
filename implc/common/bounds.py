"""The bounds of a surface's box, checked once for every entry point that takes them."""

from __future__ import annotations

import math
import sys
from typing import Any

from ..errors import CompileError


def check_bounds(bounds: Any, max_depth: int) -> tuple[tuple[float, float], ...]:
    """Three finite (lo, hi) pairs with lo < hi, as floats, whose cells stay ordinary doubles down to a grid of
    2^``max_depth`` cells; CompileError naming the bad part otherwise."""
    try:
        pairs = [tuple(pair) for pair in bounds]
    except TypeError:
        raise CompileError(f"bounds must be three (lo, hi) pairs, got {bounds!r}") from None
    if len(pairs) != 3 or any(len(p) != 2 for p in pairs):
        raise CompileError(f"bounds must be three (lo, hi) pairs, got {bounds!r}")
    out = []
    for axis, (lo, hi) in zip("xyz", pairs):
        try:
            lo_f, hi_f = float(lo), float(hi)
        except (TypeError, ValueError):
            raise CompileError(f"{axis} bounds ({lo!r}, {hi!r}) are not numbers") from None
        if not (math.isfinite(lo_f) and math.isfinite(hi_f)):
            raise CompileError(f"{axis} bounds ({lo!r}, {hi!r}) are not finite")
        if not lo_f < hi_f:
            raise CompileError(f"{axis} bounds ({lo!r}, {hi!r}) need lo < hi")
        width = hi_f - lo_f
        # the width, the outward pad and the finest cell size (2^-(max_depth + 1) of it, refined) must be
        # ordinary doubles: a width beyond the doubles has no finite cells, a subnormal cell no exact edges
        if not math.isfinite(width) or not math.isfinite(abs(lo_f) + abs(hi_f)):
            raise CompileError(f"{axis} bounds ({lo!r}, {hi!r}) are too far apart: their width is not a finite double")
        if width / 2.0 ** (max_depth + 1) < sys.float_info.min:
            raise CompileError(f"{axis} bounds ({lo!r}, {hi!r}) are too close: the finest cells would be subnormal")
        out.append((lo_f, hi_f))
    return tuple(out)


def usable_bounds(bounds: Any, max_depth: int) -> bool:
    """Whether :func:`check_bounds` accepts ``bounds`` (for readers that say what is wrong themselves)."""
    try:
        check_bounds(bounds, max_depth)
    except CompileError:
        return False
    return True
