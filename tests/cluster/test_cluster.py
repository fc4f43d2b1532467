"""implc on a Dask cluster whose scheduler and workers are separate processes (as on real hosts): the
stores it writes are, array by array, the single-process run's; a worker killed in the middle costs only
its tasks (a fresh worker joins, the store is the same); ``local:N`` starts and stops its own cluster; a
surface travels as text and is rebuilt the same. Marked slow: each test starts processes."""

import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import implc
from implc.cli.commands import main
from implc.cluster.recipe import TravelError, build, recipe_of
from implc.compiler.vm import parse_vm
from implc.errors import ClusterError
from implc.files import scene, zarr_writer

from ..support.cluster import Cluster, landed_after_interrupt
from ..support.stores import assert_same_store

pytestmark = pytest.mark.slow

@pytest.fixture
def cluster(tmp_path):
    c = Cluster(tmp_path)
    c.add_worker()
    c.add_worker()
    c.wait_for(2)
    yield c
    c.close()


@pytest.mark.parametrize("name,solid", [("paper_blobs", True), ("csg_part", False), ("paper_sin4_sin8", False)])
def test_separate_processes_write_the_single_process_store(cluster, tmp_path, name, solid):
    """The CLI against a scheduler and two workers (their own processes): three scenes (the paper's blobs
    as a solid, a CSG part through the tape engine, a spherical scene) give the single-process store."""
    sc = scene.load(name)
    surface = implc.compile(sc.surface, sc.bounds)
    zarr_writer.write_zarr(surface, 9, tmp_path / "here.zarr", solid=solid, workers=2)
    args = ["voxelize", name, "--depth", "9", "-o", str(tmp_path / "there.zarr"), "--quiet",
            "--cluster", cluster.address] + (["--solid"] if solid else [])
    assert main(args) == 0
    assert_same_store(tmp_path / "here.zarr", tmp_path / "there.zarr")
    # gathered into memory instead: the same voxels as voxelize here
    gathered = implc.voxelize(surface, 8, solid=solid, cluster=cluster.address)
    here = implc.voxelize(surface, 8, solid=solid)
    np.testing.assert_array_equal(gathered.coords, here.coords)
    np.testing.assert_array_equal(gathered.normals, here.normals)
    if solid:
        assert sorted(map(tuple, gathered.inside.tolist())) == sorted(map(tuple, here.inside.tolist()))


def test_a_killed_worker_costs_only_its_tasks(cluster, tmp_path):
    """A worker killed (SIGKILL) while the run is under way at 2048³: Dask runs its tasks again elsewhere,
    a fresh worker joins, and the store is the single-process run's."""
    sc = scene.load("paper_blobs")
    surface = implc.compile(sc.surface, sc.bounds)
    out = tmp_path / "killed.zarr"
    failures = []

    def run():
        try:
            zarr_writer.write_zarr(surface, 11, out, solid=True, cluster=cluster.address)
        except BaseException as exc:  # noqa: BLE001 - reported by the test's thread
            failures.append(exc)

    runner = threading.Thread(target=run)
    runner.start()
    parts = tmp_path / "killed.zarr.partial" / "_parts"
    deadline = time.time() + 120
    while not (parts.is_dir() and len(list(parts.glob("*.npz"))) >= 3):
        assert time.time() < deadline and runner.is_alive(), f"no task finished: {failures}"
        time.sleep(0.02)
    cluster.workers[0].kill()
    cluster.add_worker()
    runner.join(300)
    assert not runner.is_alive() and not failures, failures
    assert not parts.exists(), "the parts are removed once the store is complete"
    zarr_writer.write_zarr(surface, 11, tmp_path / "here.zarr", solid=True, workers=2)
    assert_same_store(tmp_path / "here.zarr", out)


def test_a_local_cluster_is_started_and_stopped(tmp_path, capsys):
    sc = scene.load("torus")
    surface = implc.compile(sc.surface, sc.bounds)
    zarr_writer.write_zarr(surface, 8, tmp_path / "here.zarr", solid=True, workers=2)
    assert main(["voxelize", "torus", "--depth", "8", "--solid", "-o", str(tmp_path / "there.zarr"),
                 "--cluster", "local:2"]) == 0
    err = capsys.readouterr().err
    assert "local:2: 2 workers, dashboard http://" in err
    assert_same_store(tmp_path / "here.zarr", tmp_path / "there.zarr")
    import distributed
    assert not distributed.client._global_clients, "the local cluster's client was left open"


def test_surfaces_travel_as_text():
    """A SymPy surface as its srepr text, a .vm model as its text: rebuilt, they evaluate the same; a model
    inlined into a SymPy expression cannot travel and says so."""
    from implc import shapes
    part = shapes.difference(shapes.smooth_union(0.05, shapes.rounded_box((0.6, 0.4, 0.1), 0.02),
                                                 shapes.array_polar(shapes.sphere(0.1, (0.3, 0, 0.1)), 6)),
                             shapes.capped_cylinder(0.05, 1))  # built as given: Min/Max unsorted, unpruned
    for sc in [scene.load(name) for name in ("paper_blobs", "csg_part", "paper_sin4_sin8")] + [
            scene.Scene("part", part, ((-1, 1),) * 3)]:
        surface = implc.compile(sc.surface, sc.bounds)
        recipe = recipe_of(surface)
        rebuilt = build(recipe)
        assert rebuilt is build(recipe), "a process compiles a recipe once"
        points = np.random.default_rng(1).uniform(-1, 1, (200, 3))
        np.testing.assert_array_equal(rebuilt.eval(points), surface.eval(points))
        assert rebuilt.engine == surface.engine and rebuilt.bounds == surface.bounds
    text = "x var-x\ny var-y\nz var-z\nxx square x\nyy square y\nzz square z\ns add xx yy\nt add s zz\nc const 0.25\n" \
           "out sub t c\n"
    model = parse_vm(text, name="ball")
    ball = implc.compile(model)
    assert recipe_of(ball).kind == "vm" and build(recipe_of(ball)).eval([[0.5, 0, 0]])[0] == 0
    with pytest.raises(TravelError, match="cannot travel"):
        recipe_of(implc.compile(model(implc.x, implc.y, implc.z) + implc.x / 10))
    import dataclasses
    with pytest.raises(TravelError, match="install the same implc"):
        build(dataclasses.replace(recipe_of(ball), software="implc 0123456789abcdef, llvmlite 0.1"))


def test_ctrl_c_cancels_the_cluster_and_resume_finishes(cluster, tmp_path):
    """implc voxelize --cluster interrupted (SIGINT) once some tasks are done: exit 130, nothing under the
    output's name, the finished tasks kept in OUT.partial and, once the tasks running at the interrupt
    have finished, no more land there (the queued ones were cancelled); --resume finishes it and the
    store is the single-process run's."""
    out = tmp_path / "blobs.zarr"
    env = dict(os.environ)
    command = [sys.executable, "-m", "implc", "voxelize", "paper_blobs", "--depth", "11", "--solid", "-o", str(out),
               "--cluster", cluster.address, "--quiet"]
    run = subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True)
    parts = tmp_path / "blobs.zarr.partial" / "_parts"
    deadline = time.time() + 120
    while not (parts.is_dir() and len(list(parts.glob("[0-9]*.npz"))) >= 3):
        assert time.time() < deadline and run.poll() is None, run.stderr.read() if run.poll() is not None else ""
        time.sleep(0.02)
    run.send_signal(signal.SIGINT)
    _, err = run.communicate(timeout=60)
    assert run.returncode == 130, err
    assert "--resume" in err and not out.exists()
    kept = landed_after_interrupt(lambda: sorted(p.name for p in parts.glob("[0-9]*.npz")))
    assert 3 <= len(kept) < 52
    done = subprocess.run(command + ["--resume"], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    sc = scene.load("paper_blobs")
    zarr_writer.write_zarr(implc.compile(sc.surface, sc.bounds), 11, tmp_path / "here.zarr", solid=True)
    assert_same_store(tmp_path / "here.zarr", out)


def _cluster_with_one_worker(tmp_path) -> Cluster:
    c = Cluster(tmp_path)
    c.add_worker()
    c.wait_for(1)
    return c


def test_a_run_whose_only_worker_dies_ends(tmp_path):
    """The only worker killed mid-run: the run does not wait for ever; with no worker for the bound (2 s
    here, run_tasks' parameter) it ends in one ClusterError."""
    from implc.cluster.tasks import connect, run_tasks
    c = _cluster_with_one_worker(tmp_path)
    try:
        with connect(c.address) as client:
            killer = threading.Timer(1.0, c.workers[0].kill)
            killer.start()
            t0 = time.monotonic()
            with pytest.raises(ClusterError, match="no workers"):
                run_tasks(client, time.sleep, [(0.5,)] * 40, no_workers_seconds=2.0)
            assert time.monotonic() - t0 < 30
            killer.join()
    finally:
        c.close()


def test_a_scheduler_that_dies_ends_the_run_in_one_line(tmp_path, capsys):
    c = _cluster_with_one_worker(tmp_path)
    try:
        killer = threading.Timer(2.0, c.scheduler.kill)
        killer.start()
        t0 = time.monotonic()
        code = main(["voxelize", "paper_blobs", "--depth", "11", "-o", str(tmp_path / "s.zarr"), "--quiet",
                     "--cluster", c.address])
        err = capsys.readouterr().err
        assert code == 2 and "Traceback" not in err and time.monotonic() - t0 < 90
        lines = [line for line in err.splitlines() if line.startswith("implc: error")]
        assert len(lines) == 1 and "scheduler" in lines[0], err
        killer.join()
    finally:
        c.close()


@pytest.mark.parametrize("address,words", [("local:\u0662", "worker count"), ("local:100000", "worker count"),
                                           ("tls://127.0.0.1:1", "cannot connect"),
                                           ("ucx://127.0.0.1:1", "cannot connect"),
                                           ("tcp://admin:s3cr3t@127.0.0.1:1", "cannot connect"),
                                           ("admin:s3cr3t@host", "not a scheduler address")])
def test_cluster_addresses_are_one_line_and_keep_credentials_out(tmp_path, address, words):
    run = subprocess.run([sys.executable, "-m", "implc", "voxelize", "torus", "--depth", "5", "-o",
                          str(tmp_path / "t.zarr"), "--quiet", "--cluster", address],
                         capture_output=True, text=True, timeout=120)
    assert run.returncode == 2 and run.stderr.count("\n") == 1 and words in run.stderr, run.stderr
    assert "s3cr3t" not in run.stderr and "admin" not in run.stderr


def test_worker_counts_are_bounded(capsys):
    from implc.common.threads import max_workers
    with pytest.raises(ValueError, match="workers must be"):
        implc.voxelize(implc.compile(implc.x - 0.1), 3, workers=max_workers() + 1)
    assert main(["voxelize", "torus", "--depth", "3", "-o", "never.npz", "--workers", "100000"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "--workers" in err
