"""Twisted vase
============

A rounded pentagon extruded, flared by a taper and twisted a fifth of a turn, then hollowed to a wall 0.05
thick (``shell``) and cut open at the top."""

import os

import sympy

from implc import shapes

R = sympy.Rational
section = shapes.offset(shapes.regular_polygon(5, R(2, 5)), R(1, 10))
body = shapes.twist(shapes.taper(shapes.extrude(section, R(8, 5)), R(-1, 4), R(-4, 5)), sympy.pi / 4)
surface = shapes.intersection(shapes.shell(body, R(1, 20)), shapes.half_space((0, 0, 1), R(3, 4)))
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (30, 30)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "vase.png")
