"""Zarr stores compared object by object, in a folder or at an fsspec URL (an object store)."""

from pathlib import Path

import numpy as np
import zarr


def store_objects(target) -> dict[str, bytes]:
    """Every object of the store at ``target`` (a folder, or a URL) by its name relative to the root."""
    text = str(target)
    if "://" in text and not text.startswith("file://"):
        import fsspec
        fs, root = fsspec.core.url_to_fs(text)
        fs.invalidate_cache()
        root = root.rstrip("/")
        return {name[len(root) + 1:]: fs.cat_file(name) for name in fs.find(root)}
    folder = Path(target)
    return {p.relative_to(folder).as_posix(): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def arrays(target) -> dict:
    group = zarr.open_group(str(target), mode="r")
    return {name: a for name, a in group.members(max_depth=None) if isinstance(a, zarr.Array)}


def assert_same_store(a, b):
    """Every array equal: the same arrays, and each array's metadata and encoded chunk and shard objects
    byte for byte (the encoding is deterministic; reading a 2048³ occupancy as values is 8 GiB)."""
    assert arrays(a).keys() == arrays(b).keys()
    objects_a, objects_b = store_objects(a), store_objects(b)
    assert objects_a.keys() == objects_b.keys()
    for name, data in objects_a.items():
        if name != "zarr.json":  # the group's attributes: compared below, key by key
            assert data == objects_b[name], name
    about_a = zarr.open_group(str(a), mode="r").attrs["implc"]
    about_b = zarr.open_group(str(b), mode="r").attrs["implc"]
    for key in ("depth", "bounds", "solid", "layout"):
        assert about_a[key] == about_b[key]
    for key in ("voxels", "inside_octants", "inside_voxels", "bricks", "shards", "tasks"):
        assert about_a["manifest"][key] == about_b["manifest"][key], key


def assert_same_reads(a, b, region):
    """The voxels, normals and inside octants read from the stores ``a`` and ``b`` (a folder, a URL) equal,
    whole and in ``region``."""
    from implc.files import voxel_files
    for read in (None, region):
        here, there = voxel_files.load(a, read), voxel_files.load(b, read)
        np.testing.assert_array_equal(there.coords, here.coords)
        np.testing.assert_array_equal(there.normals, here.normals)
        np.testing.assert_array_equal(there.inside, here.inside)
