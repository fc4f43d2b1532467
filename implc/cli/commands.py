"""The ``implc`` command's entry point: parse, run the command (:mod:`.outputs`, :mod:`.viewing`,
:mod:`.upkeep`), and report its outcome.

Every failure the user can cause (a missing or broken scene or file, a bad formula, option or value, an
unwritable output) ends with one line on stderr and exit status 2, and creates or damages no file (every
output is written under a temporary name and renamed into place). Ctrl-C ends with status 130 and
SIGTERM with 143, at any moment, imports included (:mod:`.signals`): the command's modules import only
the standard library at load time, and the rest of implc inside the commands.
"""

from __future__ import annotations

import signal
import sys
import threading
import typing
from pathlib import Path

from . import signals
from .arguments import (
    UsageError,
    tightness_of,
)
from .parser import attach_negative_values, build_parser, check_no_empty_values
from .signals import Terminated, on_sigint, on_sigterm, signalled
from .upkeep import cmd_bench

MESSAGE_LIMIT = 300
"""Longest error message printed (a 10,000-character formula is not repeated in full)."""



def _run(argv) -> int:
    if argv[:1] == ["bench"]:  # the suite parses its own options
        return cmd_bench(argv[1:])
    parser = build_parser()
    args = parser.parse_args(attach_negative_values(argv))
    if hasattr(args, "tightness"):
        args.tightness = tightness_of(args)
    check_no_empty_values(parser, args)
    global _output
    _output = getattr(args, "output", None) or getattr(args, "export", None)
    return args.run(args)


_output: str | None = None
"""The file or folder the running command writes last (None for commands that write none or several)."""


def _output_complete(done_before: int) -> str | None:
    """The command's output if it was put in place during this run (a signal came after that)."""
    atomic_file = sys.modules.get("implc.common.atomic_file")  # not imported: nothing was written
    if _output is None or atomic_file is None:
        return None
    done = atomic_file.COMPLETED[done_before:]
    return _output if any(Path(p) == Path(_output) for p in done) else None


def main(argv=None, *, restore_handlers: bool = True) -> int:
    """Run one command line; returns its exit status. ``python -m implc`` passes ``restore_handlers=False``:
    the process ends right after, and with main()'s handlers still in place a signal that lands then is
    noted, not raised as a traceback on the way out."""
    argv = sys.argv[1:] if argv is None else list(argv)
    in_main_thread = threading.current_thread() is threading.main_thread()
    signals.settled = False
    signalled.clear()
    atomic_file = sys.modules.get("implc.common.atomic_file")
    done_before = len(atomic_file.COMPLETED) if atomic_file else 0
    previous: dict[signal.Signals, typing.Any] = {}
    try:
        if in_main_thread:
            previous[signal.SIGTERM] = signal.signal(signal.SIGTERM, on_sigterm)
            previous[signal.SIGINT] = signal.signal(signal.SIGINT, on_sigint)
        return _outcome(argv, done_before)
    except (KeyboardInterrupt, Terminated) as exc:  # the signal came while an outcome was being reported
        return _interrupted(exc, done_before)
    finally:
        signals.settled = True  # first: the handlers below run with the outcome decided
        if restore_handlers:
            for signum, handler in previous.items():
                signal.signal(signum, handler)


def _outcome(argv, done_before: int) -> int:
    """Run the command; an error is one line on stderr and exit status 2, a signal 130 (SIGINT) or 143."""
    try:
        return _run(argv)
    except (UsageError, ValueError, MemoryError, OSError, RecursionError) as exc:
        # ValueError covers CompileError, SceneError, VoxelFileError and the API's own checks
        message = " ".join(str(exc).split()) or type(exc).__name__
        if isinstance(exc, RecursionError):
            message = "the input is nested too deeply"
        elif isinstance(exc, OSError) and exc.filename and exc.strerror:
            message = f"{exc.filename}: {exc.strerror}"
        elif isinstance(exc, OSError) and exc.strerror:  # no file named: the terminal or a pipe
            written = _output_complete(done_before)
            message = (f"{written} was written in full, but standard output failed: {exc.strerror}" if written
                       else f"standard output or error failed: {exc.strerror}")
        if len(message) > MESSAGE_LIMIT:
            message = message[: MESSAGE_LIMIT - 3] + "..."
        print(f"implc: error: {message}", file=sys.stderr)
        return 2
    except ImportError:
        if not signalled:
            raise
        # a signal during an import, wrapped by the importer
        terminated = signalled[0] == signal.SIGTERM
        print(f"implc: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return 143 if terminated else 130
    except (KeyboardInterrupt, Terminated) as exc:
        return _interrupted(exc, done_before)


def _interrupted(exc: BaseException, done_before: int) -> int:
    """The exit status after a signal: 0 where the output was written in full first, else 130 or 143."""
    complete = _output_complete(done_before)
    if complete is not None:  # the save finished first: the output is whole, the command succeeded
        print(f"implc: {complete} was written in full before the signal", file=sys.stderr)
        return 0
    print(f"implc: {'interrupted' if isinstance(exc, KeyboardInterrupt) else 'terminated'}", file=sys.stderr)
    return 130 if isinstance(exc, KeyboardInterrupt) else 143


def console() -> int:
    """The ``implc`` script: main() for a process that ends when it returns."""
    return main(restore_handlers=False)


if __name__ == "__main__":
    sys.exit(console())
