"""A cluster that shares its data through an object store, as rented clusters do: moto's S3 server, a Dask
scheduler and two workers, each its own process, the credentials in their environment only. The store
written to the server is, object by object, the one a single process writes to a folder; regions, ``implc
info`` and the viewer read it there; a worker killed (SIGKILL) mid-run and a Ctrl-C with ``--resume``
after it leave the same store; no output and no object holds the secret key. Marked slow: processes."""

import os
import signal
import subprocess
import sys
import time

import pytest

import implc
from implc.cli.commands import main
from implc.errors import StoreError
from implc.files import scene, zarr_store, zarr_writer

from ..support.cluster import Cluster, landed_after_interrupt
from ..support.s3 import SECRET, s3  # noqa: F401 - the fixture
from ..support.stores import assert_same_reads, assert_same_store, store_objects

pytestmark = pytest.mark.slow


@pytest.fixture
def cluster(tmp_path, s3):  # noqa: F811 - the fixture above
    c = Cluster(tmp_path, env=dict(os.environ, **s3.env))
    c.add_worker()
    c.add_worker()
    c.wait_for(2)
    yield c
    c.close()


def _parts(url: str) -> list[str]:
    return sorted(name for name in _names(url) if name.startswith("_parts/") and name.endswith(".npz"))


def _names(url: str) -> list[str]:
    import s3fs
    fs = s3fs.S3FileSystem()
    fs.invalidate_cache()
    root = url.removeprefix("s3://")
    return [name[len(root) + 1:] for name in fs.find(root)]


def test_a_cluster_writes_the_folders_store_to_s3(cluster, s3, tmp_path, capfd):  # noqa: F811
    """The CLI with --cluster and an s3:// output: the single-process store, object for object; read back by
    region, described and exported for the viewer from the server as from the folder."""
    sc = scene.load("paper_blobs")
    surface = implc.compile(sc.surface, sc.bounds)
    here = tmp_path / "blobs.zarr"  # the store's name is the viewer's title
    zarr_writer.write_zarr(surface, 9, here, solid=True, workers=2)
    url = f"s3://{s3.bucket()}/runs/blobs.zarr"
    assert main(["voxelize", "paper_blobs", "--depth", "9", "--solid", "-o", url, "--cluster", cluster.address]) == 0
    assert_same_store(here, url)
    assert not any(name.startswith("_parts") for name in _names(url))
    assert_same_reads(here, url, ((100, 300), (0, 512), (250, 260)))
    assert main(["info", url]) == 0
    for name, source in (("here", str(here)), ("there", url)):
        assert main(["view", source, "--export", str(tmp_path / f"{name}.view"), "--quiet"]) == 0
    views = [{p.relative_to(tmp_path / f"{n}.view"): p.read_bytes() for p in (tmp_path / f"{n}.view").rglob("*")
              if p.is_file()} for n in ("here", "there")]
    assert views[0].keys() == views[1].keys() and len(views[0]) > 2
    assert [k for k in views[0] if views[0][k] != views[1][k]] == []
    out, err = capfd.readouterr()
    assert SECRET not in out + err
    assert not any(SECRET.encode() in data for data in store_objects(url).values())


def test_a_killed_worker_and_ctrl_c_then_resume_on_s3(cluster, s3, tmp_path):  # noqa: F811
    """At 2048³ to S3: a worker killed (its tasks run again elsewhere, a fresh worker joins), then the CLI
    interrupted (exit 130): the store under the URL has no manifest (readers refuse it) and keeps its
    finished parts; after the interrupt only the tasks already running (one per worker) land, none starts;
    --resume finishes it into the single-process store."""
    url = f"s3://{s3.bucket()}/blobs.zarr"
    env = dict(os.environ, **s3.env)
    command = [sys.executable, "-m", "implc", "voxelize", "paper_blobs", "--depth", "11", "--solid", "-o", url,
               "--cluster", cluster.address, "--quiet"]
    run = subprocess.Popen(command, env=env, stderr=subprocess.PIPE, text=True)

    def wait_for_parts(count: int):
        deadline = time.time() + 180
        while len(_parts(url)) < count:
            assert time.time() < deadline and run.poll() is None, run.stderr.read() if run.poll() is not None else ""
            time.sleep(0.05)

    wait_for_parts(2)
    cluster.workers[0].kill()
    cluster.add_worker()
    wait_for_parts(5)
    run.send_signal(signal.SIGINT)
    _, err = run.communicate(timeout=60)
    assert run.returncode == 130, err
    assert "--resume" in err and SECRET not in err
    kept = landed_after_interrupt(lambda: _parts(url))
    assert 5 <= len(kept) < 52
    with pytest.raises(StoreError, match="incomplete"):
        zarr_store.load_zarr(url)
    done = subprocess.run(command + ["--resume"], env=env, capture_output=True, text=True, timeout=300)
    assert done.returncode == 0, done.stderr
    assert SECRET not in done.stdout + done.stderr
    sc = scene.load("paper_blobs")
    zarr_writer.write_zarr(implc.compile(sc.surface, sc.bounds), 11, tmp_path / "here.zarr", solid=True)
    assert_same_store(tmp_path / "here.zarr", url)


def test_a_missing_bucket_is_one_line(s3, tmp_path, capsys):  # noqa: F811
    code = main(["voxelize", "--expr", "x - 0.1", "--depth", "5", "-o", "s3://implc-no-such-bucket/x.zarr", "--quiet"])
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "bucket 'implc-no-such-bucket' does not exist" in err, err


def test_an_unreachable_endpoint_is_one_line(monkeypatch, capsys):
    """No S3 server where AWS_ENDPOINT_URL points: botocore's own error (not an OSError), as one line."""
    import socket
    s3fs = pytest.importorskip("s3fs", reason="s3fs comes with the s3test extra: pip install -e '.[s3test]'")
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]  # closed again: nothing listens there
    monkeypatch.setenv("AWS_ENDPOINT_URL", f"http://127.0.0.1:{port}")
    monkeypatch.setenv("AWS_ACCESS_KEY_ID", "implc-test-key")
    monkeypatch.setenv("AWS_SECRET_ACCESS_KEY", SECRET)
    s3fs.S3FileSystem.clear_instance_cache()
    try:
        code = main(["voxelize", "--expr", "x - 0.1", "--depth", "4", "-o", "s3://implc-bucket/x.zarr", "--quiet"])
    finally:
        s3fs.S3FileSystem.clear_instance_cache()
    err = capsys.readouterr().err
    assert code == 2 and err.count("\n") == 1 and "Could not connect" in err and SECRET not in err, err
