"""Ctrl-C stops a long voxelization within a second and leaves no thread behind."""

import signal
import subprocess
import sys
import textwrap
import time

SCRIPT = textwrap.dedent("""
    import sys, threading, sympy, implc
    from implc import theta, phi, r
    s = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r)
    print("started", flush=True)
    try:
        implc.voxelize(s, 12, workers=2, storage="coords")
    except KeyboardInterrupt:
        print("interrupted", threading.active_count(), flush=True)
        sys.exit(3)
    print("finished", flush=True)
""")


def test_ctrl_c_stops_promptly():
    proc = subprocess.Popen([sys.executable, "-c", SCRIPT], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    assert proc.stdout.readline().strip() == "started"
    time.sleep(1.5)  # well into the run (depth 12 takes far longer)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    elapsed = time.monotonic() - sent
    assert proc.returncode == 3, (out, err)
    assert out.strip() == "interrupted 1"  # only the main thread is left
    assert elapsed < 1.0, f"took {elapsed:.2f} s to stop"


BATCH_SCRIPT = textwrap.dedent("""
    import sys, numpy as np, sympy, implc
    from implc import theta, phi, r
    s = implc.compile(sympy.sin(4 * theta) * sympy.sin(8 * phi) - r)
    points = np.random.default_rng(0).uniform(-1, 1, (10**7, 3))
    print("started", flush=True)
    try:
        s.gradient(points)  # about 2 s on this machine: one native call per 65536 points
    except KeyboardInterrupt:
        print("interrupted", flush=True)
        sys.exit(3)
    print("finished", flush=True)
""")


def test_ctrl_c_stops_a_large_batched_evaluation_promptly():
    proc = subprocess.Popen([sys.executable, "-c", BATCH_SCRIPT], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            text=True)
    assert proc.stdout.readline().strip() == "started"
    time.sleep(0.3)
    sent = time.monotonic()
    proc.send_signal(signal.SIGINT)
    out, err = proc.communicate(timeout=30)
    elapsed = time.monotonic() - sent
    assert proc.returncode == 3 and out.strip() == "interrupted", (out, err)
    assert elapsed < 1.0, f"took {elapsed:.2f} s to stop"


STARTER = ("import sys, runpy, importlib.util, implc; importlib.util.find_spec('implc.__main__'); "
           "print('ready', flush=True); sys.argv = ['implc', 'scenes']; "
           "runpy.run_module('implc', run_name='__main__', alter_sys=True)")
"""``python -m implc`` from a child that says "ready" once the interpreter is up and the package found (its
``__init__`` imports nothing: the names are loaded on first use), so that the delays count from where implc's
start-up begins, whatever the load of the machine (a CI run once signalled a child still in runpy)."""


def test_ctrl_c_at_start_up_is_one_line():
    """SIGINT while `python -m implc` starts (SymPy, NumPy and LLVM being imported: about a second) ends
    with 'interrupted' and status 130, never a traceback. What remains outside implc's reach is the first
    few milliseconds, while the interpreter and runpy load the package and its entry module (the child
    says "ready" once they are found: :data:`STARTER`)."""
    for delay in (0.08, 0.12, 0.2, 0.3, 0.45, 0.7):
        proc = subprocess.Popen([sys.executable, "-c", STARTER], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                                text=True)
        assert proc.stdout.readline().strip() == "ready"
        time.sleep(delay)
        proc.send_signal(signal.SIGINT)
        _, err = proc.communicate(timeout=30)
        assert "Traceback" not in err, (delay, err)
        assert proc.returncode in (0, 130, -signal.SIGINT), (delay, proc.returncode, err)
        if proc.returncode == 130:
            assert err.strip() == "implc: interrupted", err


def test_ctrl_c_while_the_workers_start(monkeypatch):
    """An interrupt while the worker threads are being started (found by interrupting the CLI at random
    moments) stops the run with the interrupt itself, not with an error about joining a thread that never
    started."""
    import threading

    import pytest

    import implc
    s = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 0.5)
    original = threading.Thread.start
    started = []

    def start_then_interrupt(self):
        if self.name.startswith("implc-worker") and started:
            raise KeyboardInterrupt  # the second worker's start is interrupted
        started.append(self)
        original(self)
    monkeypatch.setattr(threading.Thread, "start", start_then_interrupt)
    before = threading.active_count()
    with pytest.raises(KeyboardInterrupt):
        implc.voxelize(s, 7, workers=3)
    monkeypatch.undo()
    for th in started:
        th.join(5)
    assert threading.active_count() == before
