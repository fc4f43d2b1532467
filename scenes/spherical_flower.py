"""Spherical flower: r − 0.55 − 0.25·cos(6φ)·sin²θ = 0, a surface given in spherical coordinates.

Six petals around the z axis; 2π-periodic in φ, so its boxes across the branch cut stay tight.
"""

import sympy

from implc import phi, r, theta

surface = r - sympy.Rational(11, 20) - sympy.Rational(1, 4) * sympy.cos(6 * phi) * sympy.sin(theta) ** 2
bounds = ((-1, 1), (-1, 1), (-1, 1))
view = (20, 50)
