"""A Dask scheduler and workers as separate processes (as on real hosts), for the cluster tests."""

import contextlib
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

DASK = Path(sys.executable).parent / "dask"


class Cluster:
    """A Dask scheduler and workers, each its own process, the kernel cache shared as on one host."""

    def __init__(self, folder: Path, env: dict | None = None):
        self.folder = folder
        self.file = folder / "scheduler.json"
        self.env = dict(os.environ if env is None else env, DASK_DISTRIBUTED__WORKER__DAEMON="False")
        self.scheduler = subprocess.Popen([str(DASK), "scheduler", "--scheduler-file", str(self.file), "--port", "0",
                                           "--no-dashboard", "--host", "127.0.0.1"], env=self.env,
                                          stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.workers: list[subprocess.Popen] = []
        deadline = time.time() + 60
        while not self.file.exists() or not self.file.read_text().strip():
            assert time.time() < deadline, "the scheduler did not start"
            time.sleep(0.1)
        self.address = json.loads(self.file.read_text())["address"]

    def add_worker(self) -> subprocess.Popen:
        worker = subprocess.Popen([str(DASK), "worker", "--scheduler-file", str(self.file), "--nthreads", "1",
                                   "--no-nanny", "--no-dashboard", "--host", "127.0.0.1",
                                   "--local-directory", str(self.folder / "work")], env=self.env,
                                  stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        self.workers.append(worker)
        return worker

    def wait_for(self, count: int):
        from distributed import Client
        with Client(self.address, timeout="30s") as client:
            client.wait_for_workers(count, timeout=60)

    def close(self):
        for process in self.workers + [self.scheduler]:  # the workers first, then their scheduler
            if process.poll() is None:
                process.send_signal(signal.SIGTERM)
                if process is not self.scheduler:
                    with contextlib.suppress(subprocess.TimeoutExpired):
                        process.wait(5)
        for process in self.workers + [self.scheduler]:
            try:
                process.wait(3)
            except subprocess.TimeoutExpired:  # a worker may wait for a scheduler already gone
                process.kill()
                process.wait()


def landed_after_interrupt(landed, workers: int = 2) -> list:
    """What ``landed()`` lists (the finished tasks' parts) once it stays the same for 3 s after an
    interrupt (60 s at most): the tasks running on the workers at the interrupt finish, as Dask cannot
    stop a running task, but no more start. Asserts both, and returns the listing."""
    at_interrupt = kept = landed()
    deadline = time.time() + 60
    while True:
        time.sleep(3)
        now = landed()
        if now == kept or time.time() > deadline:
            break
        kept = now
    assert landed() == kept, "tasks went on after the interrupt"
    assert len(set(kept) - set(at_interrupt)) <= workers, "more tasks finished after the interrupt than were running"
    return kept
