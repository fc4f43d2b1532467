"""Round heat sink
===============

A pin-less radial heat sink: 24 fins set around a central core by a polar array, on a base disc with four
mounting holes."""

import os

import sympy

from implc import shapes

R = sympy.Rational
base = shapes.capped_cylinder(R(9, 10), R(3, 20), (0, 0, R(-11, 20)))
core = shapes.capped_cylinder(R(1, 4), R(11, 10), (0, 0, 0))
fins = shapes.array_polar(shapes.box_exact((R(23, 100), R(1, 50), R(9, 20)), (R(47, 100), 0, R(1, 20))), 24)
holes = shapes.array_polar(shapes.capped_cylinder(R(1, 20), 1, (R(4, 5), 0, R(-1, 2))), 4)
surface = shapes.difference(shapes.smooth_union(R(1, 20), base, shapes.union(core, fins)),
                            shapes.rotate(holes, sympy.pi / 4), shapes.capped_cylinder(R(1, 10), 3))
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (30, 35)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "heatsink.png")
