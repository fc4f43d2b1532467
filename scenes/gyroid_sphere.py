"""Gyroid clipped by a sphere: max(sin 2πx·cos 2πy + sin 2πy·cos 2πz + sin 2πz·cos 2πx, r − 0.9) = 0.

Schoen's triply periodic minimal surface (approximated by its trigonometric level set), two periods per
unit, intersected with a ball of radius 0.9.
"""

import sympy

from implc import r, x, y, z

k = 2 * sympy.pi
gyroid = sympy.sin(k * x) * sympy.cos(k * y) + sympy.sin(k * y) * sympy.cos(k * z) + sympy.sin(k * z) * sympy.cos(k * x)
surface = sympy.Max(gyroid, r - sympy.Rational(9, 10))
bounds = ((-1, 1), (-1, 1), (-1, 1))
