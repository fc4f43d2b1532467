"""Every bad input the command can get: one line on stderr, exit status 2, no traceback, and no file created
or damaged; inputs that merely look odd (negative numbers after --bounds, a formula starting with '-',
an upper-case suffix) work. Interrupts at any moment of a save leave the old file or the whole new one."""

import hashlib
import os
import signal
import subprocess
import sys
import time

import numpy as np
import pytest

import implc
from implc.cli.commands import main
from implc.files import voxel_files

from ..support.command import run

SCENE_TEXT = {
    "string_surface.py": "surface = 'x**2 + y**2 - 1'\n",
    "string_view.py": "import implc\nsurface = implc.x**2 + implc.y**2 + implc.z**2 - 0.5\nview = 'front'\n",
    "word_depth.py": "import implc\nsurface = implc.x - 0.1\ndepth = 'deep'\n",
    "bad_bounds.py": "import implc\nsurface = implc.x - 0.1\nbounds = ((1, 0), (0, 1), (0, 1))\n",
    "broken.py": "import sympy\nsurface = (\n",
    "no_surface.py": "bounds = ((-1, 1),) * 3\n",
}


@pytest.fixture(scope="module")
def files(tmp_path_factory):
    """Good files of every format, damaged and foreign ones, scenes with bad values, and a file to keep."""
    d = tmp_path_factory.mktemp("files")
    v = implc.voxelize(implc.compile(implc.shapes.torus(0.6, 0.25)), 5)
    for suffix in (".npz", ".ply", ".npy"):
        voxel_files.save(v, d / f"good{suffix}")
    (d / "empty.npz").write_bytes(b"")
    good = (d / "good.npz").read_bytes()
    (d / "truncated.npz").write_bytes(good[: len(good) // 2])
    (d / "text.npz").write_text("hello\n")

    def npz(name, **changes):
        arrays = dict(implc_voxels=1, coords=v.coords, normals=v.normals, depth=v.depth,
                      bounds=np.asarray(v.bounds, dtype=np.float64))
        arrays.update(changes)
        np.savez(d / name, **arrays)
    npz("bounds_shape.npz", bounds=np.zeros((2, 2)))
    npz("neg_depth.npz", depth=-3)
    npz("depth200.npz", depth=200)
    npz("outside.npz", coords=v.coords + np.uint32(1 << v.depth))
    npz("nan_normals.npz", normals=np.full_like(v.normals, np.nan))
    npz("pickled.npz", coords=np.array([object()] * 3, dtype=object))
    for name, text in SCENE_TEXT.items():
        (d / name).write_text(text)
    (d / "keep.npz").write_bytes(good)
    return d


def digest(path):
    return hashlib.sha256(path.read_bytes()).hexdigest() if path.is_file() else "folder"


BAD_INPUTS = [  # (argv, words the message must contain); {d} is the folder of the files fixture
    (["voxelize", "nosuch", "-o", "{d}/new.npz"], "no scene 'nosuch'"),
    (["voxelize", "{d}/missing.py", "-o", "{d}/new.npz"], "no scene"),
    (["voxelize", "{d}/broken.py", "-o", "{d}/new.npz"], "failed to load: SyntaxError"),
    (["voxelize", "{d}/no_surface.py", "-o", "{d}/new.npz"], "defines no 'surface'"),
    (["voxelize", "torus", "--depth", "0", "-o", "{d}/new.npz"], "--depth must be an integer from 1 to 21"),
    (["voxelize", "torus", "-o", "{d}/new.txt"], "unknown output format '.txt'"),
    (["voxelize", "torus", "-o", "{d}/no/new.npz"], "does not exist"),
    (["render", "torus", "--size", "5", "-o", "{d}/new.png"], "--size must be an integer from 16 to 8192"),
    (["render", "torus", "--view", "up", "-o", "{d}/new.png"], "--view must be two numbers"),
    (["voxelize", "torus", "--bounds", "1,2,3", "-o", "{d}/new.npz"], "--bounds must be six"),
    (["voxelize", "--expr", "x", "--bounds", "1,0,-1,1,-1,1", "-o", "{d}/new.npz"], "lo < hi"),
    (["info", "{d}/empty.npz"], "is empty"),
    (["info", "{d}/truncated.npz"], "damaged or truncated"),
    (["info", "{d}/text.npz"], "not a voxel file"),
    (["info", "{d}/bounds_shape.npz"], "bounds must be three"),
    (["info", "{d}/neg_depth.npz"], "depth must be an integer from 1 to 21"),
    (["info", "{d}/depth200.npz"], "depth must be an integer from 1 to 21"),
    (["info", "{d}/outside.npz"], "outside the 32³ grid"),
    (["info", "{d}/nan_normals.npz"], "normals must be finite"),
    (["info", "{d}/pickled.npz"], "holds Python objects"),
    (["info", "{d}/missing.npz"], "no such file"),
    (["render", "{d}/good.ply", "-o", "{d}/new.png"], "is a PLY point cloud"),
    (["render", "{d}/good.npy", "-o", "{d}/new.png"], "dense .npy occupancy grid"),
    (["render", "{d}/good.npz", "--depth", "5", "-o", "{d}/new.png"], "--depth cannot apply"),
    (["render", "{d}/good.npz", "--expr", "x", "-o", "{d}/new.png"], "--expr cannot apply"),
    (["render", "{d}/good.npz", "--view", "nan,nan", "-o", "{d}/new.png"], "--view must be finite"),
    (["voxelize", "{d}/string_surface.py", "-o", "{d}/new.npz"], "'surface' must be a SymPy expression, got str"),
    (["render", "{d}/string_view.py", "-o", "{d}/new.png"], "'view' must be two numbers"),
    (["voxelize", "{d}/word_depth.py", "-o", "{d}/new.npz"], "'depth' must be an integer from 1 to 21, got 'deep'"),
    (["voxelize", "{d}/bad_bounds.py", "-o", "{d}/new.npz"], "'bounds'"),
    (["voxelize", "--expr", "-" * 1000 + "x", "--depth", "3", "-o", "{d}/new.npz"], "nested too deeply"),
    (["voxelize", "--expr", "max()", "-o", "{d}/new.npz"], "max() needs an argument"),
    (["voxelize", "--expr", "", "-o", "{d}/new.npz"], "--expr is empty"),
    (["voxelize", "--expr", "x +* " + "y + " * 2400, "-o", "{d}/new.npz"], "cannot parse"),
    (["voxelize", "--expr", "x/0", "-o", "{d}/new.npz"], "division by zero"),
    (["voxelize", "--expr", "tanh(0.5 / 0.0)", "-o", "{d}/new.npz"], "division by zero"),  # a Float 0 (fuzzing)
    # SymPy evaluates a function of a number as it builds it: mpmath's cosh of this one ran for minutes (fuzzing)
    (["voxelize", "--expr", "cosh(exp(1e308 / 1e300) * 1e308) + x", "-o", "{d}/new.npz"], "is too large"),
    (["voxelize", "--expr", "asin(cos(10 / (pi / 1e300))) + x", "-o", "{d}/new.npz"], "SymPy cannot build"),
    (["voxelize", "--expr", "tanh(x) ** sinh((-1) ** pi)", "-o", "{d}/new.npz"], "not a real number"),
    (["voxelize", "--expr", "x", "--bounds=-1e308,1e308,-1,1,-1,1", "-o", "{d}/new.npz"], "too far apart"),
    (["voxelize", "--expr", "x", "--bounds", "0,1e-320,-1,1,-1,1", "-o", "{d}/new.npz"], "too close"),
    (["voxelize", "--expr", "x", "--bounds", "0,inf,-1,1,-1,1", "-o", "{d}/new.npz"], "--bounds must be finite"),
    (["voxelize", "--expr", "x", "--workers", "0", "-o", "{d}/new.npz"], "--workers must be from 1 to"),
    (["voxelize", "torus", "--depth", "22", "-o", "{d}/new.npz"], "--depth must be an integer from 1 to 21"),
    (["voxelize", "torus", "-o", "{d}"], "is a folder"),
    (["voxelize", "torus", "--frobnicate", "-o", "{d}/new.npz"], "unrecognized arguments"),
    (["voxelize", "{d}/good.npz", "-o", "{d}/new.npz"], "is a voxel file"),
    (["render", "nothing.ply", "-o", "{d}/new.png"], "no such file"),
    (["demo", "--depth", "0", "--out-dir", "{d}/demo"], "--depth must be an integer from 1 to 21"),
    (["voxelize", "--expr", "x", "-o", "{d}/keep.npz", "--depth", "99"], "--depth must be"),
    (["voxelize", "--expr", "x + w", "-o", "{d}/keep.npz"], "unknown name 'w'"),
]


@pytest.mark.parametrize("argv, words", BAD_INPUTS, ids=[f"{k}-{a[0]}" for k, (a, _) in enumerate(BAD_INPUTS)])
def test_a_bad_input_is_one_line_with_exit_2_and_writes_nothing(argv, words, files, capsys):
    """In this process, through implc.cli.commands.main (an exception escaping it would fail the test with its
    traceback); the start-up path of a real process is tested with interrupts in test_interrupt.py."""
    before = {p.name: digest(p) for p in files.iterdir()}
    status = main([a.replace("{d}", str(files)) for a in argv])
    err = capsys.readouterr().err
    lines = err.strip().splitlines()
    assert status == 2 and len(lines) == 1 and "Traceback" not in err, (status, err[:400])
    assert words in err and len(err) < 400, err[:400]
    assert {p.name: digest(p) for p in files.iterdir()} == before, "a failed command created or changed a file"


def test_info_describes_every_format_it_writes(files):
    for suffix, words in ((".npz", "implc voxels"), (".ply", "PLY point cloud"), (".npy", "dense occupancy")):
        status, out, err = run("info", str(files / f"good{suffix}"))
        assert status == 0 and words in out, (suffix, out, err)
    v = voxel_files.load_npz(files / "good.npz")
    assert f"voxels   {len(v)}" in run("info", str(files / "good.npy"))[1]
    assert f"points   {len(v)}" in run("info", str(files / "good.ply"))[1]


def test_odd_but_good_inputs_work(tmp_path):
    """The README's own example (negative numbers after --bounds), --view with negative angles, a formula
    starting with '-', an upper-case suffix, --version."""
    out = tmp_path / "S.NPZ"
    status, _, err = run("voxelize", "--expr", "-x + 0.25", "-o", str(out), "--bounds", "-1,1,-1,1,-1,1",
                         "--depth", "4", "--quiet")
    assert status == 0, err
    v = voxel_files.load_npz(out)
    assert v.bounds == ((-1, 1),) * 3 and len(v) > 0 and set(v.coords[:, 0]) <= {9, 10}
    assert [p.name for p in tmp_path.iterdir()] == ["S.NPZ"]
    status, _, err = run("render", str(out), "--view", "-30,-20", "--size", "32", "-o", str(tmp_path / "s.png"),
                         "--quiet")
    assert status == 0, err
    status, stdout, _ = run("--version")
    assert status == 0 and stdout.startswith("implc ")


def test_api_arguments_are_checked():
    s = implc.compile(implc.x - 0.3)
    for kwargs, words in (({"max_voxels": "a"}, "max_voxels must be a whole number"),
                          ({"max_voxels": 0}, "max_voxels must be a whole number"),
                          ({"workers": 2.7}, "workers must be a whole number"),
                          ({"workers": True}, "workers must be a whole number")):
        with pytest.raises(ValueError, match=words):
            implc.voxelize(s, 4, **kwargs)
    with pytest.raises(MemoryError, match="max_voxels=1"):  # enforced when the plan reaches the leaves too
        implc.voxelize(s, 2, max_voxels=1)
    assert len(implc.voxelize(s, 2, max_voxels=16)) > 1


@pytest.mark.parametrize("sig", [signal.SIGINT, pytest.param(signal.SIGTERM, marks=pytest.mark.slow)])  # 7 s each
def test_an_interrupted_save_never_damages_the_old_file(tmp_path, sig):
    """Interrupt `implc voxelize -o keep.npz` at several moments, saving included (a compressed save of
    a depth-9 torus takes a good part of the run): keep.npz is always the old file or a complete new one,
    and no temporary file is left behind."""
    keep = tmp_path / "keep.npz"
    voxel_files.save(implc.voxelize(implc.compile(implc.x - 0.5), 3), keep)
    old = digest(keep)
    outcomes = set()
    argv = ["implc", "voxelize", "torus", "--depth", "9", "--compress", "--quiet", "-o", str(keep)]
    starter = (f"import sys, runpy; print('ready', flush=True); sys.argv = {argv!r}; "
               "runpy.run_module('implc', run_name='__main__', alter_sys=True)")  # python -m implc, once it is up
    for delay in (0.3, 0.9, 1.3, 1.7, 2.4):
        proc = subprocess.Popen([sys.executable, "-c", starter], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(delay)
        proc.send_signal(sig)
        _, err = proc.communicate(timeout=60)
        assert "Traceback" not in err, err
        assert proc.returncode in (0, 130, 143, -sig), (proc.returncode, err)
        if digest(keep) == old:
            outcomes.add("old")
        else:
            assert len(voxel_files.load_npz(keep)) > 0  # complete and valid
            outcomes.add("new")
            keep.write_bytes(b"")  # start the next round from a known old file again
            voxel_files.save(implc.voxelize(implc.compile(implc.x - 0.5), 3), keep)
            old = digest(keep)
        assert sorted(p.name for p in tmp_path.iterdir()) == ["keep.npz"], "a temporary file was left"
    assert "old" in outcomes


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_while_main_restores_its_handlers_is_no_traceback(tmp_path, monkeypatch, capsys, sig):
    """A signal that lands after the command's outcome is decided, while main() puts the signal handlers
    back (a CI run's SIGINT did, at random), is noted, not raised: main() returns the command's status and
    the output is whole. Sent here, deterministically, from the first restoring call."""
    import os

    from implc.cli import commands as cli
    from implc.cli import signals
    real = signal.signal
    sent = []

    def restoring(signum, handler):
        if handler is not signals.on_sigterm and handler is not signals.on_sigint and not sent:
            sent.append(signum)
            os.kill(os.getpid(), sig)  # delivered to the handler still in place
        return real(signum, handler)

    monkeypatch.setattr(cli.signal, "signal", restoring)
    out = tmp_path / "a.npz"
    assert main(["voxelize", "--expr", "x - 0.25", "--depth", "3", "--quiet", "-o", str(out)]) == 0
    assert sent and signals.signalled == [sig]
    assert len(voxel_files.load_npz(out)) > 0
    assert signal.getsignal(signal.SIGINT) is not signals.on_sigint  # put back
    capsys.readouterr()


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_after_the_command_of_a_process_is_only_noted(tmp_path, sig):
    """``python -m implc`` and the ``implc`` script keep main()'s handlers (restore_handlers=False): a
    signal that lands after the outcome is decided, on the way out of the process, is noted, not raised."""
    import os

    from implc.cli import commands as cli
    from implc.cli import signals
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    try:
        out = tmp_path / "a.npz"
        assert cli.main(["voxelize", "--expr", "x - 0.25", "--depth", "3", "--quiet", "-o", str(out)],
                        restore_handlers=False) == 0
        assert signal.getsignal(sig) in (signals.on_sigint, signals.on_sigterm)  # still in place
        os.kill(os.getpid(), sig)  # the handler runs right after this call returns
        assert signals.signalled == [sig]
    finally:
        signal.signal(signal.SIGINT, before[0])
        signal.signal(signal.SIGTERM, before[1])


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM])
def test_a_signal_in_a_finalizer_is_sent_again_not_lost(sig):
    """A signal that lands in a callback whose exceptions Python prints and drops (a finalizer, an import
    lock's weakref callback: a CI run's SIGTERM did, and 'Exception ignored ... Traceback' was all it left)
    is not raised there: it is sent again a moment later, and raised where it can stop the command."""
    from implc.cli import signals
    dropped = []
    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM), sys.unraisablehook
    sys.unraisablehook = dropped.append

    class Finalized:
        def __del__(self):
            handler = signals.on_sigint if sig == signal.SIGINT else signals.on_sigterm
            handler(sig, sys._getframe())

    try:
        signal.signal(signal.SIGINT, signals.on_sigint)
        signal.signal(signal.SIGTERM, signals.on_sigterm)
        signals.settled = False
        signals.signalled.clear()
        item = Finalized()
        del item  # the handler runs in __del__ (as if the signal had landed there)
        assert not dropped and signals.signalled == []
        with pytest.raises(KeyboardInterrupt if sig == signal.SIGINT else signals.Terminated):
            time.sleep(5)  # the signal again, from the timer: raised here
        assert signals.signalled == [sig]
    finally:
        signal.signal(signal.SIGINT, before[0])
        signal.signal(signal.SIGTERM, before[1])
        sys.unraisablehook = before[2]
        signals.settled = True  # as main() leaves it


@pytest.mark.skipif(not os.path.exists("/dev/full"), reason="needs /dev/full")
def test_a_full_standard_output_is_one_line_naming_what_was_written(tmp_path):
    """The mesh is written, then the summary cannot be: one line says both, exit status 2."""
    with open("/dev/full", "w") as full:
        run = subprocess.run([sys.executable, "-m", "implc", "mesh", "torus", "--depth", "4", "-o",
                              str(tmp_path / "t.stl")], stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    assert run.returncode == 2 and run.stderr.count("\n") == 1
    assert "t.stl was written in full, but standard output failed" in run.stderr
    assert (tmp_path / "t.stl").stat().st_size > 84
