"""Folder outputs never delete what implc did not write: a viewer export, a slice stack or a Zarr store is
written in place of an existing folder only where that folder is empty or one of implc's own outputs of the
same kind; a user's folder of the same name is refused in one line, with every file in it untouched. A run
that stopped keeps its finished work until the user resumes it or removes it."""

import hashlib

import pytest

import implc
from implc import shapes
from implc.cli.commands import main
from implc.common.atomic_file import MARKER
from implc.files import zarr_store, zarr_writer

PRECIOUS = {"precious.txt": b"a year of work", "sub/thesis.tex": b"\\section{Results}"}


def users_folder(path):
    for name, data in PRECIOUS.items():
        (path / name).parent.mkdir(parents=True, exist_ok=True)
        (path / name).write_bytes(data)
    return path


def untouched(path) -> bool:
    files = sorted(p.relative_to(path).as_posix() for p in path.rglob("*") if p.is_file())
    return files == sorted(PRECIOUS) and all((path / n).read_bytes() == d for n, d in PRECIOUS.items())


def run(capsys, argv) -> tuple[int, str]:
    code = main([str(a) for a in argv])
    return code, capsys.readouterr().err


@pytest.fixture
def mesh_file(tmp_path):
    path = tmp_path / "ball.stl"
    implc.mesh(implc.compile(shapes.sphere(0.6)), 4).save(path)
    return path


@pytest.mark.parametrize("what", ["export", "slices", "zarr", "zarr-from-npz"])
def test_a_users_folder_is_refused_and_left_whole(tmp_path, capsys, mesh_file, what):
    target = users_folder((tmp_path / "out").resolve())
    target.mkdir(exist_ok=True)
    if what == "export":
        argv = ["view", mesh_file, "--export", target, "--quiet"]
    elif what == "slices":
        argv = ["voxelize", "torus", "--depth", "4", "-o", target, "--slices", "png", "--quiet"]
    elif what == "zarr":
        target = users_folder(tmp_path / "data.zarr")
        argv = ["voxelize", "torus", "--depth", "4", "-o", target, "--quiet"]
    else:
        voxels = implc.voxelize(implc.compile(shapes.sphere(0.6)), 4, solid=True)
        target = users_folder(tmp_path / "v.zarr")
        with pytest.raises(ValueError, match="not an implc zarr store"):
            implc.files.voxel_files.save(voxels, target)
        assert untouched(target)
        return
    code, err = run(capsys, argv)
    assert code == 2 and err.count("\n") == 1 and "not an implc" in err, err
    assert untouched(target)
    assert sorted(p.name for p in tmp_path.iterdir() if p.name.startswith(".")) == []  # no temporary left


def test_implcs_own_outputs_are_replaced(tmp_path, capsys, mesh_file):
    """Writing again over an export, a slice stack or a store replaces it (the newer one wins), and an empty
    folder is filled."""
    for argv, target in ((["view", mesh_file, "--export", tmp_path / "site", "--quiet"], tmp_path / "site"),
                         (["voxelize", "torus", "--depth", "4", "-o", tmp_path / "s", "--slices", "png", "--quiet"],
                          tmp_path / "s"),
                         (["voxelize", "torus", "--depth", "4", "-o", tmp_path / "d.zarr", "--quiet"],
                          tmp_path / "d.zarr")):
        target.mkdir()
        assert run(capsys, argv)[0] == 0
        first = hashlib.sha256(b"".join(p.read_bytes() for p in sorted(target.rglob("*")) if p.is_file())).digest()
        assert run(capsys, argv)[0] == 0, capsys.readouterr().err
        second = hashlib.sha256(b"".join(p.read_bytes() for p in sorted(target.rglob("*")) if p.is_file())).digest()
        assert first == second  # the same output, written again in its place
    assert not (tmp_path / "d.zarr" / MARKER).exists()  # a store is recognised by its zarr.json


def test_a_store_with_a_users_file_added_is_not_replaced(tmp_path):
    """A store the user put a file of their own into is no longer only implc's: refused, the file kept."""
    surface = implc.compile(shapes.torus(0.5, 0.2))
    out = tmp_path / "s.zarr"
    zarr_writer.write_zarr(surface, 4, out, workers=1)
    (out / "notes.txt").write_text("mine")
    with pytest.raises(ValueError, match="not an implc zarr store"):
        zarr_writer.write_zarr(surface, 4, out, workers=1)
    assert (out / "notes.txt").read_text() == "mine"


def test_a_stopped_run_is_kept_until_resumed_or_removed(tmp_path, capsys, monkeypatch):
    """Run again without --resume, a stopped run's finished tasks are not thrown away: one line says to
    resume (or to remove it), exit status 2, and the parts are all still there; --resume then finishes it."""
    surface_args = ["voxelize", "torus", "--depth", "6", "--quiet", "--workers", "1"]
    out = tmp_path / "t.zarr"
    real = zarr_writer.task_voxels
    calls = []

    def stopping(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return real(*args, **kwargs)

    monkeypatch.setattr(zarr_writer, "task_voxels", stopping)
    small = zarr_store.sizes(zarr_store.Sizes(shard=8, chunk=4))  # many tasks
    small.__enter__()
    request_cleanup = small.__exit__
    try:
        assert run(capsys, [*surface_args, "-o", out])[0] == 130
        partial = tmp_path / "t.zarr.partial"
        parts = sorted(p.name for p in (partial / "_parts").iterdir())
        assert parts
        monkeypatch.setattr(zarr_writer, "task_voxels", real)
        code, err = run(capsys, [*surface_args, "-o", out])
        assert code == 2 and err.count("\n") == 1 and "--resume" in err
        assert sorted(p.name for p in (partial / "_parts").iterdir()) == parts
        assert run(capsys, [*surface_args, "-o", out, "--resume"])[0] == 0
        assert out.is_dir() and not partial.exists()
    finally:
        request_cleanup(None, None, None)


def test_a_users_folder_named_like_a_partial_run_is_not_taken(tmp_path):
    users_folder(tmp_path / "u.zarr.partial")
    surface = implc.compile(shapes.torus(0.5, 0.2))
    with pytest.raises(ValueError, match="is not implc's"):
        zarr_writer.write_zarr(surface, 4, tmp_path / "u.zarr", workers=1)
    with pytest.raises(ValueError, match="not an unfinished implc zarr store"):
        zarr_writer.write_zarr(surface, 4, tmp_path / "u.zarr", workers=1, resume=True)
    assert untouched(tmp_path / "u.zarr.partial")
