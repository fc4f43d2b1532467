"""Stores at an fsspec URL (implc.files.store_place), through fsspec's in-memory filesystem: the same objects
as the store written to a folder; a run that stops leaves a store without its manifest, which readers
refuse and ``resume`` finishes from the parts whose checksums hold; nothing is ever replaced in place; a
URL with credentials, an unknown protocol and other formats are refused in one line. (The same against a
real S3 API, with a cluster: tests/cluster/test_object_store_cluster.py.)"""

import io
import uuid

import numpy as np
import pytest
from sympy import Max, Rational, sqrt

import implc
from implc import shapes
from implc.cli.commands import main
from implc.compiler.symbols import x, y, z
from implc.errors import StoreError
from implc.files import voxel_files, zarr_store, zarr_writer

from ..support.stores import arrays, assert_same_reads, assert_same_store, store_objects

HOLLOW = Max(shapes.box((0.7, 0.7, 0.7)), -(sqrt(x**2 + y**2 + z**2) - Rational(3, 10)))


@pytest.fixture
def memory():
    """A fresh root in fsspec's in-memory filesystem (this process's), removed afterwards."""
    import fsspec
    fs = fsspec.filesystem("memory")
    root = f"/implc-{uuid.uuid4().hex[:12]}"
    yield f"memory://{root}"
    if fs.exists(root):
        fs.rm(root, recursive=True)


@pytest.fixture
def small_bricks():
    with zarr_store.sizes(zarr_store.Sizes(shard=8, chunk=4, row_chunk=1024, row_shard=4096, client_levels=1)):
        yield


def test_a_store_at_a_url_is_the_folders_store(tmp_path, memory, small_bricks):
    """write_zarr to a URL writes the objects the folder's store holds, byte for byte; readers take either,
    whole or by region; save_zarr, info and render take the URL too."""
    surface = implc.compile(HOLLOW)
    folder, url = tmp_path / "h.zarr", f"{memory}/h.zarr"
    zarr_writer.write_zarr(surface, 6, folder, solid=True, workers=2)
    written = zarr_writer.write_zarr(surface, 6, url, solid=True, workers=2)
    assert written.path == url and written.tasks > 8
    assert_same_store(folder, url)
    assert not any(name.startswith("_parts") for name in store_objects(url)), "the parts were left"
    assert_same_reads(folder, url, ((5, 35), (0, 23), (17, 64)))
    voxels = zarr_store.load_zarr(folder)
    voxel_files.save(voxels, f"{memory}/saved.zarr")
    zarr_writer.save_zarr(voxels, tmp_path / "saved.zarr")
    assert_same_store(tmp_path / "saved.zarr", f"{memory}/saved.zarr")
    assert main(["info", url]) == 0
    assert main(["render", url, "-o", str(tmp_path / "h.png"), "--size", "64", "--quiet"]) == 0
    assert (tmp_path / "h.png").stat().st_size > 0


def test_a_stopped_run_at_a_url_is_incomplete_and_resume_finishes_it(tmp_path, memory, small_bricks, monkeypatch,
                                                                       capsys):
    """No rename: a stopped run leaves its store under the URL without the manifest (readers refuse it),
    its finished parts with their checksums; a new run is refused, as is a resume with other options; a
    part whose checksum does not hold runs again; the resumed store is the clean run's."""
    surface = implc.compile(HOLLOW)
    zarr_writer.write_zarr(surface, 6, tmp_path / "ref.zarr", solid=True, workers=1)
    real, calls = zarr_writer.task_voxels, []

    def stopping(*args, **kwargs):
        calls.append(1)
        if len(calls) == 6:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    url = f"{memory}/h.zarr"
    monkeypatch.setattr(zarr_writer, "task_voxels", stopping)
    with pytest.raises(KeyboardInterrupt):
        zarr_writer.write_zarr(surface, 6, url, solid=True, workers=1)
    monkeypatch.setattr(zarr_writer, "task_voxels", real)
    objects = store_objects(url)
    parts = sorted(name for name in objects if name.startswith("_parts/") and name.endswith(".npz"))
    assert len(parts) >= 5 and all(name[:-4] + ".sha256" in objects for name in parts)
    with pytest.raises(StoreError, match="incomplete"):
        zarr_store.load_zarr(url)
    assert main(["info", url]) == 2 and "incomplete" in capsys.readouterr().err
    with pytest.raises(ValueError, match="unfinished run"):
        zarr_writer.write_zarr(surface, 6, url, solid=True)
    with pytest.raises(ValueError, match="another run"):
        zarr_writer.write_zarr(surface, 6, url, solid=False, resume=True)
    import fsspec
    fs, root = fsspec.core.url_to_fs(url)
    victim = next(name for name in parts if len(np.load(io.BytesIO(objects[name]))["coords"]))
    fs.pipe_file(f"{root}/{victim}", objects[victim][: len(objects[victim]) // 2])  # truncated: not trusted
    resumed = zarr_writer.write_zarr(surface, 6, url, solid=True, workers=1, resume=True)
    assert resumed.resumed == len(parts) - 1
    a, b = arrays(tmp_path / "ref.zarr"), arrays(url)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name][...], b[name][...], err_msg=name)
    with pytest.raises(ValueError, match="complete store: nothing to resume"):
        zarr_writer.write_zarr(surface, 6, url, solid=True, resume=True)


def test_nothing_is_replaced_at_a_url(memory, small_bricks, monkeypatch):
    """An object store has no rename: a complete store, and objects that are not a store, are refused and
    left as they are; a run that fails before finishing a task leaves nothing; resume needs a run."""
    import fsspec
    surface = implc.compile(shapes.torus(0.5, 0.2))
    url = f"{memory}/t.zarr"
    with pytest.raises(ValueError, match="nothing to resume"):
        zarr_writer.write_zarr(surface, 5, url, resume=True)
    zarr_writer.write_zarr(surface, 5, url)
    before = store_objects(url)
    with pytest.raises(ValueError, match="complete store"):
        zarr_writer.write_zarr(surface, 5, url)
    with pytest.raises(ValueError, match="complete store"):
        voxel_files.save(zarr_store.load_zarr(url), url)
    assert store_objects(url) == before
    fs, root = fsspec.core.url_to_fs(memory)
    fs.pipe_file(f"{root}/notes/readme.txt", b"mine")
    with pytest.raises(ValueError, match="not an implc store"):
        zarr_writer.write_zarr(surface, 5, f"{memory}/notes")
    assert fs.cat_file(f"{root}/notes/readme.txt") == b"mine"

    def failing(*args, **kwargs):
        raise KeyboardInterrupt

    monkeypatch.setattr(zarr_writer, "task_voxels", failing)
    with pytest.raises(KeyboardInterrupt):
        zarr_writer.write_zarr(surface, 5, f"{memory}/failed.zarr")
    assert not fs.exists(f"{root}/failed.zarr")


def test_a_file_url_is_a_folder(tmp_path, small_bricks):
    """file:// URLs are local folders, written through a .partial folder and renamed as plain paths are."""
    surface = implc.compile(shapes.torus(0.5, 0.2))
    written = zarr_writer.write_zarr(surface, 5, f"file://{tmp_path}/t.zarr")
    assert written.path == tmp_path / "t.zarr" and (tmp_path / "t.zarr" / "zarr.json").is_file()
    zarr_writer.write_zarr(surface, 5, tmp_path / "p.zarr")
    assert_same_store(tmp_path / "p.zarr", tmp_path / "t.zarr")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["p.zarr", "t.zarr"]
    np.testing.assert_array_equal(voxel_files.load(f"file://{tmp_path}/t.zarr").coords,
                                  zarr_store.load_zarr(tmp_path / "p.zarr").coords)


@pytest.mark.parametrize("target,words", [
    ("s3://key:secret@bucket/run.zarr", "carry no credentials"),
    ("nosuchprotocol://bucket/run.zarr", "cannot reach"),
    ("memory://bucket/run.npz", "takes a .zarr store"),
])
def test_bad_urls_are_one_line(target, words, capsys):
    code = main(["voxelize", "--expr", "x - 0.1", "--depth", "4", "-o", target, "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and words in err, err
    assert "secret" not in err
