"""Writing a file without ever leaving a damaged one: write under a temporary name, then rename.

:func:`replacing` yields a temporary path in the target's folder; when the block completes, the file is
flushed to disk and renamed over the target in one step (``os.replace``), so a reader, a crash, Ctrl-C
or SIGTERM sees either the old file or the whole new one. On any exception the temporary file is removed
and the target is untouched.
"""

from __future__ import annotations

import contextlib
import os
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
