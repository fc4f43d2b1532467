"""Gyroid-infilled part
====================

A rounded block printed the way a slicer fills it: a skin 0.05 thick around a gyroid lattice (``infill``),
shown with one corner cut away."""

import os

import sympy

from implc import shapes

R = sympy.Rational
part = shapes.infill(shapes.rounded_box((R(7, 10), R(7, 10), R(1, 2)), R(3, 20)), shapes.gyroid(R(2, 5), R(3, 10)),
                     R(1, 20))
surface = shapes.difference(part, shapes.box((R(1, 2), R(1, 2), R(3, 5)), (R(1, 2), R(-1, 2), R(3, 10))))
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (-30, 30)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "infill_block.png")
