"""Angle bracket
=============

An L-shaped bracket: two plates joined by a filleted corner and a triangular gusset, with four mounting
holes whose rims are rounded (smooth unions and differences)."""

import os

import sympy

from implc import shapes

R = sympy.Rational
base = shapes.rounded_box((R(3, 4), R(1, 2), R(1, 10)), R(3, 100), (R(1, 20), 0, R(-1, 2)))
upright = shapes.rounded_box((R(1, 10), R(1, 2), R(3, 5)), R(3, 100), (R(-3, 5), 0, R(1, 100)))
gusset = shapes.rotate(shapes.extrude(shapes.triangle((R(-1, 2), R(-1, 2)), (R(1, 2), R(-1, 2)),
                                                      (R(-1, 2), R(1, 2))), R(1, 10)), sympy.pi / 2, "x")
body = shapes.smooth_union(R(3, 20), base, upright, gusset)
drill = shapes.capped_cylinder(R(1, 10), 2)
holes = [shapes.translate(drill, (R(1, 2), s * R(3, 10), 0)) for s in (1, -1)]
holes += [shapes.translate(shapes.rotate(drill, sympy.pi / 2, "y"), (0, s * R(3, 10), R(1, 5))) for s in (1, -1)]
surface = shapes.smooth_difference(R(1, 25), body, *holes)
bounds = ((-1, 1), (-1, 1), (-1, 1))
depth = 8
view = (-55, 25)

if __name__ == "__main__":
    import implc
    from implc.view.render import View, render_voxels, save_png

    voxels = implc.voxelize(implc.compile(surface, bounds), int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8)))
    save_png(render_voxels(voxels, size=512, view=View(*view)), "bracket.png")
