"""Torus: (sqrt(x² + y²) − 3/5)² + z² − (1/4)² = 0.

A ring of major radius 3/5 and minor radius 1/4 around the z axis. Classic.
"""

import sympy

from implc import shapes

surface = shapes.torus(sympy.Rational(3, 5), sympy.Rational(1, 4))
bounds = ((-1, 1), (-1, 1), (-1, 1))
view = (30, 35)
