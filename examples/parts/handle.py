"""Lofted handle
=============

A tool handle lofted from a rounded hexagon at the palm end to a round neck, with six flutes along its
grip, a ferrule collar and a bore for the blade's tang."""

import os

import sympy

from implc import shapes

R = sympy.Rational
grip = shapes.loft(shapes.offset(shapes.regular_polygon(6, R(3, 10)), R(1, 10)), shapes.circle(R(1, 5)),
                   R(-4, 5), R(1, 2))
palm = shapes.sphere(R(7, 20), (0, 0, R(-7, 10)))
flutes = shapes.array_polar(shapes.capsule((R(37, 100), 0, R(-1, 2)), (R(27, 100), 0, R(3, 10)), R(1, 12)), 6,)
collar = shapes.capped_cylinder(R(11, 50), R(1, 5), (0, 0, R(3, 5)))
body = shapes.smooth_union(R(1, 20), shapes.smooth_difference(R(1, 25), shapes.smooth_union(R(1, 10), grip, palm),
                                                                flutes), collar)
surface = shapes.difference(body, shapes.capped_cylinder(R(1, 20), 1, (0, 0, R(1, 2))))
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (30, 25)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "handle.png")
