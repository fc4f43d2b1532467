"""Every shape of the library
==========================

One labelled tile per function of :mod:`implc.shapes`, one picture per group: each tile is the function's
solid voxelized and rendered on its own, then the tiles are laid out on a grid with numpy and labelled with
Pillow."""

import os

import numpy as np
import sympy
from PIL import Image, ImageDraw

import implc
from implc import shapes, x, y, z
from implc.view.render import View, render_voxels

depth = int(os.environ.get("IMPLC_EXAMPLE_DEPTH", 8))
R = sympy.Rational
SIZE, COLUMNS = 192, 5


def tile(name, expr, view=View(35, 25)):
    """The solid {expr < 0} in [-1, 1]³, rendered and labelled with ``name``. The default view fits each
    solid to its tile; a perspective view frames the whole cube instead, one scale for every tile."""
    voxels = implc.voxelize(implc.compile(expr), depth)
    image = Image.fromarray(render_voxels(voxels, size=SIZE, view=view))
    ImageDraw.Draw(image).text((8, 6), name, fill=(235, 235, 235))
    return np.asarray(image)


def sheet(tiles, path):
    """The tiles on a grid of COLUMNS, written to ``path``."""
    rows = -(-len(tiles) // COLUMNS)
    grid = np.zeros((rows * SIZE, COLUMNS * SIZE, 3), np.uint8)
    grid[:] = tiles[0][0, 0]  # the render's background
    for k, image in enumerate(tiles):
        grid[k // COLUMNS * SIZE:(k // COLUMNS + 1) * SIZE, k % COLUMNS * SIZE:(k % COLUMNS + 1) * SIZE] = image
    Image.fromarray(grid).save(path)


# %%
# 2D shapes and their ways into 3D
# --------------------------------
# A 2D shape is a function of x and y alone: each is shown extruded 0.5 high. ``revolve`` turns a 2D
# shape about the z axis (x its radius, y its height), ``loft`` goes from one section to another.

T = 0.5
sheet([
    tile("circle", shapes.extrude(shapes.circle(0.7), T)),
    tile("rectangle", shapes.extrude(shapes.rectangle((0.7, 0.45)), T)),
    tile("rounded_rectangle", shapes.extrude(shapes.rounded_rectangle((0.7, 0.45), 0.2), T)),
    tile("ring", shapes.extrude(shapes.ring(0.6, 0.2), T)),
    tile("convex_polygon", shapes.extrude(shapes.convex_polygon([(-0.7, -0.5), (0.6, -0.6), (0.7, 0.2),
                                                                  (0, 0.7), (-0.6, 0.3)]), T)),
    tile("regular_polygon", shapes.extrude(shapes.regular_polygon(6, 0.75), T)),
    tile("triangle", shapes.extrude(shapes.triangle((-0.7, -0.6), (0.7, -0.6), (0, 0.7)), T)),
    tile("extrude", shapes.extrude(shapes.regular_polygon(5, 0.5), 1.5, center=0.1)),
    tile("revolve", shapes.revolve(shapes.triangle((-0.2, -0.4), (0.25, -0.4), (0, 0.4)), 0.55)),
    tile("loft", shapes.loft(shapes.rectangle((0.6, 0.6)), shapes.circle(0.3), -0.7, 0.7)),
], "library_sketch.png")

# %%
# Solids
# ------
# The primitives, and the paper's blobs: ``blend`` is one blob's falloff g(d), ``blobs`` a sum of them.

squared = [(x - cx) ** 2 + y**2 + z**2 for cx in (-0.3, 0.35)]
sheet([
    tile("sphere", shapes.sphere(0.8)),
    tile("box", shapes.box((0.7, 0.5, 0.4))),
    tile("box_exact", shapes.box_exact((0.7, 0.5, 0.4))),
    tile("rounded_box", shapes.rounded_box((0.7, 0.5, 0.4), 0.15)),
    tile("torus", shapes.torus(0.6, 0.25)),
    tile("torus_exact", shapes.torus_exact(0.6, 0.25)),
    tile("cylinder", shapes.cylinder(0.5, 1.4)),
    tile("capped_cylinder", shapes.capped_cylinder(0.5, 1.4)),
    tile("capsule", shapes.capsule((-0.45, -0.45, -0.45), (0.45, 0.45, 0.45), 0.3)),
    tile("cone", shapes.cone(0.6, 1.4)),
    tile("ellipsoid", shapes.ellipsoid((0.8, 0.5, 0.35))),
    tile("half_space", shapes.half_space((1, 1, 2), 0)),
    tile("slab", shapes.slab((1, 1, 2), 0.5)),
    tile("pyramid", shapes.pyramid(0.7, 1.2, (0, 0, -0.6))),
    tile("tetrahedron", shapes.rotate(shapes.tetrahedron(0.35), sympy.pi / 2)),
    tile("octahedron", shapes.octahedron(0.5)),
    tile("dodecahedron", shapes.dodecahedron(0.6)),
    tile("icosahedron", shapes.icosahedron(0.6)),
    tile("blend", R(1, 5) - shapes.blend(squared[0], 0.75) - shapes.blend(squared[1], 0.6)),
    tile("blobs", shapes.blobs([(-0.35, 0, 0), (0.35, 0, 0), (0, 0.35, 0.3)], 0.65, 0.2)),
], "library_solids.png")

# %%
# Constructive solid geometry
# ---------------------------
# A box and a ball overlapping it, combined sharp, smooth (a fillet about 0.2 wide) and chamfered; ``morph``
# is halfway from the box to a centred ball.

A, B = shapes.box_exact((0.5, 0.5, 0.5)), shapes.sphere(0.55, (0.4, 0.4, 0.4))
sheet([
    tile("union", shapes.union(A, B)),
    tile("intersection", shapes.intersection(A, B)),
    tile("difference", shapes.difference(A, B)),
    tile("smooth_union", shapes.smooth_union(0.2, A, B)),
    tile("smooth_intersection", shapes.smooth_intersection(0.2, A, B)),
    tile("smooth_difference", shapes.smooth_difference(0.2, A, B)),
    tile("chamfer_union", shapes.chamfer_union(0.2, A, B)),
    tile("chamfer_intersection", shapes.chamfer_intersection(0.2, A, B)),
    tile("chamfer_difference", shapes.chamfer_difference(0.2, A, B)),
    tile("morph", shapes.morph(A, shapes.sphere(0.75), 0.5)),
], "library_csg.png")

# %%
# Offsets
# -------
# A cube of half size 0.6 (the first tile) grown, shrunk and hollowed, all drawn to one scale; the shells
# are cut open towards the viewer to show their walls; ``clearance`` leaves a gap of 0.1 around a pin.

cube, open_side = shapes.box_exact((0.6, 0.6, 0.6)), shapes.half_space((1, 1, 1), 0.3)
pin, scaled = shapes.capped_cylinder(0.25, 1.6), View(35, 25, perspective=True)
sheet([
    tile("box_exact (the cube)", shapes.box_exact((0.6, 0.6, 0.6)), scaled),
    tile("offset", shapes.offset(cube, 0.2), scaled),
    tile("dilate", shapes.dilate(cube, 0.35), scaled),
    tile("erode", shapes.erode(cube, 0.2), scaled),
    tile("shell", shapes.intersection(shapes.shell(shapes.sphere(0.85), 0.1), open_side), scaled),
    tile("inner_shell", shapes.intersection(shapes.inner_shell(cube, 0.1), open_side), scaled),
    tile("clearance", shapes.union(shapes.clearance(shapes.box_exact((0.7, 0.7, 0.3)), pin, 0.1), pin), scaled),
], "library_offsets.png")

# %%
# Deformations
# ------------
# A bar 0.6 × 0.6 × 1.6 twisted, bent, tapered and sheared; ``elongate`` stretches a ball.

bar = shapes.box((0.3, 0.3, 0.8))
sheet([
    tile("twist", shapes.twist(bar, 1.5)),
    tile("bend", shapes.bend(bar, 0.6)),
    tile("taper", shapes.taper(bar, -0.5)),
    tile("shear", shapes.shear(bar, 0.5)),
    tile("elongate", shapes.elongate(shapes.sphere(0.3), (0.4, 0, 0.25))),
], "library_deform.png")

# %%
# Repetition
# ----------

sheet([
    tile("array_linear", shapes.array_linear(shapes.sphere(0.2, (-0.7, 0, 0)), 4, (0.45, 0, 0))),
    tile("array_grid", shapes.array_grid(shapes.box_exact((0.15,) * 3, (-0.5,) * 3), (3, 3, 3), (0.5,) * 3)),
    tile("array_polar", shapes.array_polar(shapes.capsule((0.3, 0, 0), (0.75, 0, 0.3), 0.12), 8)),
], "library_repeat.png")

# %%
# Transforms
# ----------
# One asymmetric part (a bar with a ball on its +x end) moved, scaled, rotated, mapped by a 4×4 matrix,
# mirrored across x = 0 and made symmetric about it.

part = shapes.union(shapes.box((0.4, 0.12, 0.12), (0.2, 0, 0)), shapes.sphere(0.25, (0.55, 0, 0)))
sheet([
    tile("translate", shapes.translate(part, (-0.3, 0.3, 0.3))),
    tile("scale", shapes.scale(part, (1.2, 2, 2))),
    tile("rotate", shapes.rotate(part, sympy.pi / 2, (0, 1, 1))),
    tile("transform", shapes.transform(part, [[1, 0, 0, -0.3], [0, 1, 0, 0], [0.8, 0, 1, 0], [0, 0, 0, 1]])),
    tile("mirror", shapes.mirror(part, "x")),
    tile("symmetric", shapes.symmetric(part, "x")),
], "library_transforms.png")

# %%
# Lattices
# --------
# Each lattice clipped to a cube; ``infill`` fills a ball with a gyroid inside a skin (cut open).

clip = shapes.box_exact((0.75, 0.75, 0.75))
sheet([
    tile("gyroid", shapes.intersection(clip, shapes.gyroid(0.75, 0.3))),
    tile("schwarz_p", shapes.intersection(clip, shapes.schwarz_p(0.75, 0.3))),
    tile("diamond", shapes.intersection(clip, shapes.diamond(0.75, 0.3))),
    tile("neovius", shapes.intersection(clip, shapes.neovius(0.75, 0.8))),
    tile("infill", shapes.intersection(shapes.infill(shapes.sphere(0.85), shapes.gyroid(0.5, 0.3), 0.06),
                                       shapes.half_space((1, 1, 1), 0.2))),
], "library_lattices.png")
