"""The Zarr store (implc.files.zarr_store) against the in-memory voxelization and numpy: its occupancy is the
dense solid, each level of detail that occupancy pooled by numpy, its rows the voxels with their normals
in Morton order; a region reads back what the voxels hold there; every shard has one writer; a stopped
run leaves an incomplete store that readers refuse and that resume finishes without redoing its
finished tasks. The store is the same written from voxels in memory and while voxelizing."""

import json
import os

import numpy as np
import pytest
import zarr
from sympy import Max, Rational, sqrt

import implc
from implc import shapes
from implc.cli.commands import main
from implc.compiler.symbols import x, y, z
from implc.files import voxel_files, zarr_store, zarr_writer

HOLLOW = Max(shapes.box((0.7, 0.7, 0.7)), -(sqrt(x**2 + y**2 + z**2) - Rational(3, 10)))
TORUS = shapes.torus(Rational(3, 5), Rational(1, 4))


def arrays(path) -> dict:
    group = zarr.open_group(str(path), mode="r")
    return {name: a[...] for name, a in group.members(max_depth=None) if isinstance(a, zarr.Array)}


def pooled(dense: np.ndarray, level: int) -> np.ndarray:
    """The occupancy of the 2^level grid from the dense one, by numpy alone."""
    n, m = dense.shape[0], 1 << level
    e = n // m
    return dense.reshape(m, e, m, e, m, e).any(axis=(1, 3, 5))


@pytest.fixture
def small_bricks():
    """Bricks of 8³ (chunks 4³), row shards of 4096 rows, the caller writing only the levels of detail
    up to one below the tasks': a 64³ grid has many bricks, tasks holding several, row shards spanning
    several tasks, and levels of detail written by the tasks."""
    with zarr_store.sizes(zarr_store.Sizes(shard=8, chunk=4, row_chunk=1024, row_shard=4096, client_levels=1)):
        yield


@pytest.mark.parametrize("solid", [True, pytest.param(False, marks=pytest.mark.slow)], ids=["solid", "shell"])
def test_the_store_is_the_voxelization(tmp_path, small_bricks, solid):
    surface = implc.compile(HOLLOW)
    depth = 6
    v = implc.voxelize(surface, depth, solid=solid)
    dense = v.to_dense(solid=solid)
    written = zarr_writer.write_zarr(surface, depth, tmp_path / "w.zarr", solid=solid, workers=2)
    assert written.tasks > 8 and written.voxels == len(v)
    stored = arrays(tmp_path / "w.zarr")
    np.testing.assert_array_equal(stored["occupancy"], dense)
    for level in range(1, depth):
        np.testing.assert_array_equal(stored[f"lod/{level}"], pooled(dense, level), err_msg=f"level {level}")
    np.testing.assert_array_equal(stored["voxels/coords"], v.coords)
    np.testing.assert_array_equal(stored["voxels/normals"], v.normals)
    bricks = stored["bricks"].astype(np.int64)
    starts = stored["voxels/rows"]
    assert starts[0] == 0 and starts[-1] == len(v) and np.all(np.diff(starts) >= 0)
    for b in range(0, len(bricks), 7):  # each brick's rows are its voxels
        rows = v.coords[starts[b]:starts[b + 1]].astype(np.int64)
        assert np.all(rows >> 3 == bricks[b])
    if solid:
        inside = np.concatenate([stored["inside/coarse"], stored["inside/octants"]])
        key = lambda rows: sorted(map(tuple, rows.tolist()))  # noqa: E731
        assert key(inside) == key(v.inside)
        lo, hi = written.volume_bounds()
        assert (lo, hi) == v.volume_bounds()
    back = zarr_store.load_zarr(tmp_path / "w.zarr")
    np.testing.assert_array_equal(back.coords, v.coords)
    np.testing.assert_array_equal(back.normals, v.normals)
    if solid:
        np.testing.assert_array_equal(back.to_dense(solid=True), dense)
    # the same store from the voxels in memory (another path to the same tasks)
    zarr_writer.save_zarr(v, tmp_path / "s.zarr")
    saved = arrays(tmp_path / "s.zarr")
    assert saved.keys() == stored.keys()
    for name in stored:
        np.testing.assert_array_equal(saved[name], stored[name], err_msg=name)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["s.zarr", "w.zarr"], "a temporary folder was left"


def test_a_region_reads_what_the_voxels_hold_there(tmp_path, small_bricks):
    surface = implc.compile(TORUS)
    v = implc.voxelize(surface, 6, solid=True)
    zarr_writer.save_zarr(v, tmp_path / "t.zarr")
    for region in (((5, 35), (0, 23), (17, 64)), ((32, 33), (0, 64), (0, 64)), ((0, 64),) * 3):
        part = zarr_store.load_zarr(tmp_path / "t.zarr", region)
        box = np.array(region)
        mine = np.all((v.coords >= box[:, 0]) & (v.coords < box[:, 1]), axis=1)
        np.testing.assert_array_equal(part.coords, v.coords[mine])
        np.testing.assert_array_equal(part.normals, v.normals[mine])
        size = 1 << (6 - v.inside[:, 3].astype(np.int64))
        first = v.inside[:, :3].astype(np.int64) * size[:, None]
        meets = np.all((first < box[:, 1]) & (first + size[:, None] > box[:, 0]), axis=1)
        assert sorted(map(tuple, part.inside.tolist())) == sorted(map(tuple, v.inside[meets].tolist()))
    with pytest.raises(ValueError, match="region must be"):
        zarr_store.load_zarr(tmp_path / "t.zarr", ((0, 65), (0, 1), (0, 1)))


def test_every_shard_has_exactly_one_writer(tmp_path, small_bricks):
    """Tasks own whole bricks and their shards at every level of detail they write: no shard key is
    written by two tasks, and every shard file of those arrays is one a task reported."""
    surface = implc.compile(HOLLOW)
    written = zarr_writer.write_zarr(surface, 6, tmp_path / "h.zarr", solid=True, workers=2)
    keys = [k for task in written.shard_writers for k in task]
    assert len(keys) == len(set(keys)) > written.tasks
    layout = zarr_store.Layout.of(6, surface.bounds, True)
    by_tasks = ["occupancy"] + [f"lod/{k}" for k in range(layout.client_level + 1, 6)]
    assert by_tasks == ["occupancy", "lod/4", "lod/5"]
    on_disk = set()
    for array in by_tasks:
        folder = tmp_path / "h.zarr" / array / "c"
        on_disk |= {f"{array}/{'/'.join(f.relative_to(folder).parts)}" for f in folder.rglob("*") if f.is_file()}
    assert on_disk == set(keys)


def test_a_stopped_run_is_incomplete_and_resume_finishes_it(tmp_path, small_bricks, monkeypatch, capsys):
    surface = implc.compile(HOLLOW)
    calls = []
    real = zarr_writer.task_voxels
    monkeypatch.setattr(zarr_writer, "task_voxels", lambda *a, **k: (calls.append(a[2]), real(*a, **k))[1])
    zarr_writer.write_zarr(surface, 6, tmp_path / "ref.zarr", solid=True, workers=1)
    subdividing = len(calls)  # the tasks that subdivide (those inside an octant of the plan do not)
    calls.clear()

    def stopping(*args, **kwargs):
        calls.append(args[2])
        if len(calls) == 6:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(zarr_writer, "task_voxels", stopping)
    out = tmp_path / "h.zarr"
    with pytest.raises(KeyboardInterrupt):
        zarr_writer.write_zarr(surface, 6, out, solid=True, workers=1)
    partial = tmp_path / "h.zarr.partial"
    assert not out.exists() and partial.is_dir()
    finished = len(list((partial / "_parts").glob("*.npz")))
    ran = len(calls) - 1  # the sixth raised; the pool's thread may have finished one more before it stopped
    assert finished >= ran >= 5
    with pytest.raises(zarr_store.StoreError, match="incomplete"):
        zarr_store.load_zarr(partial)
    assert main(["info", str(partial)]) == 2
    assert "incomplete" in capsys.readouterr().err
    # another run's options do not resume it
    with pytest.raises(ValueError, match="another run"):
        zarr_writer.write_zarr(surface, 6, out, solid=False, resume=True)
    calls.clear()
    monkeypatch.setattr(zarr_writer, "task_voxels", lambda *a, **k: (calls.append(a[2]), real(*a, **k))[1])
    resumed = zarr_writer.write_zarr(surface, 6, out, solid=True, workers=1, resume=True)
    assert resumed.resumed == finished and len(calls) == subdividing - ran
    assert not partial.exists()
    a, b = arrays(tmp_path / "ref.zarr"), arrays(out)
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)
    with pytest.raises(ValueError, match="nothing to resume"):
        zarr_writer.write_zarr(surface, 6, out, solid=True, resume=True)


def test_a_damaged_or_foreign_store_is_one_line(tmp_path, capsys):
    out = tmp_path / "t.zarr"
    zarr_writer.write_zarr(implc.compile(TORUS), 5, out, solid=False)
    meta = out / "zarr.json"
    about = json.loads(meta.read_text())
    for change, message in ((lambda a: a["attributes"]["implc"].pop("manifest"), "incomplete"),
                            (lambda a: a["attributes"]["implc"].__setitem__("format", 1), "format 1"),
                            (lambda a: a["attributes"]["implc"].__setitem__("depth", 40), "depth 40"),
                            (lambda a: a["attributes"].pop("implc"), "not a store implc wrote")):
        changed = json.loads(json.dumps(about))
        change(changed)
        meta.write_text(json.dumps(changed))
        assert main(["info", str(out)]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
    zarr.create_array(store=str(tmp_path / "a.zarr"), shape=(4,), dtype="int8")
    assert main(["info", str(tmp_path / "a.zarr")]) == 2
    assert "cannot read" in capsys.readouterr().err


def test_a_store_with_damaged_or_forged_voxel_rows_is_one_line(tmp_path, capsys):
    """A chunk of the voxel rows damaged (zarr's codec raised RuntimeError through implc render, or it
    decompressed to other rows, which a full read dropped in silence), rows rewritten with coordinates
    outside the grid, or an array's damaged metadata, are one line and exit 2 from implc render, and an
    error from voxel_files.load: no damaged row is read as a voxel. Found by fuzzing stores."""
    from implc.files import voxel_files
    v = implc.voxelize(implc.compile(TORUS), 5, solid=True)
    for damage, message in (("chunk", "damaged implc Zarr store"), ("coords", "outside the bricks"),
                            ("metadata", "damaged implc Zarr store")):
        out = tmp_path / f"{damage}.zarr"
        voxel_files.save(v, out)
        if damage == "chunk":
            chunk = next(p for p in (out / "voxels" / "coords").rglob("*") if p.is_file() and p.name != "zarr.json")
            data = bytearray(chunk.read_bytes())
            data[64:128] = bytes(64)  # inside the first chunk's compressed frame (the shard's index is at its end)
            chunk.write_bytes(bytes(data))
        elif damage == "coords":
            coords = zarr.open_array(str(out / "voxels" / "coords"), mode="r+")
            coords[0] = [1000, 0, 0]
        else:  # a codec's option misspelt: zarr raised TypeError through implc info
            meta = out / "voxels" / "coords" / "zarr.json"
            meta.write_text(meta.read_text().replace('"endian"', '"enian"', 1))
        with pytest.raises(ValueError, match=message):
            voxel_files.load(out)
        assert main(["render", str(out), "-o", str(tmp_path / "r.png"), "--size", "32", "--quiet"]) == 2
        err = capsys.readouterr().err
        assert message in err and err.count("\n") == 1, err
        assert not (tmp_path / "r.png").exists()


def test_the_cli_checks_cluster_options_before_any_work(tmp_path, capsys):
    cases = [(["--cluster", "nowhere"], "not a scheduler address"),
             (["--cluster", "local:0"], "worker count"),
             (["--resume"], "nothing to resume")]
    for extra, message in cases:
        assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "t.zarr"), "--quiet", *extra]) == 2
        assert message in capsys.readouterr().err
    assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "t.npz"), "--resume"]) == 2
    assert "--resume finishes an interrupted .zarr run" in capsys.readouterr().err
    assert list(tmp_path.iterdir()) == []


def test_render_and_info_read_a_store(tmp_path, capsys):
    """implc render draws a store as it draws the same voxels from an .npz (the same PNG, byte for byte)."""
    from implc.files import voxel_files
    v = implc.voxelize(implc.compile(TORUS), 6, solid=True)
    voxel_files.save(v, tmp_path / "t.npz")
    voxel_files.save(v, tmp_path / "t.zarr")
    for name in ("t.npz", "t.zarr"):
        assert main(["render", str(tmp_path / name), "-o", str(tmp_path / f"{name}.png"), "--size", "64",
                     "--quiet"]) == 0
    assert (tmp_path / "t.npz.png").read_bytes() == (tmp_path / "t.zarr.png").read_bytes()
    assert main(["info", str(tmp_path / "t.zarr")]) == 0
    assert f"{len(v)} boundary voxels" in capsys.readouterr().out
    assert voxel_files.load(tmp_path / "t.zarr", ((0, 64), (0, 64), (0, 32))).coords[:, 2].max() < 32


def test_view_exports_a_store_as_it_exports_the_voxels(tmp_path):
    """implc view --export of a store writes the same static viewer as of the same voxels in an .npz."""
    from implc.files import voxel_files
    v = implc.voxelize(implc.compile(TORUS), 6)
    voxel_files.save(v, tmp_path / "t.npz")
    voxel_files.save(v, tmp_path / "t.zarr")
    for name in ("t.npz", "t.zarr"):
        assert main(["view", str(tmp_path / name), "--export", str(tmp_path / f"{name}.view"), "--quiet"]) == 0
    a = {p.relative_to(tmp_path / "t.npz.view"): p.read_bytes() for p in (tmp_path / "t.npz.view").rglob("*")
         if p.is_file()}
    b = {p.relative_to(tmp_path / "t.zarr.view"): p.read_bytes() for p in (tmp_path / "t.zarr.view").rglob("*")
         if p.is_file()}
    assert a.keys() == b.keys() and len(a) > 2
    assert [k for k in a if a[k] != b[k]] == []


def test_a_write_abandoned_by_a_killed_worker_is_not_left_in_the_store(tmp_path, monkeypatch):
    """A worker killed while zarr writes a shard leaves zarr's temporary file (NAME.<uuid hex>.partial) in
    the store; its task runs again elsewhere. Found by the cluster's killed-worker test (one run in five):
    the finished store held occupancy/c/2/1/3.<uuid>.partial. Finishing removes such files, and only those."""
    from pathlib import Path

    real = zarr_writer.store_task
    litter = []

    def killed_mid_write(folder, *args, **kwargs):
        summary = real(folder, *args, **kwargs)
        if not litter:  # the first task's worker "dies" writing a shard after its task's files were written
            stray = Path(folder) / "occupancy" / "c" / "0" / "0" / f"0.{'7b2f0837' * 4}.partial"
            stray.parent.mkdir(parents=True, exist_ok=True)
            stray.write_bytes(b"half a shard")
            keep = Path(folder) / "occupancy" / "notes.partial"  # not zarr's temporary name: kept
            keep.write_bytes(b"")
            litter.extend([stray.relative_to(folder), keep.relative_to(folder)])
        return summary

    monkeypatch.setattr(zarr_writer, "store_task", killed_mid_write)
    out = tmp_path / "torus.zarr"
    zarr_writer.write_zarr(implc.compile(shapes.torus(0.5, 0.2)), 6, out, workers=1)
    assert litter and not (out / litter[0]).exists() and (out / litter[1]).exists()
    assert len(voxel_files.load(out)) > 0


def _stopped_run(tmp_path, monkeypatch, stop_after=6):
    """A run of HOLLOW at 64³ stopped after some tasks: (its partial folder, the reference store)."""
    surface = implc.compile(HOLLOW)
    zarr_writer.write_zarr(surface, 6, tmp_path / "ref.zarr", solid=True, workers=1)
    real, calls = zarr_writer.task_voxels, []

    def stopping(*args, **kwargs):
        calls.append(1)
        if len(calls) == stop_after:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(zarr_writer, "task_voxels", stopping)
    with pytest.raises(KeyboardInterrupt):
        zarr_writer.write_zarr(surface, 6, tmp_path / "h.zarr", solid=True, workers=1)
    monkeypatch.setattr(zarr_writer, "task_voxels", real)
    return surface, tmp_path / "h.zarr.partial"


@pytest.mark.parametrize("damage", ["altered coords", "fifo",
                                    *[pytest.param(d, marks=pytest.mark.slow)  # the same path, other damage
                                      for d in ("altered normals", "truncated", "no checksum")]])
def test_resume_trusts_a_part_only_with_its_checksum(tmp_path, small_bricks, monkeypatch, damage):
    """A finished part that was altered (its coordinates or normals rewritten, a valid file), truncated,
    replaced by a FIFO or left without its recorded SHA-256 is not trusted: its task runs again, and the
    resumed store is, array by array, the clean run's."""
    surface, partial = _stopped_run(tmp_path, monkeypatch)
    parts = sorted((partial / "_parts").glob("*.npz"))
    victim = next(p for p in parts if len(np.load(p)["coords"]))
    if damage.startswith("altered"):
        with np.load(victim) as part:
            content = {name: part[name] for name in part.files}
        member = damage.split()[1]
        content[member] = content[member] + 1
        np.savez(victim, **content)  # a valid part, with other voxels
    elif damage == "truncated":
        victim.write_bytes(victim.read_bytes()[: victim.stat().st_size // 2])
    elif damage == "fifo":
        victim.unlink()
        os.mkfifo(victim)
    else:
        victim.with_suffix(".sha256").unlink()
    resumed = zarr_writer.write_zarr(surface, 6, tmp_path / "h.zarr", solid=True, workers=1, resume=True)
    assert resumed.resumed == len(parts) - 1
    a, b = arrays(tmp_path / "ref.zarr"), arrays(tmp_path / "h.zarr")
    assert a.keys() == b.keys()
    for name in a:
        np.testing.assert_array_equal(a[name], b[name], err_msg=name)


def test_one_writer_per_store(tmp_path, small_bricks, monkeypatch, capsys):
    """While a run writes a store (its partial folder locked), a second run is refused in one line, its
    resume too, and nothing of the first run's is touched."""
    import fcntl
    surface, partial = _stopped_run(tmp_path, monkeypatch)
    before = sorted(p.name for p in (partial / "_parts").iterdir())
    fd = os.open(partial, os.O_RDONLY)
    fcntl.flock(fd, fcntl.LOCK_EX)  # as the running writer holds it
    try:
        for resume in (True, False):
            with pytest.raises(ValueError, match="another implc run is writing"):
                zarr_writer.write_zarr(surface, 6, tmp_path / "h.zarr", solid=True, workers=1, resume=resume)
        code = main(["voxelize", "--expr", "x - 0.1", "--depth", "6", "-o", str(tmp_path / "h.zarr"), "--resume",
                     "--quiet"])
        err = capsys.readouterr().err
        assert code == 2 and err.count("\n") == 1 and "another implc run" in err
    finally:
        os.close(fd)
    assert sorted(p.name for p in (partial / "_parts").iterdir()) == before
    zarr_writer.write_zarr(surface, 6, tmp_path / "h.zarr", solid=True, workers=1, resume=True)  # now it may
