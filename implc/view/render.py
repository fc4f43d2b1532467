"""Direct visualization of voxels (the paper's §6): each voxel is a shaded, z-buffered square splat.

Points come with their normals; shading is Lambert plus a Blinn-Phong highlight, lit from over the
viewer's shoulder, two-sided (a normal facing away from the camera is flipped). Cameras are orthographic
(default) or perspective, looking at the centre of the bounds from azimuth/elevation angles. A coarser
octree level (LOD) renders its nodes as larger splats with the mean normal of the voxels below.
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from ..common.atomic_file import replacing
from ..native.runtime import Runtime
from .splat_native import SPLAT


@dataclass(frozen=True)
class View:
    azimuth: float = 35.0  # degrees around +z, from +x towards +y
    elevation: float = 25.0  # degrees above the xy plane
    perspective: bool = False
    fov: float = 35.0  # vertical field of view for the perspective camera, degrees

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(forward, right, up) unit vectors; forward points from the eye into the scene."""
        az, el = np.radians(self.azimuth), np.radians(self.elevation)
        eye_dir = np.array([np.cos(el) * np.cos(az), np.cos(el) * np.sin(az), np.sin(el)])
        forward = -eye_dir
        right = np.cross(forward, [0.0, 0.0, 1.0])
        if np.linalg.norm(right) < 1e-9:  # looking straight down or up
            right = np.array([0.0, 1.0, 0.0]) if forward[2] < 0 else np.array([0.0, -1.0, 0.0])
        right /= np.linalg.norm(right)
        up = np.cross(right, forward)
        return forward, right, up


@dataclass(frozen=True)
class Style:
    color: tuple = (0.85, 0.62, 0.35)
    background: tuple = (0.08, 0.09, 0.11)
    ambient: float = 0.18
    specular: float = 0.35
    shininess: float = 40.0


def _shade(normals, forward, right, up, style: Style):
    n = normals / np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-12)
    facing = n @ -forward
    n = np.where(facing[:, None] < 0, -n, n)  # two-sided
    light = -forward + 0.6 * up - 0.4 * right
    light /= np.linalg.norm(light)
    half = light - forward
    half /= np.linalg.norm(half)
    diffuse = np.clip(n @ light, 0.0, 1.0)
    spec = np.clip(n @ half, 0.0, 1.0) ** style.shininess
    base = np.asarray(style.color)
    rgb = base * (style.ambient + (1 - style.ambient) * diffuse[:, None]) + style.specular * spec[:, None]
    return np.clip(rgb, 0.0, 1.0)


MAX_SIZE = 8192
"""The largest image (pixels per side): :data:`BYTES_PER_PIXEL` times its pixels of working memory."""
BYTES_PER_PIXEL = 100
"""A render's working memory per pixel (z-buffer, winners, shading, the image), rounded up from the peak
measured at the largest sizes."""


def render_points(centers: np.ndarray, normals: np.ndarray, cell_size: np.ndarray, bounds: Any, *, size: int = 1024,
                  view: View = View(), style: Style = Style()) -> np.ndarray:
    """An (size, size, 3) uint8 image of points with normals, each drawn as a square of its cell's size.

    Only the points that win a pixel are shaded; the z-buffer runs natively (``implc_splat``).
    """
    if size < 16 or size > MAX_SIZE:
        raise ValueError(f"image size must be from 16 to {MAX_SIZE} pixels, got {size}")
    lo, hi = np.asarray(bounds, dtype=np.float64).T
    target = (lo + hi) / 2
    radius = np.linalg.norm(hi - lo) / 2
    forward, right, up = view.basis()
    rel = np.asarray(centers, dtype=np.float64) - target
    sx, sy, depth = rel @ right, rel @ up, rel @ forward
    if view.perspective:
        distance = radius / np.tan(np.radians(view.fov) / 2) * 1.05
        z = depth + distance
        scale = (size / 2) / (radius / distance * 1.0) / z[:, None][:, 0]
        px, py = sx * scale, sy * scale
        splat = np.maximum(np.ceil(float(np.max(cell_size)) * scale * 1.2), 1).astype(np.int64)
    else:  # fit the points' projected extent, with a margin
        if len(sx):
            sx, sy = sx - (sx.min() + sx.max()) / 2, sy - (sy.min() + sy.max()) / 2
            extent = max(np.abs(sx).max(), np.abs(sy).max()) + float(np.max(cell_size))
        else:
            extent = radius
        scale = (size / 2) * 0.92 / extent
        px, py = sx * scale, sy * scale
        z = depth
        splat = np.full(len(px), max(1, int(np.ceil(float(np.max(cell_size)) * scale * 1.2))), dtype=np.int64)
    cx = np.ascontiguousarray(np.floor(px + size / 2), dtype=np.int64)
    cy = np.ascontiguousarray(np.floor(size / 2 - py), dtype=np.int64)
    zbuf = np.full(size * size, np.inf)
    winner = np.full(size * size, -1, dtype=np.int64)
    z = np.ascontiguousarray(z, dtype=np.float64)
    splat = np.ascontiguousarray(splat, dtype=np.int64)
    splat_routines = Runtime.shared().library(SPLAT)
    splat_routines.splat(cx.ctypes.data, cy.ctypes.data, splat.ctypes.data, z.ctypes.data, len(z), size,
                  zbuf.ctypes.data, winner.ctypes.data)
    image = np.empty((size * size, 3), dtype=np.uint8)
    image[:] = (np.asarray(style.background) * 255 + 0.5).astype(np.uint8)
    hit = winner >= 0
    shown = winner[hit]
    colors = _shade(np.asarray(normals)[shown].astype(np.float64), forward, right, up, style)
    image[hit] = (colors * 255 + 0.5).astype(np.uint8)
    return image.reshape(size, size, 3)


AXES = "xyz"


def cross_section(voxels: Any, axis: int, index: int) -> np.ndarray:
    """The cells of layer ``index`` along ``axis`` that the voxels' solid covers: the boundary voxels there
    and every cell of the inside octants that cross it ((m, 3) uint32; a shell has only its voxels)."""
    parts = [voxels.coords[voxels.coords[:, axis] == index].astype(np.int64)]
    inside = voxels.inside if getattr(voxels, "inside", None) is not None else np.empty((0, 4), np.int32)
    others = [a for a in range(3) if a != axis]
    for level in np.unique(inside[:, 3]):
        size = 1 << (voxels.depth - int(level))
        rows = inside[(inside[:, 3] == level) & (inside[:, axis] == index // size)].astype(np.int64)
        if not len(rows):
            continue
        offsets = np.stack(np.meshgrid(np.arange(size), np.arange(size), indexing="ij"), -1).reshape(-1, 2)
        cells = np.empty((len(rows) * len(offsets), 3), dtype=np.int64)
        cells[:, axis] = index
        for n, a in enumerate(others):
            cells[:, a] = (rows[:, a, None] * size + offsets[None, :, n]).ravel()
        parts.append(cells)
    return np.concatenate(parts).astype(np.uint32)


def render_voxels(voxels: Any, *, size: int = 1024, view: View = View(), style: Style = Style(),
                  lod: int | None = None, cut: tuple[int, float] | None = None) -> np.ndarray:
    """Render a :class:`~implc.voxelizer.voxelize.Voxels` (or anything with coords, normals, depth, bounds).

    ``cut = (axis, value)``: a cut-away. Everything beyond the plane (coordinate ``axis`` above ``value``,
    in world units) is removed, and the cross-section on the plane is drawn facing the removed side: for a
    solid (``voxelize(..., solid=True)``) the filled section, for a shell only the surface's ring."""
    depth = voxels.depth
    coords, normals = voxels.coords, voxels.normals
    if lod is not None:
        if not 1 <= lod <= depth:
            raise ValueError(f"lod must be from 1 to {depth}, got {lod}")
        if cut is not None:
            raise ValueError("a cut-away is drawn from the voxels, not from an octree level (drop lod)")
        coords, normals = voxels.octree.level(lod)
        depth = lod
    if cut is not None:
        axis, value = cut
        lo_axis, hi_axis = voxels.bounds[axis]
        if not lo_axis <= value <= hi_axis:
            raise ValueError(f"the cut {AXES[axis]}={value} lies outside the bounds {lo_axis}..{hi_axis}")
        index = min(int((value - lo_axis) / (hi_axis - lo_axis) * (1 << depth)), (1 << depth) - 1)
        keep = coords[:, axis] < index
        section = cross_section(voxels, axis, index)
        facing = np.zeros((len(section), 3), dtype=np.float32)
        facing[:, axis] = 1.0
        coords = np.concatenate([coords[keep], section])
        normals = np.concatenate([normals[keep], facing])
    lo = np.array([b[0] for b in voxels.bounds], dtype=np.float64)
    cell = np.array([(b[1] - b[0]) / (1 << depth) for b in voxels.bounds])
    centers = lo + (coords.astype(np.float64) + 0.5) * cell
    return render_points(centers, normals, cell, voxels.bounds, size=size, view=view, style=style)


def save_png(image: np.ndarray, path: str | os.PathLike[str]) -> None:
    """Write an RGB uint8 image with Pillow, under a temporary name renamed into place."""
    from PIL import Image
    with replacing(path) as tmp:
        Image.fromarray(np.ascontiguousarray(image), mode="RGB").save(tmp, format="PNG")
