"""Lattices: triply periodic minimal surfaces as walls of a thickness, for infill.

Each is the level set of a trigonometric field of period ``period`` (a cell's edge); ``abs(field) − t`` makes a
wall about 2t wide in field units (the fields' gradients are of order 2π/period, so the wall is about
t·period/π thick: not a distance). ``infill`` keeps the lattice inside a solid, within a skin.
"""

from __future__ import annotations

import sympy

from ..compiler.symbols import x, y, z
from .vectors import Number, absolute, maximum, minimum, positive


def _k(period: Number) -> sympy.Expr:
    return 2 * sympy.pi / positive(period, "period")


def gyroid(period: Number = 1, thickness: Number = sympy.Rational(3, 10)) -> sympy.Expr:
    """Schoen's gyroid: abs(sin x cos y + sin y cos z + sin z cos x) − t (in the cell's angles).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(gyroid(1, 0.3).subs({x: 0, y: 0, z: 0})), 6)
    -0.3
    """
    k = _k(period)
    a, b, c = k * x, k * y, k * z
    field = sympy.sin(a) * sympy.cos(b) + sympy.sin(b) * sympy.cos(c) + sympy.sin(c) * sympy.cos(a)
    return absolute(field) - positive(thickness, "thickness")


def schwarz_p(period: Number = 1, thickness: Number = sympy.Rational(3, 10)) -> sympy.Expr:
    """Schwarz's P surface: abs(cos x + cos y + cos z) − t.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(schwarz_p(1, 0.3).subs({x: 0.25, y: 0.25, z: 0.25})), 6)
    -0.3
    """
    k = _k(period)
    return absolute(sympy.cos(k * x) + sympy.cos(k * y) + sympy.cos(k * z)) - positive(thickness, "thickness")


def diamond(period: Number = 1, thickness: Number = sympy.Rational(3, 10)) -> sympy.Expr:
    """Schwarz's D (diamond) surface: abs(sin x sin y sin z + sin x cos y cos z + cos x sin y cos z
    + cos x cos y sin z) − t.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(diamond(1, 0.3).subs({x: 0, y: 0, z: 0})), 6)
    -0.3
    """
    k = _k(period)
    sx, sy, sz = sympy.sin(k * x), sympy.sin(k * y), sympy.sin(k * z)
    cx, cy, cz = sympy.cos(k * x), sympy.cos(k * y), sympy.cos(k * z)
    field = sx * sy * sz + sx * cy * cz + cx * sy * cz + cx * cy * sz
    return absolute(field) - positive(thickness, "thickness")


def neovius(period: Number = 1, thickness: Number = sympy.Rational(3, 10)) -> sympy.Expr:
    """Neovius' surface: abs(3(cos x + cos y + cos z) + 4 cos x cos y cos z) − t.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(neovius(1, 1).subs({x: 0.25, y: 0.25, z: 0.25})), 6)
    -1.0
    """
    k = _k(period)
    cx, cy, cz = sympy.cos(k * x), sympy.cos(k * y), sympy.cos(k * z)
    return absolute(3 * (cx + cy + cz) + 4 * cx * cy * cz) - positive(thickness, "thickness")


def infill(solid: sympy.Expr, lattice: sympy.Expr, skin: Number) -> sympy.Expr:
    """``solid`` as a printed part: a skin ``skin`` thick under its surface, the lattice inside it.

    >>> from implc.compiler.symbols import x, y, z
    >>> from implc.shapes import gyroid, sphere
    >>> round(float(infill(sphere(1), gyroid(0.5, 0.3), 0.1).subs({x: 0, y: 0, z: 0.95})), 6)
    -0.05
    """
    s = positive(skin, "skin")
    return maximum(solid, minimum(-solid - s, lattice))  # the skin, and the lattice within the solid
