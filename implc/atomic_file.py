"""Writing a file (or a folder) without ever leaving a damaged one: write under a temporary name, then
rename.

:func:`replacing` yields a temporary path in the target's folder; when the block completes, the file is
flushed to disk and renamed over the target in one step (``os.replace``), so a reader, a crash, Ctrl-C
or SIGTERM sees either the old file or the whole new one. On any exception the temporary file is removed
and the target is untouched. :func:`replacing_folder` does the same for a folder (a Zarr store, a slice
stack): the old folder is moved aside, the new one renamed into place, then the old one removed.
"""

from __future__ import annotations

import contextlib
import os
import shutil
import tempfile
from pathlib import Path


@contextlib.contextmanager
def replacing(path):
    """``with replacing(path) as tmp: write(tmp)``: ``path`` gets the new content only if the block
    completes. The temporary name ends with the target's suffix in lower case (numpy and Pillow choose
    the format by it, and numpy appends ".npz" to a name that does not end so)."""
    path = Path(path)
    fd, name = tempfile.mkstemp(dir=path.parent if str(path.parent) else ".", prefix=f".{path.name}.",
                                suffix=f".part{path.suffix.lower()}")
    os.close(fd)
    tmp = Path(name)
    try:
        yield tmp
        with open(tmp, "rb+") as f:
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(OSError):
            tmp.unlink()
        raise


@contextlib.contextmanager
def replacing_folder(path):
    """``with replacing_folder(path) as tmp: fill(tmp)``: a new, empty folder beside ``path`` that
    becomes ``path`` (replacing an existing folder) only if the block completes."""
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise ValueError(f"{path} exists and is not a folder")
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent))
    try:
        yield tmp
        if path.exists():
            old = Path(tempfile.mkdtemp(prefix=f".{path.name}.", suffix=".old", dir=path.parent))
            path.rename(old / path.name)
            tmp.rename(path)
            shutil.rmtree(old, ignore_errors=True)
        else:
            tmp.rename(path)
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
