"""Scene 2 of Stolte & Kaufman: sin(4θ)·sin(8φ) − r = 0, a surface given in spherical coordinates.

r ≤ |sin 4θ · sin 8φ| ≤ 1, so the unit cube holds it. Source: Stolte & Kaufman, Fig. 5(a).
"""

import sympy

from implc import phi, r, theta

surface = sympy.sin(4 * theta) * sympy.sin(8 * phi) - r
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 9
