"""Scene 1 of Stolte & Kaufman: ten spheres blended with the polynomial g(d) = (d² − R²)⁴ / R⁸.

F(x, y, z) = C − Σᵢ g(|p − cᵢ|), negative inside. The paper does not list its centres or constants; these
are ours: ten centres on a ring of radius 0.6 in the xy plane, undulating ±0.25 in z, blob radius
R = 2/5 and threshold C = 1/4 (a lone blob then has radius R·sqrt(1 − C^¼) ≈ 0.22, and neighbours,
0.37 apart, blend into a necklace).
Source: Stolte & Kaufman, "Parallel spatial enumeration of implicit surfaces using interval arithmetic
for octree generation and its direct visualization" (Fig. 4).
"""

import math

import sympy

from implc import shapes

CENTERS = [  # rounded to exact thousandths, so the scene is the same rational expression everywhere
    (sympy.Rational(round(600 * math.cos(2 * math.pi * k / 10)), 1000),
     sympy.Rational(round(600 * math.sin(2 * math.pi * k / 10)), 1000),
     sympy.Rational(round(250 * math.sin(4 * math.pi * k / 10)), 1000))
    for k in range(10)
]
RADIUS = sympy.Rational(2, 5)
THRESHOLD = sympy.Rational(1, 4)

surface = shapes.blobs(CENTERS, RADIUS, THRESHOLD)
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 9
view = (30, 50)
