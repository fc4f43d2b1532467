"""2D shapes in the (x, y) plane, and their ways into 3D: ``extrude`` along z, ``revolve`` about the z axis,
``loft`` between two of them.

A 2D shape is an expression in x and y alone, F < 0 inside. Exact ones (circle, rectangle, rounded
rectangle, ring) stay exact when extruded or revolved; polygons are the largest of their edges' signed
distances (exact inside, a bound outside).
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy

from ..compiler.symbols import x, y, z
from .vectors import Number, absolute, length, maximum, minimum, positive, positive_part, substitute


def circle(radius: Number = 1, center: Sequence = (0, 0)) -> sympy.Expr:
    """Disc of ``radius``, exact.

    >>> from implc.compiler.symbols import x, y
    >>> float(circle(1).subs({x: 3, y: 4}))
    4.0
    """
    cx, cy = (sympy.sympify(c) for c in center)
    return length(x - cx, y - cy) - positive(radius, "radius")


def rectangle(half_sizes: Sequence = (1, 1), center: Sequence = (0, 0)) -> sympy.Expr:
    """Axis-aligned rectangle of ``half_sizes``, exact: the 2D box distance.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(rectangle((1, 2)).subs({x: 3, y: 0, z: 0})), 6)
    2.0
    """
    (hx, hy), (cx, cy) = (sympy.sympify(v) for v in half_sizes), (sympy.sympify(c) for c in center)
    q = (absolute(x - cx) - hx, absolute(y - cy) - hy)
    return length(*map(positive_part, q)) + minimum(maximum(*q), 0)


def rounded_rectangle(half_sizes: Sequence = (1, 1), radius: Number = sympy.Rational(1, 10),
                      center: Sequence = (0, 0)) -> sympy.Expr:
    """Rectangle with its corners rounded by ``radius``, exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(rounded_rectangle((1, 1), 0.25).subs({x: 2, y: 0, z: 0})), 6)
    1.0
    """
    r = positive(radius, "radius")
    hx, hy = (sympy.sympify(v) for v in half_sizes)
    if not (hx > r and hy > r):
        raise ValueError(f"radius {radius} must be below both half sizes {tuple(half_sizes)}")
    return rectangle((hx - r, hy - r), center) - r


def ring(radius: Number = 1, width: Number = sympy.Rational(1, 5), center: Sequence = (0, 0)) -> sympy.Expr:
    """Annulus of mean ``radius`` and ``width``, exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(ring(1, 0.2).subs({x: 1.5, y: 0, z: 0})), 6)
    0.4
    """
    return absolute(circle(radius, center)) - positive(width, "width") / 2


def convex_polygon(points: Sequence[Sequence]) -> sympy.Expr:
    """Convex polygon through ``points`` counter-clockwise: the largest of its edges' signed distances.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(convex_polygon([(0, 0), (1, 0), (0, 1)]).subs({x: 2, y: 0, z: 0})), 6)
    0.707107
    """
    pts = [tuple(sympy.sympify(c) for c in p) for p in points]
    if len(pts) < 3:
        raise ValueError("a polygon needs three points or more")
    edges = []
    for (ax, ay), (bx, by) in zip(pts, pts[1:] + pts[:1]):
        ex, ey = bx - ax, by - ay
        n = sympy.sqrt(ex**2 + ey**2)
        if n == 0:
            raise ValueError("a polygon's points must differ")
        edges.append((ey * (x - ax) - ex * (y - ay)) / n)  # > 0 on the right of the edge: outside
    return maximum(*edges)


def regular_polygon(sides: int, radius: Number = 1) -> sympy.Expr:
    """Regular polygon of ``sides`` sides, its corners ``radius`` from the origin, one on the +x axis.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(regular_polygon(4, 1).subs({x: 0, y: 0, z: 0})), 6)
    -0.707107
    """
    if not isinstance(sides, int) or sides < 3:
        raise ValueError(f"sides must be a whole number of at least 3, got {sides!r}")
    r = positive(radius, "radius")
    return convex_polygon([(r * sympy.cos(2 * sympy.pi * k / sides), r * sympy.sin(2 * sympy.pi * k / sides))
                           for k in range(sides)])


def triangle(a: Sequence, b: Sequence, c: Sequence) -> sympy.Expr:
    """Triangle with corners ``a``, ``b``, ``c`` (either orientation).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(triangle((0, 0), (0, 1), (1, 0)).subs({x: 0.25, y: 0.25, z: 0})), 6)
    -0.25
    """
    (ax, ay), (bx, by), (cx, cy) = a, b, c
    area = sympy.sympify((bx - ax) * (cy - ay) - (by - ay) * (cx - ax))
    return convex_polygon([a, b, c] if area > 0 else [a, c, b])


def extrude(shape2d: sympy.Expr, height: Number, center: Number = 0) -> sympy.Expr:
    """``shape2d`` extruded along z over ``height``, centred at z = ``center``: exact where the 2D shape is.

    >>> from implc.compiler.symbols import x, y, z
    >>> float(extrude(circle(1), 2).subs({x: 0, y: 0, z: 3}))
    2.0
    """
    w = (shape2d, absolute(z - sympy.sympify(center)) - positive(height, "height") / 2)
    return minimum(maximum(*w), 0) + length(*map(positive_part, w))


def revolve(shape2d: sympy.Expr, offset: Number = 0) -> sympy.Expr:
    """``shape2d`` (x its radial, y its height coordinate) revolved about the z axis, ``offset`` from it:
    exact where the 2D shape is (a torus is a circle revolved).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import circle
    >>> round(float(revolve(circle(0.25), 1).subs({x: 1, y: 0, z: 0})), 6)
    -0.25
    """
    return substitute(shape2d, {x: length(x, y) - sympy.sympify(offset), y: z})


def loft(bottom: sympy.Expr, top: sympy.Expr, z0: Number, z1: Number) -> sympy.Expr:
    """A solid between z0 and z1 whose section goes from ``bottom`` at z0 to ``top`` at z1 (linear
    interpolation of the two fields: not a distance).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import circle
    >>> round(float(loft(circle(1), circle(0.5), 0, 1).subs({x: 0.75, y: 0, z: 0.5})), 6)
    0.0
    """
    z0, z1 = sympy.sympify(z0), sympy.sympify(z1)
    if not z1 > z0:
        raise ValueError("loft needs z1 > z0")
    t = (z - z0) / (z1 - z0)
    return maximum((1 - t) * bottom + t * top, z0 - z, z - z1)
