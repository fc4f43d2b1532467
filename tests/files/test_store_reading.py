"""Stores from outside: the reader reads only regular files (a FIFO or a link among a store's files is
refused before zarr opens anything), checks every count and place it is told against the grid before
spending memory on it, and refuses in one line what a store of implc's never holds."""

import json
import os
import time

import pytest
import zarr

import implc
from implc import shapes
from implc.cli.commands import main
from implc.errors import StoreError
from implc.files import zarr_store, zarr_writer


@pytest.fixture
def store(tmp_path):
    """A solid torus at 32³ in small bricks (many bricks, inside octants of several levels)."""
    with zarr_store.sizes(zarr_store.Sizes(shard=8, chunk=4, row_chunk=256, row_shard=1024, client_levels=1)):
        zarr_writer.write_zarr(implc.compile(shapes.torus(0.5, 0.25)), 5, tmp_path / "s.zarr", solid=True, workers=1)
    return tmp_path / "s.zarr"


def refused(capsys, path, words, info: bool = True) -> None:
    """load_zarr refuses ``path`` (and, where ``info``, so does ``implc info``, in one line), quickly."""
    t0 = time.monotonic()
    with pytest.raises((StoreError, ValueError, MemoryError), match=words):
        zarr_store.load_zarr(path)
    if info:
        assert main(["info", str(path)]) == 2
        err = capsys.readouterr().err
        assert "Traceback" not in err and err.count("\n") == 1 and words.split()[0] in err
    assert time.monotonic() - t0 < 10


def a_chunk(store):
    return next(p for p in sorted((store / "voxels" / "coords").rglob("*")) if p.is_file() and p.name != "zarr.json")


def test_the_store_reads(store):
    assert len(zarr_store.load_zarr(store)) > 0


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
@pytest.mark.parametrize("which", ["zarr.json", "a chunk"])
def test_a_fifo_in_a_store_is_refused_without_blocking(store, capsys, which):
    victim = store / "zarr.json" if which == "zarr.json" else a_chunk(store)
    victim.unlink()
    os.mkfifo(victim)
    refused(capsys, store, "FIFO")


def test_a_link_to_dev_zero_in_a_store_is_refused(store, capsys):
    victim = a_chunk(store)
    victim.unlink()
    victim.symlink_to("/dev/zero")
    refused(capsys, store, "a link")


def _attrs(store) -> dict:
    return json.loads((store / "zarr.json").read_text())


def _set_attrs(store, about) -> None:
    meta = _attrs(store)
    meta["attributes"]["implc"] = about
    (store / "zarr.json").write_text(json.dumps(meta))


@pytest.mark.parametrize("forgery", ["bounds as huge integers", "inside voxels 10^18", "voxel count 10^12"])
def test_forged_metadata_is_refused(store, capsys, forgery):
    about = _attrs(store)["attributes"]["implc"]
    if forgery.startswith("bounds"):
        about["bounds"] = [[-10**400, 10**400]] * 3
        words = "bounds"
    elif forgery.startswith("inside"):
        about["manifest"]["inside_voxels"] = 10**18
        words = "manifest"
    else:
        about["manifest"]["voxels"] = 10**12  # and the arrays' shapes say so too: a forged store of zeros
        for name in ("voxels/coords", "voxels/normals"):
            meta = json.loads((store / name / "zarr.json").read_text())
            meta["shape"][0] = 10**12
            (store / name / "zarr.json").write_text(json.dumps(meta))
        words = "manifest"
    _set_attrs(store, about)
    refused(capsys, store, words)


def test_a_store_larger_than_the_memory_is_refused_before_reading(store, monkeypatch):
    """The whole store's rows are weighed against the free memory first (here a machine with 1 KiB free):
    refused with a word on reading a region instead, which still works."""
    monkeypatch.setattr(zarr_store, "_available_memory", lambda: 1024)
    with pytest.raises(MemoryError, match="need about .* read a region"):
        zarr_store.load_zarr(store)
    assert len(zarr_store.load_zarr(store, ((0, 8), (0, 32), (0, 32)))) >= 0


@pytest.mark.parametrize("forgery", ["rows", "brick outside", "octant level",
                                     *[pytest.param(f, marks=pytest.mark.slow)  # the same checks, other forgeries
                                       for f in ("brick twice", "octant outside", "octant twice")]])
def test_forged_arrays_are_refused(store, capsys, forgery):
    group = zarr.open_group(str(store), mode="r+")
    if forgery == "rows":
        rows = group["voxels/rows"][...]
        rows[1] = rows[-1] + 5  # a brick's rows said to run past the end
        group["voxels/rows"][...] = rows
        words = "row index"
    elif forgery.startswith("brick"):
        bricks = group["bricks"][...]
        bricks[0] = [99, 0, 0] if forgery == "brick outside" else bricks[1]
        group["bricks"][...] = bricks
        words = "bricks outside the grid"
    else:
        name = "inside/coarse" if group["inside/coarse"].shape[0] > 1 else "inside/octants"
        octants = group[name][...]
        if forgery == "octant level":
            octants[0, 3] = 9
        elif forgery == "octant outside":
            octants[0, 0] = 1 << int(octants[0, 3])
        else:
            octants[1] = octants[0]
        group[name][...] = octants
        words = "inside octant"
    refused(capsys, store, words, info=False)  # info reads the metadata, not the rows
