"""Voxel files: ``.npz`` (exact round trip), binary ``.ply`` point clouds with normals, dense ``.npy``;
the writers of ``.vdb`` (:mod:`implc.files.vdb`) and ``.zarr`` (:mod:`implc.files.zarr_store`) by extension.

Every file is written under a temporary name and renamed into place (:mod:`implc.common.atomic_file`): an
interrupted save never damages an existing file. Reading checks what a file is by its first bytes and
validates an ``.npz`` completely (depth, bounds, coordinates inside the grid, finite unit normals), so a
foreign, truncated or damaged file is a :class:`VoxelFileError` naming the problem.
"""

from __future__ import annotations

import os
import tokenize
import zipfile
import zlib
from pathlib import Path
from typing import Any

import numpy as np

from ..common.atomic_file import replacing
from ..common.bounds import usable_bounds
from ..common.untrusted import ply_elements, ply_header, printable, regular_file
from ..engines.morton import morton_codes
from ..errors import VoxelFileError
from ..native.abi import MAX_DEPTH
from ..voxelizer.voxelize import Voxels, available_memory
from .store_place import is_url, target_of
from .vdb import describe_vdb, save_vdb

FORMAT_VERSION = 1
SUFFIXES = (".npz", ".ply", ".npy", ".vdb", ".zarr")
_MAGIC = {b"PK\x03\x04": ".npz", b"PK\x05\x06": ".npz", b"\x93NUMPY": ".npy", b"ply\n": ".ply", b"ply\r": ".ply",
          b" BDV": ".vdb"}


def suffix_of(path: str | os.PathLike[str]) -> str:
    """The format a path names by its extension, in lower case (``A.NPZ`` is an .npz)."""
    return Path(path).suffix.lower()


def save(voxels: Voxels, path: str | os.PathLike[str], *, compress: bool = False) -> Path | str:
    """Write ``voxels`` in the format named by the extension: .npz, .ply, .npy (dense occupancy), .vdb
    (OpenVDB occupancy and normals grids: :mod:`implc.files.vdb`) or .zarr (a Zarr v3 array of the
    occupancy, written shard by shard: :mod:`implc.files.zarr_store`).

    ``compress``: deflate the .npz (about 3x smaller for Morton-ordered voxels, and several times slower).
    """
    from .zarr_writer import save_zarr
    if is_url(path) and suffix_of(path) != ".zarr":
        raise ValueError(f"{path}: only a .zarr store is written to an object store (write other formats to a file)")
    path = target_of(path)
    writers = {".npz": lambda v, p: save_npz(v, p, compress=compress), ".ply": save_ply, ".npy": save_dense,
               ".vdb": save_vdb, ".zarr": save_zarr}
    suffix = suffix_of(path)
    if suffix not in writers:
        raise ValueError(f"unknown output format {suffix or '(none)'!r} for {path}: use {', '.join(SUFFIXES)}")
    writers[suffix](voxels, path)
    return path


def save_npz(voxels: Voxels, path: str | os.PathLike[str], *, compress: bool = False) -> None:
    """``voxels`` as an ``.npz`` that :func:`load_npz` reads back exactly (coords, normals, depth, bounds,
    and a solid's inside octants); ``compress``: deflated."""
    arrays: dict[str, Any] = dict(implc_voxels=FORMAT_VERSION, coords=voxels.coords, normals=voxels.normals,
                                  depth=voxels.depth, bounds=np.asarray(voxels.bounds, dtype=np.float64))
    if getattr(voxels, "inside", None) is not None:  # a solid: its inside octants (i, j, k, level)
        arrays["inside"] = voxels.inside
    with replacing(path) as tmp:
        (np.savez_compressed if compress else np.savez)(tmp, **arrays)


def sniff(path: str | os.PathLike[str]) -> str:
    """The format of an existing file by its first bytes: ".npz", ".npy", ".ply", ".vdb" or "" (unknown)."""
    with open(path, "rb") as f:
        head = f.read(8)
    return next((fmt for magic, fmt in _MAGIC.items() if head.startswith(magic)), "")


MAX_RATIO = 200
"""The most an ``.npz`` member may inflate beyond 64 MiB (a Morton-ordered one deflates about 3×): more
is a zip bomb, refused before it is inflated."""


def _check_readable(path: Path) -> str:
    regular_file(path, VoxelFileError)
    try:
        fmt = sniff(path)
    except OSError as exc:
        raise VoxelFileError(f"cannot read {path}: {exc.strerror or exc}") from None
    if not fmt:
        size = path.stat().st_size
        raise VoxelFileError(f"{path} is {'empty' if size == 0 else 'not a voxel file'} "
                             "(implc reads the .npz, .ply, .npy and .vdb files it writes)")
    return fmt


def load(path: str | os.PathLike[str], region: Any = None) -> Voxels:
    """The voxels of an ``.npz`` (:func:`load_npz`) or of a Zarr store (``.zarr``: all, or ``region``,
    cell ranges ((i0, i1), (j0, j1), (k0, k1)): :func:`implc.files.zarr_store.load_zarr`)."""
    path = target_of(path)  # a store's URL as given, file:// as its path
    if isinstance(path, str) or path.is_dir():
        from .zarr_store import load_zarr
        voxels = load_zarr(path, region)  # checked as an .npz is: a damaged store must not reach native code
        coords, normals, depth, bounds = _validated(path, voxels.coords, voxels.normals, np.asarray(voxels.depth),
                                                    np.asarray(voxels.bounds, dtype=np.float64))
        inside = _validated_inside(path, voxels.inside, depth)
        return Voxels(coords, normals, depth, bounds, stats=None, inside=inside)
    if region is not None:
        raise ValueError("region= reads part of a Zarr store; an .npz is read whole")
    return load_npz(path)


def load_npz(path: str | os.PathLike[str]) -> Voxels:
    """The :class:`~implc.voxelizer.voxelize.Voxels` stored in an ``.npz`` written by :func:`save_npz`, validated."""
    path = Path(path)
    fmt = _check_readable(path)
    if fmt != ".npz":
        what = {".ply": "a PLY point cloud", ".npy": "a dense .npy occupancy grid", ".vdb": "an OpenVDB file"}[fmt]
        raise VoxelFileError(f"{path} is {what}: voxels are read back from the .npz files implc writes")
    try:
        _check_inflation(path)
        with np.load(path, allow_pickle=False) as data:
            if "implc_voxels" not in data:
                raise VoxelFileError(f"{path} is not an implc voxel file (no 'implc_voxels' entry)")
            missing = [k for k in ("coords", "normals", "depth", "bounds") if k not in data]
            if missing:
                raise VoxelFileError(f"{path}: damaged implc voxel file, missing {', '.join(missing)}")
            arrays = {k: data[k] for k in ("coords", "normals", "depth", "bounds", "inside") if k in data}
    except VoxelFileError:
        raise
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile, zlib.error, NotImplementedError,
            SyntaxError, tokenize.TokenError) as exc:  # the last two: numpy's parser of a damaged .npy header
        raise VoxelFileError(f"cannot read {path}: damaged or truncated ({type(exc).__name__}: "
                             f"{printable(str(exc), 120)})") from None
    for name, value in arrays.items():
        if not isinstance(value, np.ndarray):  # a member that is not a .npy array comes back as bytes
            raise VoxelFileError(f"{path}: damaged implc voxel file, {name} is not an array")
    coords, normals, depth, bounds = (arrays[k] for k in ("coords", "normals", "depth", "bounds"))
    inside = arrays.get("inside")
    coords, normals, depth, bounds = _validated(path, coords, normals, depth, bounds)
    inside = _validated_inside(path, inside, depth)
    _check_disjoint(path, coords, inside, depth)
    return Voxels(coords, normals, depth, bounds, stats=None, inside=inside)


def _check_inflation(path):
    """VoxelFileError for an ``.npz`` whose members would inflate past :data:`MAX_RATIO` times their
    stored size (beyond 64 MiB), or past the memory there is, before anything is inflated."""
    with zipfile.ZipFile(path) as archive:
        members = archive.infolist()
        for m in members:
            if m.file_size > (64 << 20) and m.file_size > MAX_RATIO * max(m.compress_size, 1):
                raise VoxelFileError(f"{path}: member {printable(m.filename, 60)} would inflate from "
                                     f"{m.compress_size} to {m.file_size} bytes (a zip bomb, or damaged)")
        total = sum(m.file_size for m in members)
        if total > available_memory():
            raise VoxelFileError(f"{path}: its arrays take {total / 2**30:.1f} GiB, more than the memory "
                                 f"available ({available_memory() / 2**30:.1f} GiB)")
        for m in members:
            if m.filename.endswith(".npy"):
                with archive.open(m) as f:
                    _check_npy_header(path, m, f)


def _check_npy_header(path, member, f):
    """VoxelFileError where a member's .npy header claims more bytes than the member holds (numpy would
    allocate what the header says before finding the data missing)."""
    from numpy.lib import format as npy
    version = npy.read_magic(f)
    shape, _, dtype = (npy.read_array_header_1_0 if version == (1, 0) else npy.read_array_header_2_0)(f)
    if dtype.hasobject:
        raise VoxelFileError(f"{path}: member {printable(member.filename, 60)} holds Python objects")
    claimed = int(np.prod(shape, dtype=object)) * dtype.itemsize
    if claimed > member.file_size:
        raise VoxelFileError(f"{path}: member {printable(member.filename, 60)} claims {claimed} bytes of array "
                             f"in {member.file_size} (damaged)")


def _octant_ranges(inside: np.ndarray, depth: int) -> tuple[np.ndarray, np.ndarray]:
    """Each inside octant's cells as a range [start, end) of Morton codes at ``depth``."""
    levels = inside[:, 3].astype(np.int64)
    shift = (3 * (depth - levels)).astype(np.uint64)
    start = morton_codes(inside[:, :3].astype(np.uint32)) << shift
    return start, start + (np.uint64(1) << shift)


def _check_disjoint(path, coords, inside, depth):
    """VoxelFileError where two inside octants overlap (a duplicate included) or an inside octant holds a
    boundary voxel: either would count cells twice in the volume."""
    if inside is None or not len(inside):
        return
    start, end = _octant_ranges(inside, depth)
    order = np.argsort(start, kind="stable")
    start, end = start[order], end[order]
    if np.any(end[:-1] > start[1:]):
        raise VoxelFileError(f"{path}: inside octants overlap (or repeat): a solid's octants are disjoint")
    if len(coords):
        codes = morton_codes(coords)
        row = np.searchsorted(start, codes, side="right") - 1
        held = (row >= 0) & (codes < end[np.maximum(row, 0)])
        if held.any():
            raise VoxelFileError(f"{path}: {int(held.sum())} boundary voxels lie inside inside octants")


def _validated_inside(path, inside, depth):
    """A solid's inside octants as save_npz writes them (None for a shell); VoxelFileError otherwise."""
    if inside is None:
        return None
    if inside.ndim != 2 or inside.shape[1:] != (4,) or inside.dtype.kind not in "iu":
        raise VoxelFileError(f"{path}: inside must be an (N, 4) integer array, got {inside.dtype} {inside.shape}")
    if len(inside):  # compared in the array's own type, before any cast could wrap a forged value
        levels, cells = inside[:, 3], inside[:, :3]
        if levels.min() < 1 or levels.max() > depth or cells.min() < 0 or cells.max() >= 1 << depth:
            raise VoxelFileError(f"{path}: inside octants outside the grid of depth {depth}")
        if np.any(cells.astype(np.int64).max(axis=1) >= np.left_shift(1, levels.astype(np.int64))):
            raise VoxelFileError(f"{path}: inside octants outside the grid of depth {depth}")
    return inside.astype(np.int32, copy=False)


def _validated(path, coords, normals, depth, bounds):
    """(coords, normals, depth, bounds) checked to be what save_npz writes; VoxelFileError otherwise."""
    if depth.shape != () or depth.dtype.kind not in "iu" or not 1 <= int(depth) <= MAX_DEPTH:
        raise VoxelFileError(f"{path}: depth must be an integer from 1 to {MAX_DEPTH}, got {depth!r}")
    depth = int(depth)
    if bounds.shape != (3, 2) or bounds.dtype.kind != "f" or not usable_bounds(bounds.tolist(), MAX_DEPTH):
        raise VoxelFileError(f"{path}: bounds must be three finite (lo, hi) pairs with lo < hi and a finite, "
                             f"non-zero cell size, got {printable(np.array2string(bounds, threshold=12), 200)}")
    if coords.ndim != 2 or coords.shape[1:] != (3,) or coords.dtype.kind not in "iu":
        raise VoxelFileError(f"{path}: coords must be an (N, 3) integer array, got {coords.dtype} {coords.shape}")
    if normals.shape != coords.shape or normals.dtype.kind != "f":
        raise VoxelFileError(f"{path}: normals must be an (N, 3) float array like coords, got "
                             f"{normals.dtype} {normals.shape}")
    if len(coords) and (coords.min() < 0 or coords.max() >= 1 << depth):
        raise VoxelFileError(f"{path}: coordinates outside the {1 << depth}³ grid of depth {depth}")
    if not np.all(np.isfinite(normals)) or (len(normals) and np.abs(np.linalg.norm(normals, axis=1) - 1).max() > 1e-3):
        raise VoxelFileError(f"{path}: normals must be finite unit vectors")
    return (coords.astype(np.uint32, copy=False), normals.astype(np.float32, copy=False), depth,
            tuple(tuple(b) for b in bounds.tolist()))


def describe(path: str | os.PathLike[str]) -> list[str]:
    """Lines describing any voxel file implc writes (for ``implc info``)."""
    path = Path(path)
    fmt = _check_readable(path)
    size = f"{path} ({path.stat().st_size / 2**20:.1f} MiB)"
    if fmt == ".npz":
        voxels = load_npz(path)
        n = 1 << voxels.depth
        lo = voxels.coords.min(axis=0) if len(voxels) else [0, 0, 0]
        hi = voxels.coords.max(axis=0) if len(voxels) else [0, 0, 0]
        return [f"file     {size}, implc voxels",
                f"grid     {n}³ (depth {voxels.depth}) over {voxels.bounds}",
                f"voxels   {len(voxels)} ({len(voxels) / n**3:.4%} of the cells)",
                f"extent   cells {list(map(int, lo))} .. {list(map(int, hi))}",
                *_solid_lines(voxels)]
    if fmt == ".npy":
        try:
            grid = np.load(path, mmap_mode="r", allow_pickle=False)
        except Exception as exc:  # numpy's header parser raises several kinds (SyntaxError among them)
            raise VoxelFileError(f"cannot read {path}: damaged or truncated .npy "
                                 f"({type(exc).__name__}: {printable(str(exc), 120)})") from None
        if grid.ndim != 3 or grid.dtype != bool:
            raise VoxelFileError(f"{path}: not a dense occupancy grid (a 3-D bool array), got {grid.dtype} "
                                 f"{grid.shape}")
        return [f"file     {size}, dense occupancy grid", f"grid     {'x'.join(map(str, grid.shape))}",
                f"voxels   {int(np.count_nonzero(grid))}"]
    if fmt == ".vdb":
        try:
            return describe_vdb(path)
        except (ValueError, OSError) as exc:
            raise VoxelFileError(str(exc)) from None
    header, body = ply_header(path, VoxelFileError)
    count, row = _ply_vertices(path, header, body)
    comment = next((line[len("comment "):] for line in header if line.startswith("comment implc")), "")
    return [f"file     {size}, PLY point cloud", f"points   {count}",
            *([f"comment  {printable(comment)}"] if comment else [])]


def _ply_vertices(path, header: list[str], body: int) -> tuple[int, int]:
    """(vertices, bytes per vertex) of a binary PLY point cloud, checked against the file's length."""
    elements = ply_elements(path, header, body, VoxelFileError)
    if [name for name, _, _ in elements] != ["vertex"]:
        raise VoxelFileError(f"{path}: not a PLY point cloud (one 'element vertex COUNT' expected)")
    if not any(line.startswith("format binary") for line in header):
        raise VoxelFileError(f"{path}: an ASCII PLY; implc describes the binary point clouds it writes")
    _, count, row = elements[0]
    size = Path(path).stat().st_size
    if count * row != size - body:
        raise VoxelFileError(f"{path}: damaged PLY: {count} vertices of {row} bytes need {count * row} bytes "
                             f"after the header, the file has {size - body}")
    return count, row


def _solid_lines(voxels) -> list[str]:
    if voxels.inside is None:
        return []
    lo, hi = voxels.volume_bounds()
    return [f"inside   {len(voxels.inside)} octants ({voxels.inside_voxels()} voxels)",
            f"volume   [{lo!r}, {hi!r}] (contains the volume where F < 0 within the bounds)"]


def save_ply(voxels: Voxels, path: str | os.PathLike[str]) -> None:
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
    with replacing(path) as tmp, open(tmp, "wb") as f:
        f.write(header.encode("ascii"))
        f.write(vertex.tobytes())


def save_dense(voxels: Voxels, path: str | os.PathLike[str]) -> None:
    """Dense occupancy as a bool ``.npy`` indexed [i, j, k]."""
    with replacing(path) as tmp:
        np.save(tmp, voxels.to_dense())
