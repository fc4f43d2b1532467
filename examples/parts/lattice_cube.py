"""Lattice cube
============

A diamond (Schwarz D) lattice clipped to a cube, inside a frame of the cube's twelve edges."""

import os

import sympy

from implc import shapes

R = sympy.Rational
cube = shapes.box_exact((R(4, 5),) * 3)
frame = shapes.difference(cube, *[shapes.box_exact(tuple(1 if k == axis else R(7, 10) for k in range(3)))
                                  for axis in range(3)])
surface = shapes.union(frame, shapes.intersection(cube, shapes.diamond(R(4, 5), R(3, 10))))
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (35, 30)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "lattice_cube.png")
