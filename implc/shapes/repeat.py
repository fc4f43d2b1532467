"""Repetition: copies of a shape in a row, a grid or around an axis, as the union (Min) of placed copies,
so every copy's exact distance is kept (the tape engine prunes the copies far from an octant).
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy

from .csg import union
from .transforms import rotate, translate
from .vectors import Vec, vec3

MAX_COPIES = 4096
"""The most copies one repetition makes."""


def _count(n, name: str) -> int:
    if not isinstance(n, int) or not 1 <= n <= MAX_COPIES:
        raise ValueError(f"{name} must be a whole number from 1 to {MAX_COPIES}, got {n!r}")
    return n


def array_linear(expr: sympy.Expr, count: int, step: Vec) -> sympy.Expr:
    """``count`` copies of ``expr``, each ``step`` from the one before.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(array_linear(sphere(0.25), 3, (1, 0, 0)).subs({x: 2, y: 0, z: 0})), 6)
    -0.25
    """
    sx, sy, sz = vec3(step, "step")
    return union(*[translate(expr, (k * sx, k * sy, k * sz)) for k in range(_count(count, "count"))])


def array_grid(expr: sympy.Expr, counts: Sequence[int], spacing: Vec) -> sympy.Expr:
    """Copies of ``expr`` on a grid of ``counts`` (nx, ny, nz) with ``spacing`` between neighbours.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(array_grid(sphere(0.25), (2, 2, 1), (1, 1, 1)).subs({x: 1, y: 1, z: 0})), 6)
    -0.25
    """
    nx, ny, nz = (_count(n, "counts") for n in counts)
    if nx * ny * nz > MAX_COPIES:
        raise ValueError(f"at most {MAX_COPIES} copies, not {nx * ny * nz}")
    dx, dy, dz = vec3(spacing, "spacing")
    return union(*[translate(expr, (i * dx, j * dy, k * dz)) for i in range(nx) for j in range(ny)
                   for k in range(nz)])


def array_polar(expr: sympy.Expr, count: int, axis: str | Vec = "z") -> sympy.Expr:
    """``count`` copies of ``expr`` evenly around ``axis`` through the origin (the first where it is).

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import sphere
    >>> round(float(array_polar(sphere(0.25, (1, 0, 0)), 4).subs({x: 0, y: 1, z: 0})), 6)
    -0.25
    """
    n = _count(count, "count")
    return union(*[rotate(expr, 2 * sympy.pi * k / n, axis) for k in range(n)])
