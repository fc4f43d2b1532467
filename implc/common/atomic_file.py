"""Writing a file (or a folder) without ever leaving a damaged one: write under a temporary name, then
rename.

:func:`replacing` yields a temporary path in the target's folder; when the block completes, the file is
flushed to disk and renamed over the target in one step (``os.replace``), so a reader, a crash, Ctrl-C
or SIGTERM sees either the old file or the whole new one. On any exception the temporary file is removed
and the target is untouched. :func:`replacing_folder` does the same for a folder (a Zarr store, a slice
stack): the old folder is moved aside, the new one renamed into place, then the old one removed. A folder
is replaced only where it is empty or one of implc's own outputs of the same kind (it holds the
:data:`MARKER` file naming that kind, or the caller recognises its layout): a user's folder that happens to
have the name is refused, and nothing in it is touched.
:func:`resumable_folder` builds a folder under the fixed name ``NAME.partial`` instead, kept when the
block fails after saving finished work in it, so that a later run can finish it.

The new file gets the mode a plain write would give it (the umask's), or the old file's mode when it
replaces one; an error while writing (a full disk) names the target; the renaming and its record in
:data:`COMPLETED` happen with SIGINT and SIGTERM held, so a signal that comes after it is seen after the
record (the CLI then reports the output complete, not a failure).
"""

from __future__ import annotations

import contextlib
import os
import shutil
import signal
import stat
import tempfile
import threading
from collections.abc import Callable
from pathlib import Path

MARKER = ".implc-output"
"""The file every folder output of implc holds, naming its kind ("zarr store", "viewer", "slices")."""

COMPLETED: list[Path] = []
"""Every target this process has put in place, in order (see the module's docstring)."""


def _umask() -> int:
    try:
        with open("/proc/self/status") as f:  # Linux: read without changing it (os.umask would, for a moment)
            for line in f:
                if line.startswith("Umask:"):
                    return int(line.split()[1], 8)
    except (OSError, ValueError):
        pass
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _mode_for(path: Path, folder: bool) -> int:
    """The mode a new file (or folder) at ``path`` gets: the existing one's, or the umask's."""
    try:
        return stat.S_IMODE(os.stat(path).st_mode)
    except OSError:
        return (0o777 if folder else 0o666) & ~_umask()


@contextlib.contextmanager
def _signals_held():
    """SIGINT and SIGTERM held for the block (in the main thread; elsewhere they go to it anyway)."""
    held = {signal.SIGINT, signal.SIGTERM}
    if threading.current_thread() is not threading.main_thread() or not hasattr(signal, "pthread_sigmask"):
        yield
        return
    previous = signal.pthread_sigmask(signal.SIG_BLOCK, held)
    try:
        yield
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, previous)


def _named(exc: OSError, path: Path) -> OSError:
    """``exc`` with the target's name where it names no file (ENOSPC, EIO while writing)."""
    if exc.filename is None and exc.strerror:
        return type(exc)(exc.errno, exc.strerror, str(path))
    return exc


def _put_in_place(tmp: Path, path: Path):
    with _signals_held():
        os.replace(tmp, path)
        COMPLETED.append(path)


@contextlib.contextmanager
def replacing(path):
    """``with replacing(path) as tmp: write(tmp)``: ``path`` gets the new content only if the block
    completes (where ``path`` is a symbolic link, its target does). The temporary name ends with the
    target's suffix in lower case (numpy and Pillow choose
    the format by it, and numpy appends ".npz" to a name that does not end so)."""
    path = Path(path)
    if path.is_symlink():  # the link's target gets the new content; the link stays a link
        path = Path(os.path.realpath(path))
    fd, name = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.",
                                suffix=f".part{path.suffix.lower()}")
    os.close(fd)
    tmp = Path(name)
    try:
        try:
            yield tmp
            with open(tmp, "rb+") as f:
                os.fsync(f.fileno())
            os.chmod(tmp, _mode_for(path, folder=False))
        except OSError as exc:
            raise _named(exc, path) from None
        _put_in_place(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


def _folder_in_place(new: Path, path: Path) -> None:
    """``new`` renamed to ``path``; an existing folder there moved aside first and removed after."""
    if path.exists():
        old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
        with _signals_held():  # the old folder aside and the new one in, as one step for a signal
            path.rename(old / path.name)
            _put_in_place(new, path)
        shutil.rmtree(old, ignore_errors=True)
    else:
        _put_in_place(new, path)


@contextlib.contextmanager
def _filled_into_place(folder: Path, path: Path, keep=None):
    """Yield ``folder``; when the block completes, give it the mode ``path`` would have and put it in
    place as ``path``. On failure it is removed, unless ``keep(folder)`` says it holds work to keep."""
    try:
        try:
            yield folder
            os.chmod(folder, _mode_for(path, folder=True))
        except OSError as exc:
            raise _named(exc, path) from None
        _folder_in_place(folder, path)
    except BaseException:
        if keep is None or not keep(folder):
            shutil.rmtree(folder, ignore_errors=True)
        raise


def mark(folder: Path, kind: str) -> None:
    """Mark ``folder`` as an implc output of ``kind`` (:data:`MARKER`)."""
    (Path(folder) / MARKER).write_text(kind + "\n")


def output_kind(folder: Path) -> str | None:
    """The kind of implc output ``folder`` is, by its :data:`MARKER` (None: not marked as one)."""
    try:
        with open(folder / MARKER, "rb") as f:
            return f.read(64).decode("ascii", errors="replace").strip() or None
    except OSError:
        return None


def _ours(folder: Path, kind: str, recognise: Callable[[Path], bool] | None) -> bool:
    """Whether ``folder`` is an implc output of ``kind``: marked so, or recognised by its layout."""
    return folder.is_dir() and not folder.is_symlink() and (
        output_kind(folder) == kind or (recognise is not None and recognise(folder)))


def check_replaceable(path: Path, kind: str, recognise: Callable[[Path], bool] | None = None) -> None:
    """Refuse (ValueError, one line) to replace ``path`` unless it is missing, an empty folder, or an implc
    output of ``kind`` (its marker, or ``recognise(path)`` for outputs written before markers)."""
    if not path.exists() and not path.is_symlink():
        return
    if not path.is_dir() or path.is_symlink():
        raise ValueError(f"{path} exists and is not a folder: implc writes a {kind} there only in place of "
                         f"its own (choose another name, or remove it first)")
    with os.scandir(path) as entries:
        if next(entries, None) is None:
            return
    if _ours(path, kind, recognise):
        return
    raise ValueError(f"{path} exists and is not an implc {kind}: implc replaces only its own outputs "
                     "(choose another name, or remove it first)")


@contextlib.contextmanager
def replacing_folder(path, kind: str, recognise: Callable[[Path], bool] | None = None, *, marked: bool = True):
    """``with replacing_folder(path, kind) as tmp: fill(tmp)``: a new folder beside ``path`` (marked as an
    implc output of ``kind`` unless not ``marked``: then ``recognise`` alone tells it later) that becomes
    ``path`` only if the block completes, replacing an existing folder only where :func:`check_replaceable`
    allows."""
    path = Path(path)
    check_replaceable(path, kind, recognise)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent))
    if marked:
        mark(tmp, kind)
    with _filled_into_place(tmp, path) as folder:
        yield folder


@contextlib.contextmanager
def resumable_folder(path, kind: str, *, resume: bool = False, matches=None, keep=None, recognise=None,
                     marked: bool = True):
    """``with resumable_folder(path, kind) as folder: fill(folder)``: the folder ``NAME.partial`` beside
    ``path``, marked as an implc output of ``kind``, renamed into place (replacing an existing folder where
    :func:`check_replaceable` allows) when the block completes. If the block fails where ``keep(folder)``
    says finished work was saved in it, it stays for a later ``resume=True``, which takes it up again where
    ``matches(folder)`` says it holds the same job; a run without ``resume`` refuses to start over it (its
    finished work is the user's to keep or remove). ``recognise`` and ``marked``: as for
    :func:`replacing_folder`."""
    path = Path(path)
    check_replaceable(path, kind, recognise)
    partial = path.with_name(path.name + ".partial")
    with contextlib.ExitStack() as held:
        if partial.is_dir() and not partial.is_symlink():
            held.enter_context(_locked(partial))  # a run writing it now has it locked: refused here
        if resume:
            if not partial.is_dir():
                raise ValueError(f"nothing to resume: {partial} does not exist (a run that stops early keeps it)")
            if not _ours(partial, kind, recognise):
                raise ValueError(f"{partial} is not an unfinished implc {kind}: nothing to resume there")
            if matches is not None and not matches(partial):
                raise ValueError(f"{partial} holds another run (another surface, depth or options): remove it to "
                                 "start over")
        elif partial.exists() or partial.is_symlink():
            if _ours(partial, kind, recognise):
                raise ValueError(f"{partial} holds an unfinished run: finish it with --resume (resume=True), or "
                                 "remove it to start over")
            raise ValueError(f"{partial} exists and is not implc's: implc keeps its unfinished runs there (choose "
                             "another name, or remove it first)")
        else:
            partial.mkdir(parents=True, exist_ok=True)
            held.enter_context(_locked(partial))
        if marked and output_kind(partial) is None:
            mark(partial, kind)
        with _filled_into_place(partial, path, keep) as folder:
            yield folder


@contextlib.contextmanager
def _locked(folder: Path):
    """``folder`` locked for this process (an advisory lock on the folder itself, which follows it when it
    is renamed into place): one writer at a time; ValueError at once where another holds it."""
    import fcntl
    fd = os.open(folder, os.O_RDONLY)
    try:
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            raise ValueError(f"another implc run is writing {folder} now: wait for it to finish, or stop it") \
                from None
        yield
    finally:
        os.close(fd)
