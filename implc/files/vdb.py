"""OpenVDB export: the voxels (and a solid's inside octants) as a ``.vdb`` file, written here in numpy.

The file holds two grids of the standard 5-4-3 tree (8³ leaves, 16³ and 32³ internal nodes, a root
table of 4096³ blocks), in file format 224 (OpenVDB 6 and later read it):

- ``occupancy`` (``Tree_float_5_4_3``, class fog volume, background 0): boundary voxels are active leaf
  voxels of value 0.5 (the surface may cross them); a solid's inside octants are active value 1.0 at the
  coarsest level that holds them whole: root tiles (4096³), tiles of the upper internal nodes (128³), of
  the lower internal nodes (8³), and active leaf voxels for octants smaller than a leaf.
- ``normals`` (``Tree_vec3s_5_4_3``, vector type covariant normalize): the unit normal of every
  boundary voxel.

Index (i, j, k) is cell (i, j, k) of the voxelization; the transform (a scale-and-translate map) puts
each voxel's centre where the cell's centre is. Values are stored with OpenVDB's active-mask compression
(only active values are written; no zlib or Blosc, so no codec library is needed to read them). The
layout follows OpenVDB's documented reader (``io/Archive``, ``tree/RootNode``, ``InternalNode``,
``LeafNode``, ``io/Compression``); the tests read every file they write back with the reference library
(Debian's ``python3-openvdb``) where the machine has it. The file is written under a temporary name and
renamed into place.
"""

from __future__ import annotations

import os
import struct
import uuid
from pathlib import Path

import numpy as np

from ..common.atomic_file import replacing
from ..common.untrusted import printable

FILE_VERSION = 224  # OPENVDB_FILE_VERSION_MULTIPASS_IO; format of OpenVDB 6-11
LIBRARY_VERSION = (10, 0)
MAGIC = 0x56444220  # "VDB "
COMPRESS_ACTIVE_MASK = 0x2
NO_MASK_OR_INACTIVE_VALS = 0  # every inactive value is the background: only active values follow

LEAF, LOWER, UPPER = 3, 7, 12  # log2 of the edge, in voxels, of a leaf, a lower and an upper internal node
BOUNDARY_VALUE, INSIDE_VALUE = 0.5, 1.0
LEAF_CHUNK = 1 << 12
"""Leaves assembled at a time: bounds the writer's temporary memory (a leaf's dense values take 6 KiB for
normals), and small enough to stay in the caches."""


class _Writer:
    """Little-endian binary writing in OpenVDB's conventions (strings with a uint32 length)."""

    def __init__(self, f):
        self.f = f

    def raw(self, data: bytes):
        self.f.write(data)

    def pack(self, fmt: str, *values):
        self.f.write(struct.pack("<" + fmt, *values))

    def string(self, text: str):
        data = text.encode()
        self.pack("I", len(data))
        self.f.write(data)

    def metadata(self, entries: list[tuple[str, str, bytes]]):
        self.pack("I", len(entries))
        for name, type_name, value in entries:
            self.string(name)
            self.string(type_name)
            self.pack("I", len(value))
            self.f.write(value)


def _string_meta(name, text):
    return name, "string", text.encode()


def _mask(offsets: np.ndarray, size: int) -> bytes:
    """A node mask of ``size`` bits with bits ``offsets`` set (OpenVDB's layout: little-endian 64-bit
    words, bit n in word n / 64)."""
    bits = np.zeros(size, dtype=bool)
    bits[offsets] = True
    return np.packbits(bits, bitorder="little").tobytes()


def _offset(coords: np.ndarray, child_log2: int, log2dim: int) -> np.ndarray:
    """A child's index in its parent node: x-major over the parent's (2^log2dim)³ children."""
    c = (coords.astype(np.int64) >> child_log2) & ((1 << log2dim) - 1)
    return (c[:, 0] << (2 * log2dim)) | (c[:, 1] << log2dim) | c[:, 2]


def _order_key(origins: np.ndarray) -> np.ndarray:
    """Sort key giving OpenVDB's order of nodes (root table by (x, y, z), then children by offset), for
    voxel-coordinate origins of non-negative cells below 2^21. Computed a block of rows at a time, axis by
    axis: temporaries of the whole array cost more than the arithmetic."""
    key = np.empty(len(origins), np.int64)
    step = LEAF_CHUNK * 64
    for a in range(0, len(origins), step):
        o = origins[a:a + step]
        k = np.zeros(len(o), np.int64)
        for axis in range(3):
            c = o[:, axis].astype(np.int64)
            shift = 2 - axis  # x the most significant of the three at each level
            k |= (c >> UPPER) << (27 + 9 * shift)
            k |= ((c >> LOWER) & ((1 << (UPPER - LOWER)) - 1)) << (12 + 5 * shift)
            k |= ((c >> LEAF) & ((1 << (LOWER - LEAF)) - 1)) << (4 * shift)
        key[a:a + step] = k
    return key


def _blocks(inside: np.ndarray, depth: int, lo_log2: int, hi_log2: int) -> np.ndarray:
    """The inside octants of edge 2^lo_log2 .. 2^(hi_log2 − 1) voxels, cut into blocks of 2^lo_log2:
    the blocks' first cells, (n, 3) int64."""
    size_log2 = depth - inside[:, 3].astype(np.int64)
    keep = (size_log2 >= lo_log2) & (size_log2 < hi_log2)
    rows, size_log2 = inside[keep], size_log2[keep]
    out = []
    for s in np.unique(size_log2):
        s = int(s)
        first = rows[size_log2 == s][:, :3].astype(np.int64) << s
        per = 1 << (s - lo_log2)
        steps = np.stack(np.meshgrid(*(np.arange(per, dtype=np.int64),) * 3, indexing="ij"), -1).reshape(-1, 3)
        out.append((first[:, None, :] + (steps << lo_log2)[None]).reshape(-1, 3))
    return np.concatenate(out) if out else np.empty((0, 3), dtype=np.int64)


def _cube_bits(size_log2: int) -> np.ndarray:
    """Leaf bit offsets of a cube of edge 2^size_log2 at the leaf's first cell."""
    e = np.arange(1 << size_log2)
    return ((e[:, None, None] << 6) | (e[None, :, None] << 3) | e[None, None, :]).ravel()


class _Runs:
    """Morton-ordered voxels by leaf, shared by the grids: each leaf's voxels are one run (a leaf is an
    aligned 8³ block); each voxel's bit in its leaf."""

    def __init__(self, coords: np.ndarray):
        cuts, self.bits = [], np.empty(len(coords), np.uint16)
        for a in range(0, len(coords), LEAF_CHUNK * 64):  # a block of rows at a time: small temporaries
            block = coords[a:a + LEAF_CHUNK * 64 + 1]
            leaf = block >> np.uint32(LEAF)
            cuts.append(np.flatnonzero(np.any(leaf[1:] != leaf[:-1], axis=1)) + a + 1)
            low = (block[:LEAF_CHUNK * 64] & np.uint32((1 << LEAF) - 1)).astype(np.uint16)
            self.bits[a:a + len(low)] = (low[:, 0] << (2 * LEAF)) | (low[:, 1] << LEAF) | low[:, 2]
        self.starts = np.concatenate([[0], *cuts, [len(coords)]]).astype(np.int64) if len(coords) else \
            np.zeros(1, np.int64)
        self.origins = (coords[self.starts[:-1]] >> np.uint32(LEAF)).astype(np.int64) << LEAF


class _Leaves:
    """A grid's leaves in OpenVDB's order, filled from Morton-ordered voxels with values (one value or
    one per voxel) and from octants smaller than a leaf with one value. Assembled a chunk of leaves at a
    time into dense (leaves, 512) arrays, so nothing per voxel is sorted or expanded whole."""

    def __init__(self, runs: _Runs, values, cubes: np.ndarray, cube_log2: np.ndarray, cube_value, dtype, width: int):
        self.bits, self.values, self.cube_value = runs.bits, values, cube_value
        self.dtype, self.width = dtype, width
        self.value_size = np.dtype(dtype).itemsize * width
        self.run_starts, run_origins = runs.starts, runs.origins
        run_keys = _order_key(run_origins)
        # the cubes grouped by leaf (one sort), each leaf's key computed once
        cube_keys = _order_key((cubes >> LEAF) << LEAF)
        order = np.argsort(cube_keys, kind="stable")
        self.cubes, self.cube_log2, cube_keys = cubes[order], cube_log2[order], cube_keys[order]
        heads = np.flatnonzero(np.r_[True, cube_keys[1:] != cube_keys[:-1]]) if len(cube_keys) else \
            np.empty(0, np.int64)
        keys = np.concatenate([run_keys, cube_keys[heads]])
        self.keys, first = np.unique(keys, return_index=True)
        self.origins = np.concatenate([run_origins, (self.cubes[heads] >> LEAF) << LEAF])[first]
        run_rank = np.searchsorted(self.keys, run_keys)
        self.run_order = np.argsort(run_rank, kind="stable")
        self.run_rank = run_rank[self.run_order]
        self.cube_rank = np.repeat(np.searchsorted(self.keys, cube_keys[heads]), np.diff(np.r_[heads, len(cube_keys)]))

    def __len__(self) -> int:
        return len(self.keys)

    def dense(self, first: int, last: int, with_values: bool = True) -> tuple[np.ndarray, np.ndarray | None]:
        """Leaves first..last − 1: their active masks (n, 512) bool and (``with_values``) their values
        (n, 512[, width])."""
        n = last - first
        active = np.zeros((n, 512), dtype=bool)
        shape = (n, 512) if self.width == 1 else (n, 512, self.width)
        values = np.zeros(shape, dtype=self.dtype) if with_values else None
        a, b = np.searchsorted(self.run_rank, [first, last])
        runs = self.run_order[a:b]
        lengths = self.run_starts[runs + 1] - self.run_starts[runs]
        index = np.repeat(self.run_starts[runs] - np.r_[0, np.cumsum(lengths)[:-1]], lengths) + np.arange(lengths.sum())
        rank = np.repeat(self.run_rank[a:b] - first, lengths)
        bit = self.bits[index]
        active[rank, bit] = True
        if values is not None:
            values[rank, bit] = self.values if np.ndim(self.values) == 0 else self.values[index]
        a, b = np.searchsorted(self.cube_rank, [first, last])
        for s in np.unique(self.cube_log2[a:b]):
            pick = np.flatnonzero(self.cube_log2[a:b] == s) + a
            rank = np.repeat(self.cube_rank[pick] - first, 1 << (3 * int(s)))
            bit = (_offset(self.cubes[pick], 0, LEAF)[:, None] + _cube_bits(int(s))[None]).ravel()
            active[rank, bit] = True
            if values is not None:
                values[rank, bit] = self.cube_value
        return active, values


class _Grid:
    """One grid's tree: leaves (:class:`_Leaves`) and active tiles of the internal nodes and the root."""

    def __init__(self, leaves: _Leaves, tiles: dict[int, np.ndarray], tile_value: bytes, background: bytes):
        self.leaves, self.tile_value, self.background = leaves, tile_value, background
        self.leaf_origins = leaves.origins
        empty = np.empty((0, 3), np.int64)
        lower_tiles, upper_tiles = tiles.get(LEAF, empty), tiles.get(LOWER, empty)
        self.lower_origins = _unique_in_order(np.concatenate([(self.leaf_origins >> LOWER) << LOWER,
                                                              (lower_tiles >> LOWER) << LOWER]))
        self.upper_origins = _unique_in_order(np.concatenate([(self.lower_origins >> UPPER) << UPPER,
                                                              (upper_tiles >> UPPER) << UPPER]))
        self.root_tiles = _unique_in_order(tiles.get(UPPER, empty))
        # the owner of each leaf, node and tile among its parents (all in order: the groups are contiguous)
        self.leaf_lower = _owner(self.leaf_origins, self.lower_origins, LOWER)
        self.lower_upper = _owner(self.lower_origins, self.upper_origins, UPPER)
        self.lower_tiles = lower_tiles[np.argsort(_order_key(lower_tiles), kind="stable")]
        self.lower_tile_owner = _owner(self.lower_tiles, self.lower_origins, LOWER)
        self.upper_tiles = upper_tiles[np.argsort(_order_key(upper_tiles), kind="stable")]
        self.upper_tile_owner = _owner(self.upper_tiles, self.upper_origins, UPPER)
        self.masks = np.empty((len(leaves), 64), dtype=np.uint8)
        for first in range(0, len(leaves), LEAF_CHUNK):
            last = min(first + LEAF_CHUNK, len(leaves))
            self.masks[first:last] = np.packbits(leaves.dense(first, last, False)[0], axis=1, bitorder="little")

    def _internal(self, w: _Writer, child_offsets, tile_offsets, log2dim: int):
        size = 1 << (3 * log2dim)
        w.raw(_mask(child_offsets, size))
        w.raw(_mask(tile_offsets, size))
        w.pack("b", NO_MASK_OR_INACTIVE_VALS)
        w.raw(self.tile_value * len(tile_offsets))

    def write_topology(self, w: _Writer):
        w.pack("i", 1)  # buffer count
        w.raw(self.background)
        w.pack("II", len(self.root_tiles), len(self.upper_origins))
        # the root table is ordered by key (x, y, z): tiles and children written in two passes
        for origin in self.root_tiles:
            w.pack("iii", *map(int, origin))
            w.raw(self.tile_value)
            w.pack("?", True)
        lower_bounds = _group_bounds(self.lower_upper, len(self.upper_origins))
        upper_tile_bounds = _group_bounds(self.upper_tile_owner, len(self.upper_origins))
        leaf_bounds = _group_bounds(self.leaf_lower, len(self.lower_origins))
        lower_tile_bounds = _group_bounds(self.lower_tile_owner, len(self.lower_origins))
        for u, origin in enumerate(self.upper_origins):
            w.pack("iii", *map(int, origin))
            lo, hi = lower_bounds[u], lower_bounds[u + 1]
            t0, t1 = upper_tile_bounds[u], upper_tile_bounds[u + 1]
            self._internal(w, _offset(self.lower_origins[lo:hi], LOWER, UPPER - LOWER),
                           _offset(self.upper_tiles[t0:t1], LOWER, UPPER - LOWER), UPPER - LOWER)
            for n in range(lo, hi):
                a, b = leaf_bounds[n], leaf_bounds[n + 1]
                t0, t1 = lower_tile_bounds[n], lower_tile_bounds[n + 1]
                self._internal(w, _offset(self.leaf_origins[a:b], LEAF, LOWER - LEAF),
                               _offset(self.lower_tiles[t0:t1], LEAF, LOWER - LEAF), LOWER - LEAF)
                w.raw(self.masks[a:b].tobytes())

    def write_buffers(self, w: _Writer):
        """Each leaf: its value mask, the compression metadata byte, its active values in mask order."""
        size = self.leaves.value_size
        for first in range(0, len(self.leaves), LEAF_CHUNK):
            last = min(first + LEAF_CHUNK, len(self.leaves))
            active, values = self.leaves.dense(first, last)
            assert values is not None
            counts = active.sum(axis=1)
            record = 64 + 1 + counts * size
            starts = np.r_[0, np.cumsum(record)[:-1]]
            out = np.zeros(int(record.sum()) + 64, dtype=np.uint8)  # 64: room for the strided views' last element
            _byte_view(out, 64)[starts] = self.masks[first:last].view("V64").ravel()
            before = np.r_[0, np.cumsum(counts)[:-1]]  # active values in earlier leaves of the chunk
            at = np.repeat(starts + 65 - before * size, counts) + np.arange(counts.sum()) * size
            _byte_view(out, size)[at] = np.ascontiguousarray(values[active]).view(f"V{size}").ravel()
            w.raw(out[:-64].tobytes())


def _byte_view(buffer: np.ndarray, size: int) -> np.ndarray:
    """Every ``size``-byte window of a byte array as one element (a view with a stride of one byte), to
    place records at any byte offset."""
    return np.ndarray((len(buffer) - size + 1,), dtype=f"V{size}", buffer=buffer, strides=(1,))


def _unique_in_order(origins: np.ndarray) -> np.ndarray:
    if not len(origins):
        return np.empty((0, 3), dtype=np.int64)
    key = _order_key(origins)
    _, first = np.unique(key, return_index=True)  # sorted by key: OpenVDB's order
    return origins[first]


def _owner(children: np.ndarray, parents: np.ndarray, parent_log2: int) -> np.ndarray:
    """Index into ``parents`` (origins in order) of each child's parent (children in order)."""
    if not len(children):
        return np.empty(0, dtype=np.int64)
    parent_keys = _order_key(parents)
    return np.searchsorted(parent_keys, _order_key((children >> parent_log2) << parent_log2))


def _group_bounds(owner: np.ndarray, groups: int) -> np.ndarray:
    return np.searchsorted(owner, np.arange(groups + 1))


def _transform(w: _Writer, bounds, depth: int):
    """Index (i, j, k) → the centre of cell (i, j, k): scale by the cell size, translate by half a cell
    past the lower bounds."""
    scale = np.array([(hi - lo) / (1 << depth) for lo, hi in bounds])
    translation = np.array([lo for lo, _ in bounds]) + scale / 2
    uniform = scale[0] == scale[1] == scale[2]
    w.string("UniformScaleTranslateMap" if uniform else "ScaleTranslateMap")
    for vec in (translation, scale, np.abs(scale), 1 / scale, 1 / scale**2, 0.5 / scale):
        w.pack("ddd", *map(float, vec))


def _extent(firsts: np.ndarray, edge_log2) -> tuple[np.ndarray, np.ndarray] | None:
    """The first and last cells of the cubes whose first cells are ``firsts`` (n, 3) and whose edges'
    log2 are ``edge_log2`` ((n,), or one for all), a block of rows at a time; None for no cube."""
    lows, highs = [], []
    for a in range(0, len(firsts), LEAF_CHUNK * 64):
        block = firsts[a:a + LEAF_CHUNK * 64].astype(np.int64)
        edge = np.left_shift(1, np.asarray(edge_log2 if np.ndim(edge_log2) == 0 else edge_log2[a:a + len(block)],
                                           np.int64))
        lows.append(block.min(axis=0))
        highs.append((block + (np.reshape(edge, (-1, 1)) - 1)).max(axis=0))
    return (np.min(lows, axis=0), np.max(highs, axis=0)) if lows else None


def _box(extents) -> tuple[np.ndarray, np.ndarray]:
    """The bounding box of the :func:`_extent` of each piece of a grid (zeros for an empty grid)."""
    found = [e for e in extents if e is not None]
    if not found:
        return np.zeros(3, np.int64), np.zeros(3, np.int64)
    return np.min([lo for lo, _ in found], axis=0), np.max([hi for _, hi in found], axis=0)


def _grid_metadata(name, grid_class, value_type, box, extra=()):
    """A grid's metadata, its bounding box ``box`` (:func:`_box`)."""
    lo, hi = box
    return [_string_meta("class", grid_class), _string_meta("creator", "implc"),
            ("file_bbox_max", "vec3i", struct.pack("<iii", *map(int, hi))),
            ("file_bbox_min", "vec3i", struct.pack("<iii", *map(int, lo))),
            ("is_saved_as_half_float", "bool", b"\x00"), _string_meta("name", name),
            _string_meta("value_type", value_type), *extra]


def save_vdb(voxels, path) -> Path:
    """Write ``voxels`` (a shell or a solid) as an OpenVDB file with the grids ``occupancy`` and
    ``normals`` (see the module's docstring)."""
    path = Path(path)
    depth = voxels.depth
    coords = np.ascontiguousarray(voxels.coords, dtype=np.uint32)
    inside = voxels.inside if voxels.inside is not None else np.empty((0, 4), dtype=np.int32)
    size_log2 = depth - inside[:, 3].astype(np.int64)
    small = size_log2 < LEAF
    cubes = np.left_shift(inside[small, :3].astype(np.uint32), size_log2[small, None].astype(np.uint32))
    tiles = {LEAF: _blocks(inside, depth, LEAF, LOWER), LOWER: _blocks(inside, depth, LOWER, UPPER),
             UPPER: _blocks(inside, depth, UPPER, 64)}
    runs = _Runs(coords)
    occupancy = _Grid(_Leaves(runs, np.float32(BOUNDARY_VALUE), cubes, size_log2[small], INSIDE_VALUE,
                              np.float32, 1), tiles, struct.pack("<f", INSIDE_VALUE), struct.pack("<f", 0.0))
    normals = _Grid(_Leaves(runs, np.asarray(voxels.normals, dtype=np.float32), np.empty((0, 3), np.int64),
                            np.empty(0, np.int64), 0.0, np.float32, 3), {}, b"", struct.pack("<fff", 0.0, 0.0, 0.0))
    voxels_extent = _extent(coords, 0)  # both grids' boxes hold it: one pass over the voxels
    grids = [("occupancy", "Tree_float_5_4_3", occupancy,
              _grid_metadata("occupancy", "fog volume", "float",
                             _box([voxels_extent, _extent(cubes, size_log2[small])]
                                  + [_extent(t, s) for s, t in tiles.items()]))),
             ("normals", "Tree_vec3s_5_4_3", normals,
              _grid_metadata("normals", "unknown", "vec3s", _box([voxels_extent]),
                             [_string_meta("vector_type", "covariant normalize")]))]
    with replacing(path) as tmp, open(tmp, "wb") as f:
        w = _Writer(f)
        w.pack("q", MAGIC)
        w.pack("III", FILE_VERSION, *LIBRARY_VERSION)
        w.pack("?", True)  # the grid descriptors carry stream offsets
        w.raw(str(uuid.uuid4()).encode())
        w.metadata([_string_meta("creator", "implc")])
        w.pack("i", len(grids))
        for name, grid_type, grid, meta in grids:
            w.string(name)
            w.string(grid_type)
            w.string("")  # no instance parent
            offsets_at = f.tell()
            w.pack("qqq", 0, 0, 0)
            grid_pos = f.tell()
            w.pack("I", COMPRESS_ACTIVE_MASK)
            w.metadata(meta)
            _transform(w, voxels.bounds, depth)
            grid.write_topology(w)
            block_pos = f.tell()
            grid.write_buffers(w)
            end_pos = f.tell()
            f.seek(offsets_at)
            w.pack("qqq", grid_pos, block_pos, end_pos)
            f.seek(end_pos)
    return path


class _Reader:
    """Reads an OpenVDB file it does not trust: every count and length is checked against the bytes left
    before anything is read or allocated by it."""

    _FIXED = {"vec3i": "<iii", "vec3s": "<fff", "vec3d": "<ddd", "bool": "<?", "int64": "<q", "int32": "<i",
              "float": "<f", "double": "<d"}

    def __init__(self, f, path):
        self.f, self.path = f, path
        self.size = os.fstat(f.fileno()).st_size

    def damaged(self, what: str) -> ValueError:
        return ValueError(f"{self.path}: damaged OpenVDB file ({what})")

    def left(self) -> int:
        return self.size - self.f.tell()

    def unpack(self, fmt: str):
        size = struct.calcsize("<" + fmt)
        data = self.f.read(size)
        if len(data) != size:
            raise ValueError(f"{self.path}: truncated OpenVDB file")
        return struct.unpack("<" + fmt, data)

    def bytes(self, n: int, what: str) -> bytes:
        if n > self.left():
            raise self.damaged(f"{what} of {n} bytes, {self.left()} left in the file")
        return self.f.read(n)

    def string(self) -> str:
        (n,) = self.unpack("I")
        return self.bytes(n, "a string").decode(errors="replace")

    def metadata(self) -> dict:
        (count,) = self.unpack("I")
        if count * 12 > self.left():  # each entry takes at least three 4-byte lengths
            raise self.damaged(f"{count} metadata entries")
        out = {}
        for _ in range(count):
            name, type_name = self.string(), self.string()
            (n,) = self.unpack("I")
            data = self.bytes(n, f"metadata {printable(name, 40)}")
            fmt = self._FIXED.get(type_name)
            if fmt is not None:
                if n != struct.calcsize(fmt):
                    raise self.damaged(f"metadata {printable(name, 40)} of type {printable(type_name, 20)} has "
                                       f"{n} bytes, not {struct.calcsize(fmt)}")
                values = struct.unpack(fmt, data)
                out[name] = values[0] if len(values) == 1 else values
            elif type_name == "string":
                out[name] = printable(data.decode(errors="replace"))
            else:
                out[name] = f"({printable(type_name, 40)}, {n} bytes)"
        return out


def describe_vdb(path) -> list[str]:
    """Lines describing an OpenVDB file (its header, grids, their metadata and transforms) for
    ``implc info``; ValueError if it is not one this can read (format 222 or later). Text from the file
    is printed escaped (:func:`implc.common.untrusted.printable`)."""
    path = Path(path)
    with open(path, "rb") as f:
        r = _Reader(f, path)
        (magic,) = r.unpack("q")
        if magic != MAGIC:
            raise ValueError(f"{path} is not an OpenVDB file")
        version, major, minor = r.unpack("III")
        (offsets,) = r.unpack("?")
        if version < 222 or not offsets:
            raise ValueError(f"{path}: OpenVDB format {version}{'' if offsets else ' without grid offsets'}; "
                             "implc describes format 222 and later")
        r.bytes(36, "the file's UUID")
        meta = r.metadata()
        (count,) = r.unpack("i")
        if not 0 <= count <= r.left() // 36:  # a grid's descriptor takes 36 bytes at least
            raise r.damaged(f"a grid count of {count}")
        creator = f", by {printable(str(meta['creator']), 80)}" if "creator" in meta else ""
        lines = [f"file     {path} ({r.size / 2**20:.1f} MiB), OpenVDB format {version} "
                 f"(library {major}.{minor}){creator}"]
        for _ in range(count):
            name, grid_type, _parent = r.string(), r.string(), r.string()
            grid_pos, _block_pos, end_pos = r.unpack("qqq")
            here = f.tell()
            if not here <= grid_pos < end_pos <= r.size:  # offsets only move forward: the walk ends
                raise r.damaged(f"grid {printable(name, 40)} at offsets {grid_pos}..{end_pos}")
            f.seek(grid_pos)
            r.unpack("I")  # compression flags
            grid_meta = r.metadata()
            map_type = r.string()
            translation, scale = r.unpack("ddd"), r.unpack("ddd")
            box = (grid_meta.get("file_bbox_min"), grid_meta.get("file_bbox_max"))
            lines.append(f"grid     {printable(name, 80)}: {printable(grid_type, 80)}, class "
                         f"{printable(str(grid_meta.get('class', '?')), 40)}, index box {box[0]} .. {box[1]}")
            lines.append(f"         {printable(map_type, 80)}: voxel size {tuple(scale)}, "
                         f"voxel (0, 0, 0) centred at {tuple(translation)}")
            f.seek(end_pos)
    return lines
