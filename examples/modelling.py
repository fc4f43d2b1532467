"""Modelling a part, step by step
===============================

A tray in five steps (the walk-through of the guide's "Modelling parts"): a 2D sketch, extruded, its edges
rounded by offsets, hollowed to a shell and opened at the top, a polar array of holes in its floor."""

import os

import implc
from implc import shapes
from implc.view.render import View, render_voxels, save_png

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
sketch = shapes.difference(shapes.rounded_rectangle((0.8, 0.6), 0.25), shapes.circle(0.15))
block = shapes.extrude(sketch, 0.6)
rounded = shapes.offset(shapes.extrude(shapes.offset(sketch, -0.1), 0.4), 0.1)
tray = shapes.intersection(shapes.shell(rounded, 0.06), shapes.half_space((0, 0, 1), 0.2))
part = shapes.difference(tray, shapes.array_polar(shapes.capped_cylinder(0.07, 1, (0.4, 0, 0)), 8))
steps = [shapes.extrude(sketch, 0.1), block, rounded, tray, part]  # the sketch drawn as a thin plate
for k, step in enumerate(steps, 1):
    save_png(render_voxels(implc.voxelize(implc.compile(step), depth), size=400, view=View(30, 40)), f"step{k}.png")
