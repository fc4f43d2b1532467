"""The README's picture of meshes: flat-shaded triangles with their edges drawn, back to front (Pillow).

    python benchmarks/mesh_picture.py docs/images/meshes.png

Each panel meshes a scene at a coarse grid, so that the triangles (and the sharp creases of CSG) can be
seen: above as ``implc.mesh`` does (one vertex per dual cell), below with the tetrahedral construction in
every cell (``lean=False``: about three vertices a crossed cell).
"""

from __future__ import annotations

import sys

import numpy as np
from PIL import Image, ImageDraw

import implc
from implc.files import scene
from implc.meshing.contour import contour

PANELS = (("csg_part", 4), ("paper_blobs", 5), ("torus", 4))
SIZE = 520


def draw(mesh, size=SIZE, view=(35.0, 25.0)) -> Image.Image:
    """The mesh seen from azimuth/elevation ``view`` (degrees), orthographic, Lambert-shaded faces."""
    az, el = np.radians(view)
    forward = -np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
    right = np.cross(forward, [0, 0, 1.0])
    right /= np.linalg.norm(right)
    up = np.cross(right, forward)
    p = mesh.vertices[mesh.faces]
    normal = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    normal /= np.linalg.norm(normal, axis=1)[:, None]
    facing = normal @ forward < 0  # closed and oriented outward: the back faces are hidden
    p, normal = p[facing], normal[facing]
    centre = mesh.vertices.mean(axis=0)
    radius = np.abs(mesh.vertices - centre).max() * 1.8
    xy = np.stack([(p - centre) @ right, -(p - centre) @ up], -1) / radius * size * 0.5 + size / 2
    depth = ((p - centre) @ forward).mean(axis=1)
    light = -forward + 0.6 * up
    light /= np.linalg.norm(light)
    shade = 0.45 + 0.55 * np.clip(normal @ light, 0, 1)
    image = Image.new("RGB", (size, size), (255, 255, 255))
    pen = ImageDraw.Draw(image)
    for k in np.argsort(-depth):  # far to near
        tone = tuple(int(c * shade[k]) for c in (150, 195, 250))
        pen.polygon([tuple(v) for v in xy[k]], fill=tone, outline=(60, 80, 115))
    return image


def main(path: str) -> None:
    rows = []
    for lean in (True, False):  # the default mesh above, the tetrahedral construction everywhere below
        panels = []
        for name, depth in PANELS:
            sc = scene.load(name)
            surface = implc.compile(sc.surface, sc.bounds)
            voxels = implc.voxelize(surface, depth, **implc.NATURAL)
            mesh = contour(surface, voxels.coords, depth, voxels.bounds, lean=lean)
            panels.append(draw(mesh, view=sc.view or (35.0, 25.0)))
        rows.append(panels)
    sheet = Image.new("RGB", (SIZE * len(PANELS), SIZE * len(rows)), (255, 255, 255))
    for r, panels in enumerate(rows):
        for k, panel in enumerate(panels):
            sheet.paste(panel, (k * SIZE, r * SIZE))
    sheet.save(path)


if __name__ == "__main__":
    main(sys.argv[1] if len(sys.argv) > 1 else "meshes.png")
