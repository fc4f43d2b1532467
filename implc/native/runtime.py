"""The process's native modules: each feature's module (the tape engine, the walk over compiled kernels,
the octree index, the contouring, ...) compiled once per process on first use, from the disk cache after
the first time, and those first needed together compiled at once.

A feature owns its native half: it declares a :class:`Library` (its :class:`~implc.native.jit.Source` and
the :mod:`implc.native.abi` entries bound from it) beside the code that emits it, and calls
``Runtime.shared().library(LIBRARY)``. The runtime knows no feature, so nothing here imports upward. The
modules are the same for every surface, so a process needs one runtime: :meth:`Runtime.shared` hands the
same one to every caller, which keeps its code alive for the life of the process.
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from . import abi
from .jit import NativeModule, Source


@dataclass(frozen=True)
class Library:
    """A feature's native module: what compiles it and the entry points bound from it."""

    source: Source
    entries: tuple[abi.Entry, ...]
    prefix: str = "implc_"
    """What the entries' names lose as the attributes of :class:`Routines`."""


class Routines:
    """A library's entry points, each an attribute named after its entry without the ``implc_`` prefix
    (``implc_octree_insert`` -> ``octree_insert``); ``native``: the module they live in."""

    def __init__(self, native: NativeModule, entries: Sequence[abi.Entry], prefix: str = "implc_"):
        self.native = native
        for entry in entries:
            setattr(self, entry.name.removeprefix(prefix), native.bind(entry))

    def __getattr__(self, name: str) -> Callable[..., Any]:  # reached only for a name no entry has
        raise AttributeError(f"no entry point {name!r} in the module {self.native.key!r}")


class Runtime:
    """The process's native modules, each compiled on first use (:meth:`modules`) and kept for the life of
    the process; :meth:`library` binds a feature's entry points."""

    _shared: Runtime | None = None
    _lock = threading.Lock()

    def __init__(self):
        self._modules: dict[str, NativeModule] = {}  # by source key
        self._routines: dict[str, Routines] = {}  # by source key

    def modules(self, *sources: Source, extra: Sequence[Source] = ()) -> list[NativeModule]:
        """The modules of ``sources`` (kept by this runtime, so built once) and then of ``extra`` (a
        surface's, returned only), those not built yet compiled at once (:meth:`NativeModule.together`)."""
        with self._lock:
            missing = list({s.key: s for s in sources if s.key not in self._modules}.values())
            built = NativeModule.together([*missing, *extra]) if missing or extra else []
            self._modules.update((s.key, m) for s, m in zip(missing, built))
            return [self._modules[s.key] for s in sources] + built[len(missing):]

    def library(self, library: Library, *also: Source) -> Routines:
        """``library``'s entry points, its module compiled on first use at once with the modules of ``also``
        (those a caller knows it needs next) where they are not built yet either."""
        key = library.source.key
        with self._lock:
            routines = self._routines.get(key)
        if routines is None:
            native = self.modules(library.source, *also)[0]
            with self._lock:
                routines = self._routines.setdefault(key, Routines(native, library.entries, library.prefix))
        return routines

    @classmethod
    def shared(cls) -> Runtime:
        """The process's runtime, built on first use (thread-safe)."""
        with cls._lock:
            if cls._shared is None:
                cls._shared = cls()
            return cls._shared
