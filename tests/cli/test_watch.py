"""Live editing: ``implc view part.py --watch`` rebuilds the part on every save in a child process, the
page updates in place with its camera kept, and nothing a user's script does stops the server."""

import http.client
import json
import queue
import subprocess
import sys
import threading
import time

import numpy as np
import pytest

import implc
from implc import shapes
from implc.cli.watch import Job, Watcher
from implc.view.server import ViewServer

from ..support.browser import until

USES_HELPER = '"""A ball."""\nfrom implc import shapes\nfrom sizes import RADIUS\nsurface = shapes.sphere(RADIUS)\n'
SPHERE = '''"""A ball."""
from implc import shapes
surface = shapes.sphere({radius})
'''


def _expected(radius: float, depth: int) -> int:
    return len(implc.voxelize(implc.compile(shapes.sphere(radius)), depth))


class _Events:
    """The watcher's callbacks as a queue of ("build", Build) and ("error", line)."""

    def __init__(self):
        self.queue: queue.Queue = queue.Queue()

    def next(self, timeout=60.0):
        return self.queue.get(timeout=timeout)


def _save(path, text):
    """Write as an editor does; the modification time moves on even within the clock's granularity."""
    before = path.stat().st_mtime_ns if path.exists() else 0
    path.write_text(text)
    while path.stat().st_mtime_ns == before:
        time.sleep(0.01)
        path.write_text(text)


def test_each_save_is_built_and_what_the_script_does_wrong_is_one_line(tmp_path):
    part, helper = tmp_path / "part.py", tmp_path / "sizes.py"
    helper.write_text("RADIUS = 0.5\n")
    part.write_text(USES_HELPER)
    events = _Events()
    watcher = Watcher(Job(str(part), depth=5), on_build=lambda b: events.queue.put(("build", b)),
                      on_error=lambda line: events.queue.put(("error", line)))
    try:
        first = watcher.first()
        assert len(first.arrays["coords"]) == _expected(0.5, 5) and first.depth == 5
        assert str(helper.resolve()) in watcher.files  # a module beside the scene is watched with it
        watcher.start()

        _save(part, SPHERE.format(radius=0.7))
        kind, build = events.next()
        assert kind == "build" and len(build.arrays["coords"]) == _expected(0.7, 5)

        cases = [("surface = shapes.sphere(0.5)\nradius = undefined_name\n", "part.py, line 3: NameError"),
                 ("surface = shapes.sphere(\n", "part.py, line 2: SyntaxError: '(' was never closed"),
                 ("import sys\nsys.exit(3)\n", "part.py, line 2: SystemExit: 3"),
                 ("import os\nos._exit(3)\n", "exit status 3"),
                 ("import os, signal\nos.kill(os.getpid(), signal.SIGKILL)\n", "killed by signal 9"),
                 ("surface = shapes.smooth_union(-1, shapes.sphere(0.5), shapes.sphere(0.2))\n",
                  "part.py, line 2: ValueError: radius must be above 0")]
        for text, words in cases:
            _save(part, "from implc import shapes\n" + text if "shapes" in text else text)
            kind, line = events.next()
            assert kind == "error" and words in line and "\n" not in line, (text, line)

        _save(part, SPHERE.format(radius=0.3))  # after a crashed child, a fresh one builds the next save
        kind, build = events.next()
        assert kind == "build" and len(build.arrays["coords"]) == _expected(0.3, 5)

        _save(part, USES_HELPER)
        kind, build = events.next()
        assert kind == "build" and len(build.arrays["coords"]) == _expected(0.5, 5)
        _save(helper, "RADIUS = 0.6\n")  # an edit of the helper module alone: rebuilt, and imported afresh
        kind, build = events.next()
        assert kind == "build" and len(build.arrays["coords"]) == _expected(0.6, 5)
    finally:
        watcher.close()


def test_a_save_during_a_build_stops_it_and_the_latest_wins(tmp_path):
    part = tmp_path / "part.py"
    part.write_text(SPHERE.format(radius=0.5))
    events = _Events()
    watcher = Watcher(Job(str(part), depth=5), on_build=lambda b: events.queue.put(("build", b)),
                      on_error=lambda line: events.queue.put(("error", line)))
    try:
        watcher.first()
        watcher.start()
        _save(part, "import time\ntime.sleep(600)\n")  # a build that would never end
        time.sleep(1.0)
        _save(part, SPHERE.format(radius=0.4))
        kind, build = events.next()
        assert kind == "build" and len(build.arrays["coords"]) == _expected(0.4, 5)
        assert events.queue.empty()  # the stopped build reported nothing
    finally:
        watcher.close()


def _get(server, path):
    conn = http.client.HTTPConnection("127.0.0.1", server.port, timeout=30)
    conn.request("GET", f"/{server.token}/{path}")
    response = conn.getresponse()
    return response.status, response.read()


def test_a_live_server_answers_news_at_once_and_refuses_an_older_generation():
    ball = implc.voxelize(implc.compile(shapes.sphere(0.5)), 6)
    smaller = implc.voxelize(implc.compile(shapes.sphere(0.3)), 6)
    from implc.view.page import lod_chunks
    with ViewServer(lod_chunks(ball), port=0, live=True).start() as server:
        status, body = _get(server, "meta.json")
        meta = json.loads(body)
        assert status == 200 and meta["live"] and meta["generation"] == 0 and meta["voxels"] == len(ball)
        answers: list = []
        waiting = threading.Thread(target=lambda: answers.append(_get(server, "live.json?after=0")))
        started = time.monotonic()
        waiting.start()
        time.sleep(0.5)
        assert not answers  # nothing new yet: the request waits
        server.replace(lod_chunks(smaller))
        waiting.join(10)
        assert time.monotonic() - started < 5
        state = json.loads(answers[0][1])
        assert state["generation"] == 1 and state["error"] is None
        assert _get(server, "chunks/0-0-0-0.bin?generation=0")[0] == 409
        assert _get(server, "chunks/0-0-0-0.bin?generation=1")[0] == 200
        assert json.loads(_get(server, "meta.json")[1])["voxels"] == len(smaller)
        server.report(error="part.py, line 3: NameError: name 'x1' is not defined")
        state = json.loads(_get(server, f"live.json?after={state['revision']}")[1])
        assert state["error"].startswith("part.py, line 3") and state["generation"] == 1


@pytest.mark.slow
def test_the_page_follows_saves_keeps_its_camera_and_shows_errors(browser, tmp_path):
    part = tmp_path / "part.py"
    part.write_text(SPHERE.format(radius=0.5))
    server = subprocess.Popen([sys.executable, "-m", "implc", "view", str(part), "--watch", "--no-browser",
                               "--port", "0", "--depth", "6"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                              text=True)
    try:
        url = next(line.strip() for line in server.stdout if line.startswith("http://"))
        page = browser.new_page(viewport={"width": 400, "height": 400})
        page.goto(url)
        until(page, "window.implcViewer.drawnGeneration === 0")
        page.evaluate("window.implcViewer.setView(120, -20, 4)")
        meta = page.evaluate("fetch('meta.json').then(r => r.json())")
        assert meta["voxels"] == _expected(0.5, 6)

        _save(part, SPHERE.format(radius=0.8))
        until(page, "window.implcViewer.drawnGeneration === 1")
        until(page, "window.implcViewer.stats().settled")
        camera = page.evaluate("window.implcViewer.camera")
        assert (camera["azimuth"], camera["elevation"], camera["distance"]) == (120, -20, 4)
        assert str(_expected(0.8, 6)) in page.inner_text("#overlay").replace(",", "")

        _save(part, "from implc import shapes\nsurface = shapes.sphere(0.5) + missing\n")
        until(page, "document.getElementById('status').className === 'error'")
        assert "part.py, line 2: NameError" in page.inner_text("#status")
        assert page.evaluate("window.implcViewer.drawnGeneration") == 1  # the last good model stays
        assert server.poll() is None

        _save(part, SPHERE.format(radius=0.6))
        until(page, "window.implcViewer.drawnGeneration === 2")
        until(page, "document.getElementById('status').className === ''")
        pixels = np.frombuffer(page.screenshot(), dtype=np.uint8)
        assert len(pixels) > 0 and server.poll() is None
    finally:
        server.terminate()
        _, err = server.communicate(timeout=20)
    assert "NameError" in err and "Traceback" not in err
