"""Heart (Taubin's heart surface): (x² + 9/4·y² + z² − 1)³ − x²z³ − 9/80·y²z³ = 0.

Source: G. Taubin, "An accurate algorithm for rasterizing algebraic curves and surfaces" (1994).
"""

import sympy

from implc import x, y, z

surface = (x**2 + sympy.Rational(9, 4) * y**2 + z**2 - 1) ** 3 - x**2 * z**3 - sympy.Rational(9, 80) * y**2 * z**3
bounds = ((-1.5, 1.5), (-1.5, 1.5), (-1.5, 1.5))
view = (90, 10)
