"""Spur gear
=========

An 18-tooth spur gear: trapezoid teeth set around the rim by a polar array, a raised hub, five lightening
holes and a keyed bore."""

import os

import sympy

from implc import shapes

R = sympy.Rational
tooth = shapes.extrude(shapes.convex_polygon([(R(60, 100), R(-8, 100)), (R(80, 100), R(-4, 100)),
                                              (R(80, 100), R(4, 100)), (R(60, 100), R(8, 100))]), R(1, 5))
rim = shapes.union(shapes.capped_cylinder(R(64, 100), R(1, 5)), shapes.array_polar(tooth, 18))
hub = shapes.capped_cylinder(R(25, 100), R(2, 5))
holes = shapes.array_polar(shapes.capped_cylinder(R(9, 100), 1, (R(43, 100), 0, 0)), 5)
bore = shapes.union(shapes.capped_cylinder(R(1, 10), 1), shapes.box((R(3, 100), R(3, 100), 1), (R(11, 100), 0, 0)))
surface = shapes.difference(shapes.union(rim, hub), holes, bore)
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (30, 40)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "gear.png")
