"""Deformations: twist, bend, taper, shear and elongate a shape by substituting the coordinates.

Twist, bend, taper and shear move points by different amounts, so F is no longer a distance (‖∇F‖ grows
with the deformation: a bound only where the deformation is mild); elongate keeps an exact distance exact.
"""

from __future__ import annotations

import sympy

from ..compiler.symbols import x, y, z
from .vectors import Number, Vec, maximum, minimum, substitute, vec3


def twist(expr: sympy.Expr, rate: Number) -> sympy.Expr:
    """``expr`` twisted about the z axis by ``rate`` radians per unit of height.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(twist(x, 0).subs({x: 2, y: 0, z: 0})), 6)
    2.0
    """
    a = sympy.sympify(rate) * z
    c, s = sympy.cos(a), sympy.sin(a)
    return substitute(expr, {x: c * x + s * y, y: -s * x + c * y})


def bend(expr: sympy.Expr, rate: Number) -> sympy.Expr:
    """``expr`` bent in the (x, z) plane, its z axis curving towards +x by ``rate`` radians per unit of
    height.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(bend(x, 0).subs({x: 1, y: 0, z: 0})), 6)
    1.0
    """
    a = sympy.sympify(rate) * z
    c, s = sympy.cos(a), sympy.sin(a)
    return substitute(expr, {x: c * x - s * z, z: s * x + c * z})


def taper(expr: sympy.Expr, rate: Number, axis_z0: Number = 0) -> sympy.Expr:
    """``expr`` scaled in x and y by 1 + rate·(z − z0): wider above z0 for a positive ``rate``.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(taper(x - 1, 1).subs({x: 1.5, y: 0, z: 1})), 6)
    -0.25
    """
    k = 1 + sympy.sympify(rate) * (z - sympy.sympify(axis_z0))
    return substitute(expr, {x: x / k, y: y / k})


def shear(expr: sympy.Expr, dx_per_z: Number = 0, dy_per_z: Number = 0) -> sympy.Expr:
    """``expr`` sheared: a point at height z moved by (dx_per_z·z, dy_per_z·z).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(shear(x, 1).subs({x: 1, y: 0, z: 1})), 6)
    0.0
    """
    return substitute(expr, {x: x - sympy.sympify(dx_per_z) * z, y: y - sympy.sympify(dy_per_z) * z})


def elongate(expr: sympy.Expr, half_lengths: Vec) -> sympy.Expr:
    """``expr`` stretched by inserting 2·h along each axis at its middle (a sphere becomes a capsule or a
    rounded box): p − clamp(p, −h, h) substituted; exact where ``expr`` is.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(elongate(sphere(1), (1, 0, 0)).subs({x: 2, y: 0, z: 0})), 6)
    0.0
    """
    hx, hy, hz = vec3(half_lengths, "half_lengths")
    moved = [v - minimum(maximum(v, -h), h) for v, h in ((x, hx), (y, hy), (z, hz))]
    return substitute(expr, dict(zip((x, y, z), moved)))
