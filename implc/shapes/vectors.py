"""Numbers and points as the shape builders take them, and the few vector operations they share."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy

Number = Any
"""A number: int, float or a SymPy number (exact where it is a Rational or an Integer)."""
Vec = Sequence[Any]
"""Three numbers (x, y, z)."""


def vec3(v: Vec, name: str = "point") -> tuple[sympy.Expr, sympy.Expr, sympy.Expr]:
    """``v`` as three SymPy numbers; ValueError naming ``name`` otherwise."""
    values = tuple(sympy.sympify(c) for c in v)
    if len(values) != 3:
        raise ValueError(f"{name} needs three coordinates, got {v!r}")
    return values  # type: ignore[return-value]


def number(v: Number, name: str) -> sympy.Expr:
    """``v`` as a SymPy number; ValueError naming ``name`` where it is not one."""
    value = sympy.sympify(v)
    if not value.is_number:
        raise ValueError(f"{name} must be a number, got {v!r}")
    return value


def positive(v: Number, name: str) -> sympy.Expr:
    """``v`` as a SymPy number above 0."""
    value = number(v, name)
    if not value.is_positive:
        raise ValueError(f"{name} must be above 0, got {v!r}")
    return value


def length(*components: sympy.Expr) -> sympy.Expr:
    """The Euclidean length of a vector given by its components."""
    return sympy.sqrt(sympy.Add(*[c**2 for c in components]))


def positive_part(v: sympy.Expr) -> sympy.Expr:
    """max(v, 0)."""
    return sympy.Max(v, 0)


def clamp(v: sympy.Expr, lo: Number, hi: Number) -> sympy.Expr:
    """v limited to [lo, hi]."""
    return sympy.Min(sympy.Max(v, lo), hi)


def unit(v: Vec, name: str = "direction") -> tuple[sympy.Expr, sympy.Expr, sympy.Expr]:
    """``v`` scaled to length 1 (exactly, as SymPy numbers)."""
    a, b, c = vec3(v, name)
    n = sympy.sqrt(a**2 + b**2 + c**2)
    if n == 0:
        raise ValueError(f"{name} must not be zero")
    return a / n, b / n, c / n
