"""Knurled knob
============

A control knob: a domed cap with a diamond knurl (two polar arrays of grooves twisted in opposite senses),
on a flange, with a D-shaped shaft hole underneath."""

import os

import sympy

from implc import shapes

R = sympy.Rational
cap = shapes.smooth_intersection(R(1, 10), shapes.capped_cylinder(R(3, 5), R(7, 10), (0, 0, R(1, 20))),
                                 shapes.sphere(R(23, 20), (0, 0, R(-7, 10))))
groove = shapes.array_polar(shapes.capped_cylinder(R(1, 25), 2, (R(3, 5), 0, 0)), 24)
knurled = shapes.difference(cap, shapes.twist(groove, 2), shapes.twist(groove, -2))
flange = shapes.capped_cylinder(R(7, 10), R(1, 10), (0, 0, R(-7, 20)))
shaft = shapes.difference(shapes.capped_cylinder(R(3, 20), R(7, 10), (0, 0, R(-1, 2))),
                          shapes.half_space((-1, 0, 0), R(-1, 10)))  # D-shaped: flat at x = 0.1
surface = shapes.difference(shapes.smooth_union(R(1, 20), knurled, flange), shaft)
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (30, 35)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "knob.png")
