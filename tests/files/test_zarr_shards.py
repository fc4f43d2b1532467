"""The shards implc encodes in its tasks' threads (implc.files.zarr_shards) are, byte for byte, the objects
zarr itself writes for the same blocks: a store's occupancy (bool, 3-D, with empty and full chunks), its
row arrays (uint32 and float32, a last shard cut short by the array's end, a chunk of zeros), and a
shard of nothing but the fill value is no object at all."""

import numpy as np
import pytest
import zarr

from implc.files import zarr_store
from implc.files.zarr_shards import ShardEncoder


def _array(folder, shape, chunks, shards, dtype):
    return zarr.create_array(store=str(folder), shape=shape, chunks=chunks, shards=shards, dtype=dtype, fill_value=0,
                             compressors=zarr_store.compressors(), zarr_format=3)


def test_occupancy_shards_are_zarrs_own(tmp_path):
    rng = np.random.default_rng(3)
    array = _array(tmp_path / "occ", (32, 32, 32), (8, 8, 8), (16, 16, 16), "bool")
    encoder = ShardEncoder(array)
    for shard in [(0, 0, 0), (1, 0, 1), (1, 1, 1)]:
        block = rng.random((16, 16, 16)) < 0.2
        block[:8, :8, :8] = False  # an empty chunk: not stored
        block[8:, :8, :8] = True  # a full one
        lo = [16 * s for s in shard]
        array[lo[0]:lo[0] + 16, lo[1]:lo[1] + 16, lo[2]:lo[2] + 16] = block
        assert encoder.encode(block) == (tmp_path / "occ" / encoder.key(shard)).read_bytes()
    assert encoder.full() == ShardEncoder(array).encode(np.ones((16, 16, 16), bool))
    assert encoder.encode(np.zeros((16, 16, 16), bool)) is None


@pytest.mark.parametrize("dtype", ["uint32", "float32"])
def test_row_shards_are_zarrs_own(tmp_path, dtype):
    rng = np.random.default_rng(4)
    rows = (rng.normal(size=(1000, 3)) * 1000).astype(dtype)
    rows[128:192] = 0  # a chunk of the fill value
    array = _array(tmp_path / "rows", (1000, 3), (64, 3), (256, 3), dtype)
    array[...] = rows
    encoder = ShardEncoder(array)
    for shard in range(4):  # the last holds 232 rows of 256
        data = encoder.encode(rows[shard * 256:(shard + 1) * 256])
        assert data == (tmp_path / "rows" / encoder.key((shard, 0))).read_bytes()
    read = zarr.open_array(str(tmp_path / "rows"), mode="r")[...]
    np.testing.assert_array_equal(read, rows)
