"""A real S3 API for the tests: moto's server as its own process on a free loopback port, reached through
s3fs as any S3 endpoint is (``AWS_ENDPOINT_URL``), with credentials only in the environment."""

import contextlib
import os
import shutil
import socket
import subprocess
import sys
import time
import uuid
from pathlib import Path

import pytest

SECRET = "implc-test-secret-" + "7f3a9c" * 4
"""The secret access key the tests give: it must appear in no output, log or object."""


class S3Server:
    """moto's S3 server on 127.0.0.1 and the environment that reaches it."""

    def __init__(self, folder: Path):
        with socket.socket() as s:
            s.bind(("127.0.0.1", 0))
            self.port = s.getsockname()[1]
        self.endpoint = f"http://127.0.0.1:{self.port}"
        self.env = {"AWS_ENDPOINT_URL": self.endpoint, "AWS_ACCESS_KEY_ID": "implc-test-key",
                    "AWS_SECRET_ACCESS_KEY": SECRET, "AWS_DEFAULT_REGION": "us-east-1"}
        server = shutil.which("moto_server") or str(Path(sys.executable).parent / "moto_server")
        self.log = open(folder / "moto.log", "wb")  # noqa: SIM115 - closed in close()
        self.process = subprocess.Popen([server, "-H", "127.0.0.1", "-p", str(self.port)], stdout=self.log,
                                        stderr=subprocess.STDOUT)
        deadline = time.time() + 30
        while True:
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", self.port), timeout=1):
                break
            assert self.process.poll() is None and time.time() < deadline, "moto's S3 server did not start"
            time.sleep(0.1)

    def bucket(self) -> str:
        """A new, empty bucket's name."""
        import s3fs
        name = f"implc-{uuid.uuid4().hex[:12]}"
        s3fs.S3FileSystem().mkdir(name)
        return name

    def close(self):
        self.process.terminate()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()
            self.process.wait()
        self.log.close()


@pytest.fixture(scope="module")
def s3(tmp_path_factory):
    """The server, with this process's environment pointing at it for the module's tests (s3fs's cached
    filesystems forgotten on the way in and out, so that none reaches another endpoint)."""
    for module in ("s3fs", "moto"):
        pytest.importorskip(module, reason=f"{module} comes with the s3test extra: pip install -e '.[s3test]'")
    import s3fs
    server = S3Server(tmp_path_factory.mktemp("s3"))
    saved = {name: os.environ.get(name) for name in server.env}
    os.environ.update(server.env)
    s3fs.S3FileSystem.clear_instance_cache()
    try:
        yield server
    finally:
        for name, value in saved.items():
            if value is None:
                os.environ.pop(name, None)
            else:
                os.environ[name] = value
        s3fs.S3FileSystem.clear_instance_cache()
        server.close()
