"""Settings that hold for a block of code: a context variable set on entry and reset on exit (so that
threads and nested blocks each see their own)."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from contextvars import ContextVar
from typing import TypeVar

T = TypeVar("T")


@contextlib.contextmanager
def scoped(variable: ContextVar[T], value: T) -> Iterator[None]:
    """Within the block, ``variable`` holds ``value``."""
    token = variable.set(value)
    try:
        yield
    finally:
        variable.reset(token)
