"""Offsets: a solid grown or shrunk by a distance, hollowed to a shell, or kept a clearance away from another.

Where F is an exact distance, ``offset`` by d ≥ 0 is the exact distance to the grown solid outside it, and
``shell`` of thickness t is exact everywhere (abs(F) − t/2); otherwise they are what F is, shifted.
"""

from __future__ import annotations

import sympy

from .vectors import Number, absolute, maximum, positive


def offset(expr: sympy.Expr, distance: Number) -> sympy.Expr:
    """The solid grown by ``distance`` (shrunk where it is negative): F − d.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(offset(sphere(1), 1).subs({x: 3, y: 0, z: 0})), 6)
    1.0
    """
    return expr - sympy.sympify(distance)


def dilate(expr: sympy.Expr, distance: Number) -> sympy.Expr:
    """The solid grown by ``distance`` (> 0).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(dilate(sphere(1), 0.5).subs({x: 1.5, y: 0, z: 0})), 6)
    0.0
    """
    return offset(expr, positive(distance, "distance"))


def erode(expr: sympy.Expr, distance: Number) -> sympy.Expr:
    """The solid shrunk by ``distance`` (> 0).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(erode(sphere(1), 0.5).subs({x: 0, y: 0, z: 0})), 6)
    -0.5
    """
    return offset(expr, -positive(distance, "distance"))


def shell(expr: sympy.Expr, thickness: Number) -> sympy.Expr:
    """A wall ``thickness`` thick centred on the surface: abs(F) − t/2.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> float(shell(sphere(1), 0.2).subs({x: 0, y: 0, z: 0}))
    0.9
    """
    return absolute(expr) - positive(thickness, "thickness") / 2


def inner_shell(expr: sympy.Expr, thickness: Number) -> sympy.Expr:
    """The part of the solid within ``thickness`` of its surface (a hollowed part, its outside kept).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(inner_shell(sphere(1), 0.25).subs({x: 0, y: 0, z: 0})), 6)
    0.75
    """
    t = positive(thickness, "thickness")
    return maximum(expr, -expr - t)


def clearance(a: sympy.Expr, b: sympy.Expr, gap: Number) -> sympy.Expr:
    """``a`` with everything within ``gap`` of ``b`` removed (a hole for ``b`` with room around it).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(clearance(x - 1, x, 0.25).subs({x: 0.1, y: 0, z: 0})), 6)
    0.15
    """
    return maximum(a, -(b - positive(gap, "gap")))
