"""Live editing (``implc view part.py --watch``): the scene file rebuilt each time it is saved, each build in
a fresh process of its own, the viewer given each new model.

A user's script is run, compiled, voxelized (and meshed) in a child process, never in the server's: an
exception or ``sys.exit`` is reported by the child, a crash, a runaway loop or its memory ends it, and the
server reports one line and keeps the last good model. The child has imported implc and warmed its engines
before the first save, and serves build after build (SymPy's cache keeps what an edit did not change);
before each build it forgets the modules beside the scene file, so an edit to a helper module is seen too
(they are watched with it). A save that comes while a build runs stops that build (its child is killed and
a fresh one started): the latest save wins.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import sys
import threading
import time
import traceback
from dataclasses import dataclass, field
from pathlib import Path
from types import SimpleNamespace
from typing import Any

POLL_SECONDS = 0.03
"""How often the watched files' sizes and modification times are read."""


@dataclass(frozen=True)
class Job:
    """What a build makes: the scene file, the depth (None: the scene's own), the bounds (None: the
    scene's), mesh or voxels, and the voxelizer's keyword arguments."""

    path: str
    depth: int | None = None
    bounds: Any = None
    mesh: bool = False
    options: dict = field(default_factory=dict)


@dataclass
class Build:
    """A finished build: the model's arrays (voxels' Morton-ordered coords and normals, or a mesh's
    vertices, faces and normals), its name, depth, bounds and view, the seconds it took and the files it
    read (the scene and the modules beside it)."""

    name: str
    depth: int
    bounds: Any
    view: Any
    arrays: dict
    seconds: float
    files: list[str] = field(default_factory=list)

    def shown(self):
        """What the viewer serves: the voxels' levels of detail, or the mesh."""
        from ..view.mesh_payload import MeshPayload
        from ..view.page import lod_chunks
        if "faces" in self.arrays:
            mesh = SimpleNamespace(bounds=self.bounds, **self.arrays)
            return MeshPayload(mesh, name=self.name, view=self.view)
        voxels = SimpleNamespace(depth=self.depth, bounds=self.bounds, **self.arrays)
        return lod_chunks(voxels, name=self.name, view=self.view)

    def summary(self) -> str:
        if "faces" in self.arrays:
            return f"{len(self.arrays['faces'])} triangles at {1 << self.depth}³ in {self.seconds:.2f} s"
        return f"{len(self.arrays['coords'])} voxels at {1 << self.depth}³ in {self.seconds:.2f} s"


class BuildError(Exception):
    """A build that failed: its one-line message names the file and line where the scene's own code
    failed."""


def _one_line(exc: BaseException, path: Path) -> str:
    """The exception as one line, with the scene file's last line in its traceback (or the modules' beside
    it)."""
    from ..errors import SceneError
    cause = exc.__cause__ if isinstance(exc, SceneError) and exc.__cause__ is not None else exc  # the script's own
    where = ""
    folder = path.resolve().parent
    if isinstance(cause, SyntaxError) and cause.filename:
        where = f"{Path(cause.filename).name}, line {cause.lineno}: "
    else:
        for frame in reversed(traceback.extract_tb(cause.__traceback__)):
            if frame.filename and Path(frame.filename).resolve().parent == folder:
                where = f"{Path(frame.filename).name}, line {frame.lineno}: "
                break
    message = cause.msg if isinstance(cause, SyntaxError) else str(cause)  # its str repeats file and line
    message = " ".join(str(message).split()) or type(cause).__name__
    if type(cause).__module__.startswith("implc"):
        text = message
    else:
        text = f"{type(cause).__name__}: {message}"
    return (where + text)[:400]


def _build(job: Job) -> Build:
    """Load, compile, voxelize (and mesh) the scene as ``job`` says: run in the child."""
    from ..engines.surface import compile as compile_surface
    from ..files.scene import load
    from ..voxelizer.voxelize import voxelize
    started = time.perf_counter()
    folder = Path(job.path).resolve().parent
    scene = load(job.path)
    surface = compile_surface(scene.surface, job.bounds if job.bounds is not None else scene.bounds)
    depth = job.depth if job.depth is not None else scene.depth
    voxels = voxelize(surface, depth, **job.options)
    if job.mesh:
        mesh = voxels.mesh()
        arrays = {"vertices": mesh.vertices, "faces": mesh.faces, "normals": mesh.normals}
    else:
        arrays = {"coords": voxels.coords, "normals": voxels.normals}
    files = sorted(set(_modules_beside(folder).values()) | {str(Path(job.path).resolve())})
    return Build(scene.name, depth, surface.bounds, scene.view, arrays, time.perf_counter() - started, files)


def _modules_beside(folder: Path) -> dict[str, str]:
    """The modules imported from ``folder`` (the scene's): name → resolved file."""
    found = {}
    for name, module in list(sys.modules.items()):
        where = getattr(module, "__file__", None)
        if where and Path(where).resolve().parent == folder:
            found[name] = str(Path(where).resolve())
    return found


def _forget_beside(path: str) -> None:
    """Drop the modules imported from the scene's folder, so the next build imports them as saved."""
    for name in _modules_beside(Path(path).resolve().parent):
        del sys.modules[name]


def _child(connection) -> None:
    """A build process: warm up (import implc, run its engines once), then answer jobs until the pipe
    closes. Ctrl-C is the server's to handle: the server stops its children."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        import implc

        from .. import shapes  # noqa: F401 - imported now so that a scene's import of it costs nothing
        implc.voxelize(implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 0.5), 3)
    except Exception:  # noqa: BLE001 - a broken install shows in the build's own error below
        pass
    while True:
        try:
            job = connection.recv()
        except (EOFError, OSError):
            return
        _forget_beside(job.path)
        try:
            answer: tuple = ("ok", _build(job))
        except BaseException as exc:  # noqa: BLE001 - whatever the user's script raised, SystemExit included
            answer = ("error", _one_line(exc, Path(job.path)))
        try:
            connection.send(answer)
        except OSError:
            return


class _Child:
    """One build process and our end of its pipe."""

    def __init__(self, context):
        self.connection, theirs = context.Pipe()
        self.process = context.Process(target=_child, args=(theirs,), name="implc-watch-build", daemon=True)
        self.process.start()
        theirs.close()

    def stop(self):
        if self.process.is_alive():
            self.process.kill()
        self.process.join(5)
        self.connection.close()


def _signature(files) -> tuple:
    """What changes when any of ``files`` is saved (its size, modification time and inode), None for a
    missing one."""
    out: list[tuple | None] = []
    for name in files:
        try:
            st = os.stat(name)
            out.append((st.st_mtime_ns, st.st_size, st.st_ino))
        except OSError:
            out.append(None)
    return tuple(out)


class Watcher:
    """Rebuilds ``job``'s scene whenever one of its files changes and hands each result to ``on_build``
    (a :class:`Build`), each failure to ``on_error`` (one line), each start to ``on_start``; from a thread of
    its own once :meth:`start` is called."""

    def __init__(self, job: Job, *, on_build, on_error, on_start=lambda: None, poll: float = POLL_SECONDS):
        self.job, self.poll = job, poll
        self.on_build, self.on_error, self.on_start = on_build, on_error, on_start
        self._context = multiprocessing.get_context("spawn")  # never fork a process that serves threads
        self._child: _Child | None = None
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self.files = [str(Path(job.path).resolve())]
        self._seen: tuple | None = None

    def first(self) -> Build:
        """The first build, here and now; :class:`BuildError` where it fails."""
        files, self._seen = list(self.files), self._signature_now()
        outcome = self._run(self._seen)
        if not isinstance(outcome, Build):
            raise BuildError(outcome or "the build was stopped")
        if self.files != files:  # the modules beside the scene that it read: watched from now on
            self._seen = self._signature_now()
        return outcome

    def start(self) -> Watcher:
        self._thread = threading.Thread(target=self._loop, name="implc-watch", daemon=True)
        self._thread.start()
        return self

    def close(self):
        self._stop.set()
        if self._thread is not None:
            self._thread.join(10)
        if self._child is not None:
            self._child.stop()
            self._child = None

    def _signature_now(self) -> tuple:
        return _signature(self.files)

    def _run(self, signature: tuple) -> Build | str | None:
        """One build of the files as they are now: the Build, an error line, or None when a newer save
        stopped it (or the watcher closes). A child that dies or is stopped is replaced at once, so the
        next one warms up while the user edits."""
        if self._child is None or not self._child.process.is_alive():
            if self._child is not None:
                self._child.stop()
            self._child = _Child(self._context)
        child, outcome = self._child, None
        try:
            child.connection.send(self.job)
            while True:
                if child.connection.poll(self.poll):
                    status, value = child.connection.recv()
                    if status == "ok":
                        self.files = value.files or self.files
                    return value
                if not child.process.is_alive() and not child.connection.poll():
                    outcome = self._died(child)
                    break
                if self._stop.is_set() or (self._thread is not None and self._signature_now() != signature):
                    break  # a newer save: this build is stopped, the loop starts the next
        except (EOFError, OSError):
            outcome = self._died(child)
        child.stop()
        self._child = None if self._stop.is_set() else _Child(self._context)
        return outcome

    @staticmethod
    def _died(child: _Child) -> str:
        child.process.join(5)
        code = child.process.exitcode
        if code is not None and code < 0:
            return f"the build process was killed by signal {-code} (out of memory, or a crash in the scene's code)"
        return f"the build process ended with exit status {code} before its result (os._exit in the scene?)"

    def _loop(self):
        seen = self._seen  # the files as the first build read them: a save since then is built at once
        while not self._stop.wait(self.poll):
            now = self._signature_now()
            if now == seen:
                continue
            seen, files = now, list(self.files)
            self.on_start()
            outcome = self._run(now)
            if outcome is None:
                seen = None  # stopped by a newer save: build that one next
                continue
            if isinstance(outcome, str):
                self.on_error(outcome)
            else:
                self.on_build(outcome)
            if self.files != files:  # the build read other modules beside the scene: watched from now on
                seen = self._signature_now()
