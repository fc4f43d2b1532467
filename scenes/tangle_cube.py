"""Tangle cube (Goursat): x⁴ − 5x² + y⁴ − 5y² + z⁴ − 5z² + 11.8 = 0.

A classic quartic with six arms and eight bulbs. Source: Goursat's surfaces (Banchoff; MathWorld).
Written as Σ(t² − 5/2)² − 139/20, the same polynomial: each variable then appears once per term, which
keeps interval enclosures tight (x⁴ − 5x² evaluated term by term over-includes about 4x the cells).
"""

import sympy

from implc import x, y, z

half = sympy.Rational(5, 2)
surface = (x**2 - half) ** 2 + (y**2 - half) ** 2 + (z**2 - half) ** 2 - sympy.Rational(139, 20)
bounds = ((-3, 3), (-3, 3), (-3, 3))
