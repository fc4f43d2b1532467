"""Scene 3 of Stolte & Kaufman: sin(3θ)·sin(4φ) − r = 0, a surface given in spherical coordinates.

Source: Stolte & Kaufman, Fig. 5(b).
"""

import sympy

from implc import phi, r, theta

surface = sympy.sin(3 * theta) * sympy.sin(4 * phi) - r
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 9
