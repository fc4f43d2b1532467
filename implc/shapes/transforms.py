"""Transforms: a shape moved, scaled, rotated about any axis, mapped by a 4×4 matrix, mirrored or made
symmetric, by substituting the coordinates (the shape at p is the original at the inverse image of p).

Rigid motions (translate, rotate, mirror) keep an exact distance exact; scaling by a factor s divides it by
s (the distance to the scaled shape is s times F's) and keeps it a distance only where the factor is the
same on every axis and F is multiplied by s again (``scale`` does not renormalise: s·F would).
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy

from ..compiler.symbols import x, y, z
from .vectors import Number, Vec, absolute, substitute, unit, vec3


def translate(expr: sympy.Expr, offset: Vec) -> sympy.Expr:
    """``expr`` moved by ``offset`` (dx, dy, dz).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(translate(sphere(1), (1, 0, 0)).subs({x: 1, y: 0, z: 0})), 6)
    -1.0
    """
    dx, dy, dz = vec3(offset, "offset")
    return substitute(expr, {x: x - dx, y: y - dy, z: z - dz})


def scale(expr: sympy.Expr, factor: Number) -> sympy.Expr:
    """Scale about the origin by a number or per-axis (sx, sy, sz); F is not renormalised.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(scale(sphere(1), 2).subs({x: 2, y: 0, z: 0})), 6)
    0.0
    """
    sx, sy, sz = vec3(factor, "factor") if isinstance(factor, (tuple, list)) else (sympy.sympify(factor),) * 3
    return substitute(expr, {x: x / sx, y: y / sy, z: z / sz})


def rotate(expr: sympy.Expr, angle: Number, axis: str | Vec = "z") -> sympy.Expr:
    """Rotate by ``angle`` (radians, counter-clockwise looking down the axis) about the x, y or z axis, or
    any axis through the origin given as a vector.

    >>> from implc.compiler.symbols import x, y, z
    >>> import sympy
    >>> rotate(x, sympy.pi / 2, "z")  # the half space x < 0, turned a quarter: y < 0
    y
    """
    if isinstance(axis, str):
        if axis not in ("x", "y", "z"):
            raise ValueError(f"axis must be 'x', 'y', 'z' or a vector, got {axis!r}")
        axis = {"x": (1, 0, 0), "y": (0, 1, 0), "z": (0, 0, 1)}[axis]
    kx, ky, kz = unit(axis, "axis")
    c, s = sympy.cos(angle), sympy.sin(angle)
    # the shape at p rotated by +angle is the original at p rotated by -angle (Rodrigues' formula)
    k_dot = kx * x + ky * y + kz * z
    cross = (ky * z - kz * y, kz * x - kx * z, kx * y - ky * x)  # k × p
    back = [p * c - cr * s + kk * k_dot * (1 - c) for p, cr, kk in zip((x, y, z), cross, (kx, ky, kz))]
    return substitute(expr, {x: back[0], y: back[1], z: back[2]})


def transform(expr: sympy.Expr, matrix: Sequence[Sequence[Number]]) -> sympy.Expr:
    """``expr`` mapped by the affine 4×4 ``matrix`` (column vectors: p' = M·p; its last row 0 0 0 1): the
    original at M⁻¹·p. Exact distances stay exact only where M is rigid.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(transform(x, [[1, 0, 0, 2], [0, 1, 0, 0], [0, 0, 1, 0], [0, 0, 0, 1]]).subs({x: 2, y: 0, z: 0})), 6)
    0.0
    """
    m = sympy.Matrix(matrix)
    if m.shape != (4, 4) or list(m[3, :]) != [0, 0, 0, 1]:
        raise ValueError("matrix must be 4×4 with its last row 0 0 0 1")
    if m[:3, :3].det() == 0:
        raise ValueError("matrix must be invertible")
    inverse = m.inv()
    p = inverse * sympy.Matrix([x, y, z, 1])
    return substitute(expr, {x: p[0], y: p[1], z: p[2]})


def mirror(expr: sympy.Expr, axis: str = "x") -> sympy.Expr:
    """The mirror image of ``expr`` across the plane through the origin normal to ``axis``.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(mirror(x - 1, 'x').subs({x: 0, y: 0, z: 0})), 6)
    -1.0
    """
    a = _axis(axis)
    return substitute(expr, {a: -a})


def symmetric(expr: sympy.Expr, axis: str = "x") -> sympy.Expr:
    """The half of ``expr`` on the positive side of ``axis``, reflected onto the negative side too (abs(a) for a).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(symmetric(x - 1, 'x').subs({x: -2, y: 0, z: 0})), 6)
    1.0
    """
    a = _axis(axis)
    return substitute(expr, {a: absolute(a)})


def _axis(axis: str):
    if axis not in ("x", "y", "z"):
        raise ValueError(f"axis must be 'x', 'y' or 'z', got {axis!r}")
    return {"x": x, "y": y, "z": z}[axis]
