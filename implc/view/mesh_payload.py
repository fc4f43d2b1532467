"""A triangle mesh as the browser viewer reads it: ``meta.json`` (``"kind": "mesh"``) and one ``mesh.bin``.

``mesh.bin``: a header of eight little-endian uint32 (:data:`MAGIC`, :data:`VERSION`, vertices V,
triangles T, then zeros), the positions (V × 3 float32, world coordinates), the unit normals (V × 3
float32) and the triangles (T × 3 uint32 vertex indices, counter-clockwise seen from outside). The page
draws it whole with WebGL2 (no level of detail: a mesh of a few million triangles is one draw call); the
normals are F's gradient where the mesh came from implc, else the area-weighted mean of the faces around
each vertex (a file that carries none).
"""

from __future__ import annotations

import numpy as np

from .json_text import json_bytes

MAGIC = 0x484D4D49  # "IMMH" read as a little-endian uint32
VERSION = 1
HEADER_WORDS = 8
MAX_TRIANGLES = (1 << 32) // 3 - 1
"""Vertex indices are uint32 in the page's index buffer."""


def vertex_normals(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """The area-weighted mean normal of the triangles around each vertex, unit length (+z where none)."""
    p = vertices[faces]
    area = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    summed = np.zeros_like(vertices, dtype=np.float64)
    for k in range(3):
        np.add.at(summed, faces[:, k], area)
    length = np.linalg.norm(summed, axis=1)
    out = np.zeros_like(summed)
    out[:, 2] = 1.0
    good = length > 0
    out[good] = summed[good] / length[good, None]
    return out


class MeshPayload:
    """What the viewer shows of a mesh (an :class:`implc.Mesh`): its meta and its ``mesh.bin``."""

    def __init__(self, mesh, name: str = "", view=None):
        faces = np.asarray(mesh.faces)
        if len(faces) > MAX_TRIANGLES:
            raise ValueError(f"the viewer draws at most {MAX_TRIANGLES:,} triangles, this mesh has {len(faces):,}")
        self.name = name
        self.vertices = np.asarray(mesh.vertices, dtype=np.float64)
        self.faces = faces
        normals = None if mesh.normals is None else np.asarray(mesh.normals, dtype=np.float64)
        if normals is None or not np.isfinite(normals).all():
            fallback = vertex_normals(self.vertices, faces)
            if normals is not None:
                usable = np.isfinite(normals).all(axis=1, keepdims=True)
                fallback = np.where(usable, normals, fallback)
            normals = fallback
        self.normals = normals
        if mesh.bounds is not None:
            self.bounds = [[float(lo), float(hi)] for lo, hi in mesh.bounds]
        elif len(self.vertices):
            self.bounds = [[float(lo), float(hi)] for lo, hi in zip(self.vertices.min(0), self.vertices.max(0))]
        else:
            self.bounds = [[-1.0, 1.0]] * 3
        self.view = list(view) if view is not None else [35.0, 25.0]

    def meta(self, budget: int = 1_000_000) -> dict:
        """What the viewer needs before the mesh (``budget`` is the point viewer's; kept for the same call)."""
        return {"kind": "mesh", "name": self.name, "bounds": self.bounds, "view": self.view,
                "vertices": len(self.vertices), "triangles": len(self.faces), "budget": int(budget)}

    def meta_json(self, budget: int = 1_000_000) -> bytes:
        return json_bytes(self.meta(budget))

    def body(self) -> bytes:
        """``mesh.bin`` (see the module docstring)."""
        header = np.zeros(HEADER_WORDS, dtype="<u4")
        header[:4] = MAGIC, VERSION, len(self.vertices), len(self.faces)
        parts = [header, self.vertices.astype("<f4"), self.normals.astype("<f4"), self.faces.astype("<u4")]
        return b"".join(np.ascontiguousarray(p).tobytes() for p in parts)

    @property
    def size(self) -> int:
        """Bytes of ``mesh.bin``."""
        return 4 * HEADER_WORDS + 24 * len(self.vertices) + 12 * len(self.faces)
