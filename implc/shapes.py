"""Shape helpers: plain functions returning SymPy expressions F (F < 0 inside, F > 0 outside).

CSG uses Min/Max (union = Min, intersection = Max, difference = Max(a, -b)); transforms substitute the
coordinates. Blobs follow the paper's polynomial blend g(d) = (d² − R²)⁴ / R⁸ for d ≤ R, else 0.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy

from .compiler.symbols import cartesian_form, x, y, z

Number = Any
"""A number: int, float or a SymPy number (exact where it is a Rational or an Integer)."""
Vec = Sequence[Any]
"""Three numbers (x, y, z)."""


def _vec(v, name="point"):
    values = tuple(sympy.sympify(c) for c in v)
    if len(values) != 3:
        raise ValueError(f"{name} needs three coordinates, got {v!r}")
    return values


def _squared_distance(center):
    cx, cy, cz = _vec(center, "center")
    return (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2


def sphere(radius: Number = 1, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Signed-distance sphere: ‖p − c‖ − radius."""
    return sympy.sqrt(_squared_distance(center)) - radius


def box(half_sizes: Vec = (1, 1, 1), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Axis-aligned box as max(abs(pᵢ − cᵢ) − hᵢ) over the axes (exact inside, a lower bound outside)."""
    hx, hy, hz = _vec(half_sizes, "half_sizes")
    cx, cy, cz = _vec(center, "center")
    return sympy.Max(sympy.Abs(x - cx) - hx, sympy.Abs(y - cy) - hy, sympy.Abs(z - cz) - hz)


def torus(major: Number = 1, minor: Number = sympy.Rational(1, 4), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Torus around the z axis: (sqrt(x² + y²) − major)² + z² − minor²."""
    cx, cy, cz = _vec(center, "center")
    ring = sympy.sqrt((x - cx) ** 2 + (y - cy) ** 2) - major
    return ring**2 + (z - cz) ** 2 - minor**2


def cylinder(radius: Number = 1, height: Number = 2, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Capped cylinder along z: max(radial distance − radius, abs(z − cz) − height / 2)."""
    cx, cy, cz = _vec(center, "center")
    return sympy.Max(sympy.sqrt((x - cx) ** 2 + (y - cy) ** 2) - radius, sympy.Abs(z - cz) - height / sympy.S(2))


def blend(squared_distance: sympy.Expr, radius: Number) -> sympy.Expr:
    """The paper's blend g(d) = (d² − R²)⁴ / R⁸ for d ≤ R, else 0, written in d² (no square root)."""
    r2 = sympy.sympify(radius) ** 2
    return sympy.Piecewise(((squared_distance - r2) ** 4 / r2**4, squared_distance <= r2), (0, True))


def blobs(centers: Sequence[Vec], radius: Number, threshold: Number,
          weights: Sequence[Number] | None = None) -> sympy.Expr:
    """Blended blobs: threshold − Σ wᵢ g(‖p − cᵢ‖), negative inside (where the field exceeds threshold)."""
    centers = list(centers)
    if not centers:
        raise ValueError("blobs needs at least one center")
    weights = [1] * len(centers) if weights is None else list(weights)
    if len(weights) != len(centers):
        raise ValueError(f"{len(weights)} weights for {len(centers)} centers")
    field = sympy.Add(*[sympy.sympify(w) * blend(_squared_distance(c), radius) for c, w in zip(centers, weights)])
    return sympy.sympify(threshold) - field


def union(*shapes: sympy.Expr) -> sympy.Expr:
    """The union of solids (F < 0 inside each): their Min."""
    return sympy.Min(*shapes)


def intersection(*shapes: sympy.Expr) -> sympy.Expr:
    """The intersection of solids: their Max."""
    return sympy.Max(*shapes)


def difference(a: sympy.Expr, *cut: sympy.Expr) -> sympy.Expr:
    """a with every shape in ``cut`` removed."""
    return sympy.Max(a, *[-c for c in cut])


def translate(expr: sympy.Expr, offset: Vec) -> sympy.Expr:
    """``expr`` moved by ``offset`` (dx, dy, dz)."""
    dx, dy, dz = _vec(offset, "offset")
    return cartesian_form(expr).xreplace({x: x - dx, y: y - dy, z: z - dz})


def scale(expr: sympy.Expr, factor: Number) -> sympy.Expr:
    """Scale about the origin by a number or per-axis (sx, sy, sz); F is not renormalised."""
    sx, sy, sz = _vec(factor, "factor") if isinstance(factor, (tuple, list)) else (sympy.sympify(factor),) * 3
    return cartesian_form(expr).xreplace({x: x / sx, y: y / sy, z: z / sz})


def rotate(expr: sympy.Expr, angle: Number, axis: str = "z") -> sympy.Expr:
    """Rotate by ``angle`` (radians) about the x, y or z axis through the origin."""
    if axis not in ("x", "y", "z"):
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    c, s = sympy.cos(angle), sympy.sin(angle)
    a, b = {"x": (y, z), "y": (z, x), "z": (x, y)}[axis]
    # the shape at p rotated by +angle is the original at p rotated by -angle
    return cartesian_form(expr).xreplace({a: c * a + s * b, b: -s * a + c * b})
