"""Constructive solid geometry: union, intersection and difference, sharp (Min/Max), smooth (a blend radius)
and chamfered, and a morph between two shapes.

The smooth operations are the polynomial smooth minimum min(a, b) − max(k − abs(a − b), 0)² / 4k, written with
Min and Max: where the operands are more than k apart the correction's Max picks 0, so the tape engine
decides it there and prunes the blend far from the seam. They keep the union's (intersection's) exact
distance away from the blend region; inside it they are a bound.
"""

from __future__ import annotations

import sympy

from .vectors import Number, absolute, maximum, minimum, positive


def union(*shapes: sympy.Expr) -> sympy.Expr:
    """The union of solids (F < 0 inside each): their Min.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(union(x - 1, y - 1).subs({x: 2, y: 0, z: 0})), 6)
    -1.0
    """
    return minimum(*shapes)


def intersection(*shapes: sympy.Expr) -> sympy.Expr:
    """The intersection of solids: their Max.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(intersection(x - 1, y - 1).subs({x: 2, y: 0, z: 0})), 6)
    1.0
    """
    return maximum(*shapes)


def difference(a: sympy.Expr, *cut: sympy.Expr) -> sympy.Expr:
    """a with every shape in ``cut`` removed.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(difference(x - 1, x).subs({x: 0.5, y: 0, z: 0})), 6)
    -0.5
    """
    return maximum(a, *[-c for c in cut])


def _pairwise(join, shapes, name: str):
    """``shapes`` joined two by two, then the results two by two, to one: each join uses both operands
    twice, so a balanced tree keeps the expression's depth logarithmic where a chain would be linear.
    ``name``: the operation's, for the error where there is no shape."""
    if not shapes:
        raise ValueError(f"{name} needs at least one shape")
    items = list(shapes)
    while len(items) > 1:
        items = [join(items[i], items[i + 1]) if i + 1 < len(items) else items[i] for i in range(0, len(items), 2)]
    return items[0]


def _smooth_min(a: sympy.Expr, b: sympy.Expr, k: sympy.Expr) -> sympy.Expr:
    return minimum(a, b) - maximum(k - absolute(a - b), 0) ** 2 / (4 * k)


def smooth_union(radius: Number, *shapes: sympy.Expr) -> sympy.Expr:
    """The union of ``shapes`` with their seams filled by a fillet about ``radius`` wide.

    >>> from implc.compiler.symbols import x
    >>> float(smooth_union(1, x - 1, -x - 1).subs(x, 0))  # two half spaces 2 apart: the fillet dips below
    -1.25
    """
    k = positive(radius, "radius")
    return _pairwise(lambda a, b: _smooth_min(a, b, k), shapes, "smooth_union")


def smooth_intersection(radius: Number, *shapes: sympy.Expr) -> sympy.Expr:
    """The intersection of ``shapes`` with its edges rounded about ``radius``.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(smooth_intersection(1, x - 1, -x - 1).subs({x: 0, y: 0, z: 0})), 6)
    -0.75
    """
    k = positive(radius, "radius")
    return -smooth_union(k, *[-s for s in shapes])


def smooth_difference(radius: Number, a: sympy.Expr, *cut: sympy.Expr) -> sympy.Expr:
    """``a`` with ``cut`` removed, the cut's edges rounded about ``radius``.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(smooth_difference(0.5, x - 1, x).subs({x: 0.5, y: 0, z: 0})), 6)
    -0.375
    """
    return smooth_intersection(radius, a, *[-c for c in cut])


def chamfer_union(size: Number, *shapes: sympy.Expr) -> sympy.Expr:
    """The union with a 45° chamfer of width about ``size`` along each seam.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(chamfer_union(0.5, x - 1, y - 1).subs({x: 1, y: 1, z: 0})), 6)
    -0.353553
    """
    c = positive(size, "size")
    return _pairwise(lambda a, b: minimum(a, b, (a + b - c) / sympy.sqrt(2)), shapes, "chamfer_union")


def chamfer_intersection(size: Number, *shapes: sympy.Expr) -> sympy.Expr:
    """The intersection with its edges cut at 45°, about ``size`` wide.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(chamfer_intersection(0.5, x - 1, y - 1).subs({x: 1, y: 1, z: 0})), 6)
    0.353553
    """
    return -chamfer_union(size, *[-s for s in shapes])


def chamfer_difference(size: Number, a: sympy.Expr, *cut: sympy.Expr) -> sympy.Expr:
    """``a`` with ``cut`` removed, the cut's edges chamfered about ``size``.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(chamfer_difference(0.1, x - 1, x).subs({x: 0.5, y: 0, z: 0})), 6)
    -0.5
    """
    return chamfer_intersection(size, a, *[-c for c in cut])


def morph(a: sympy.Expr, b: sympy.Expr, t: Number) -> sympy.Expr:
    """The shape between ``a`` (t = 0) and ``b`` (t = 1): (1 − t)·a + t·b (not a distance).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(morph(x, y, 0.5).subs({x: 1, y: 1, z: 0})), 6)
    1.0
    """
    t = sympy.sympify(t)
    return (1 - t) * a + t * b
