"""Signals while a command runs: SIGINT and SIGTERM raised where they land (KeyboardInterrupt, Terminated),
except in callbacks whose exceptions Python drops (sent again a moment later) and once the outcome is
decided (then only noted), so that the command ends with one line and status 130 or 143."""

from __future__ import annotations

import os
import threading


class Terminated(BaseException):
    """SIGTERM, raised in the main thread so that cleanup (temporary files, worker threads) runs."""


signalled: list[int] = []
"""The signals main() saw: an import that an interrupt broke (numpy wraps it in an ImportError) is then
reported as the interrupt, not as a broken installation."""


settled = False
"""True once main()'s outcome is decided: a signal then is only noted (raised there, it would escape main()
as a traceback). A plain global, set by one store that runs no Python code, so no signal handler can run
half-way through setting it (a CI run's SIGINT once landed inside threading.Event.set)."""


REDELIVER_SECONDS = 0.01
"""How soon a signal that landed in a callback is sent again (:func:`_deliver`)."""


def on_sigterm(signum, frame):
    _deliver(signum, frame, Terminated)


def on_sigint(signum, frame):
    _deliver(signum, frame, KeyboardInterrupt)


def _deliver(signum, frame, exception: type[BaseException]) -> None:
    """Raise ``exception`` where the signal landed, unless the outcome is decided (:data:`settled`: only
    noted) or it landed in a callback whose exceptions Python prints and drops (:func:`_in_a_callback`):
    raised there, it would be lost, printed as a traceback, and the command would go on. Then the signal
    is sent again a moment later, once the callback is done (a CI run's SIGTERM landed in an import lock's
    weakref callback)."""
    if not settled and _in_a_callback(frame):
        timer = threading.Timer(REDELIVER_SECONDS, os.kill, (os.getpid(), signum))
        timer.daemon = True
        timer.start()
        return
    signalled.append(signum)
    if not settled:
        raise exception


def _in_a_callback(frame) -> bool:
    """Whether a frame on the stack runs a callback whose exceptions Python prints and drops instead of
    raising them: a finalizer (``__del__``) or importlib's module-lock weakref callback."""
    while frame is not None:
        code = frame.f_code
        if code.co_name == "__del__" or (code.co_name == "cb" and code.co_filename.startswith("<frozen importlib")):
            return True
        frame = frame.f_back
    return False
