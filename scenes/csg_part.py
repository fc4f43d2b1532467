"""CSG part: a rounded-off box with a spherical cavity and three drilled holes (Min/Max CSG).

max(box(0.7), −sphere(0.9), −cylinders of radius 0.3 along x, y and z) = 0.
"""

import sympy

from implc import shapes

R = sympy.Rational
body = shapes.intersection(shapes.box((R(7, 10),) * 3), shapes.sphere(R(19, 20)))
hole_z = shapes.cylinder(R(3, 10), 4)
hole_x = shapes.rotate(hole_z, sympy.pi / 2, "y")
hole_y = shapes.rotate(hole_z, sympy.pi / 2, "x")
surface = shapes.difference(body, hole_x, hole_y, hole_z)
bounds = ((-1, 1), (-1, 1), (-1, 1))
view = (35, 30)
