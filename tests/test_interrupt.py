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
