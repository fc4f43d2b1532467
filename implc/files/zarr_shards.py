"""A whole shard of a store's array encoded in the calling thread, as zarr would write it.

zarr's own ``array[...] = block`` runs every encode on its single event-loop thread, so the tasks' threads
of one process wrote their shards one at a time, however many cores they had. Here a task encodes its
shard itself — each inner chunk through the array's own compressor (numcodecs, which releases the GIL),
the chunks in zarr's order, the index of (offset, length) pairs after them with its CRC32C, the layout
of the Zarr v3 ``sharding_indexed`` codec — and writes the bytes as one object
(:meth:`implc.files.store_place.StorePlace.write`). The tests check the bytes against zarr's own writes
of the same blocks. Only the stores' own codec chain is handled: bytes (little-endian), then one
compressor, an index of little-endian uint64 with CRC32C at the shard's end.
"""

from __future__ import annotations

from typing import Any

import numpy as np

EMPTY = np.uint64(2**64 - 1)
"""An index entry of a chunk not written (it reads as the fill value)."""


def _chunk_order(per_shard: tuple[int, ...]) -> np.ndarray:
    """The chunks' coordinates in a shard in zarr's order: Morton order, the first axis the fastest."""
    grid = np.indices(per_shard).reshape(len(per_shard), -1).T.astype(np.uint64)
    keys = np.zeros(len(grid), np.uint64)
    bits = max(1, int(max(per_shard) - 1).bit_length())
    for bit in range(bits):
        for axis in range(len(per_shard)):
            keys |= ((grid[:, axis] >> np.uint64(bit)) & np.uint64(1)) << np.uint64(bit * len(per_shard) + axis)
    return grid[np.argsort(keys, kind="stable")].astype(np.int64)


class ShardEncoder:
    """Encodes whole shards of one array (``array``: a sharded ``zarr.Array`` of a store, its metadata
    read once)."""

    def __init__(self, array: Any):
        import numcodecs

        meta = array.metadata
        sharding = meta.codecs[0]
        inner = sharding.codecs
        if len(inner) != 2 or type(inner[0]).__name__ != "BytesCodec" or sharding.index_location.value != "end":
            raise ValueError(f"{array.path}: a codec chain this encoder does not write ({meta.codecs!r})")
        config = inner[1].to_dict()
        self.compressor = numcodecs.get_codec({"id": config["name"], **config.get("configuration", {})})
        self.shard = tuple(array.shards)
        self.chunk = tuple(sharding.chunk_shape)
        self.dtype = np.dtype(array.dtype).newbyteorder("<")
        self.fill = np.asarray(array.fill_value, self.dtype)
        self.per_shard = tuple(s // c for s, c in zip(self.shard, self.chunk))
        self.order = _chunk_order(self.per_shard)
        self.path = array.path
        self._full: bytes | None = None

    def key(self, shard: Any) -> str:
        """The object name of shard ``shard`` (its index in the shard grid) relative to the store's root."""
        key = "c/" + "/".join(str(int(i)) for i in shard)
        return f"{self.path}/{key}" if self.path else key

    def full(self) -> bytes:
        """The bytes of a shard all True (a bool array's): the same for every full shard, encoded once
        (every shard of a solid's inside is this one)."""
        if self._full is None:
            self._full = self.encode(np.ones(self.shard, bool))
        assert self._full is not None
        return self._full

    def encode(self, block: np.ndarray) -> bytes | None:
        """The shard's bytes for ``block`` (the shard's shape, or less at the array's end: the rest is the
        fill value), or None where every chunk is the fill value (zarr writes no object then)."""
        import google_crc32c

        if block.shape != self.shard:
            padded = np.full(self.shard, self.fill, self.dtype)
            padded[tuple(slice(0, n) for n in block.shape)] = block
            block = padded
        index = np.full(self.per_shard + (2,), EMPTY, np.dtype("<u8"))
        pieces, offset = [], 0
        for coords in self.order:
            where = tuple(slice(c * n, (c + 1) * n) for c, n in zip(coords, self.chunk))
            chunk = np.ascontiguousarray(block[where], self.dtype)
            if not chunk.any() if self.fill == 0 else np.array_equal(chunk, np.broadcast_to(self.fill, chunk.shape)):
                continue  # all the fill value (for 0: any() is the same test, and faster)
            data = bytes(self.compressor.encode(chunk))
            index[tuple(coords)] = (offset, len(data))
            pieces.append(data)
            offset += len(data)
        if not pieces:
            return None
        raw = index.tobytes()
        pieces += [raw, np.uint32(google_crc32c.value(raw)).astype("<u4").tobytes()]
        return b"".join(pieces)
