"""Voxel files: ``.npz`` (exact round trip), binary ``.ply`` point clouds with normals, dense ``.npy``."""

from __future__ import annotations

import zipfile
from pathlib import Path

import numpy as np

from .voxelize import Voxels

FORMAT_VERSION = 1


class VoxelFileError(ValueError):
    """A voxel file is missing, unreadable or not one of ours."""


def save(voxels, path) -> Path:
    """Write ``voxels`` in the format named by the extension: .npz, .ply or .npy (dense occupancy)."""
    path = Path(path)
    writers = {".npz": save_npz, ".ply": save_ply, ".npy": save_dense}
    if path.suffix not in writers:
        raise ValueError(f"unknown output format {path.suffix!r} for {path}: use .npz, .ply or .npy")
    writers[path.suffix](voxels, path)
    return path


def save_npz(voxels, path) -> None:
    np.savez_compressed(path, implc_voxels=FORMAT_VERSION, coords=voxels.coords, normals=voxels.normals,
                        depth=voxels.depth, bounds=np.asarray(voxels.bounds, dtype=np.float64))


def load_npz(path):
    """The :class:`~implc.voxelize.Voxels` stored in an ``.npz`` written by :func:`save_npz`."""
    path = Path(path)
    try:
        with np.load(path) as data:
            if "implc_voxels" not in data:
                raise VoxelFileError(f"{path} is not an implc voxel file (no 'implc_voxels' entry)")
            coords, normals = data["coords"], data["normals"]
            depth, bounds = int(data["depth"]), tuple(tuple(b) for b in data["bounds"].tolist())
    except (OSError, ValueError, KeyError, zipfile.BadZipFile) as exc:
        if isinstance(exc, VoxelFileError):
            raise
        raise VoxelFileError(f"cannot read {path}: {exc}") from exc
    if coords.ndim != 2 or coords.shape[1] != 3 or normals.shape != coords.shape:
        raise VoxelFileError(f"{path}: coords and normals must both be (N, 3)")
    return Voxels(coords.astype(np.uint32, copy=False), normals.astype(np.float32, copy=False), depth, bounds,
                  stats=None)


def save_ply(voxels, path) -> None:
    """Binary little-endian PLY: one vertex per voxel centre with float x y z nx ny nz."""
    centers = voxels.centers().astype(np.float32)
    vertex = np.empty(len(centers), dtype=[(n, "<f4") for n in ("x", "y", "z", "nx", "ny", "nz")])
    for i, n in enumerate(("x", "y", "z")):
        vertex[n] = centers[:, i]
        vertex["n" + n] = voxels.normals[:, i]
    header = "\n".join([
        "ply", "format binary_little_endian 1.0",
        f"comment implc voxels depth {voxels.depth} bounds {list(map(list, voxels.bounds))}",
        f"element vertex {len(vertex)}",
        *[f"property float {n}" for n in ("x", "y", "z", "nx", "ny", "nz")],
        "end_header",
    ]) + "\n"
    with open(path, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vertex.tobytes())


def save_dense(voxels, path) -> None:
    """Dense occupancy as a bool ``.npy`` indexed [i, j, k]."""
    np.save(path, voxels.to_dense())
