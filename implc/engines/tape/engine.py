"""The tape engine's module for one rounding mode, shared by every surface the engine runs.

One interpreter for every program (:mod:`implc.engines.tape.engine_native`), so a surface compiles nothing of
its own: the module is compiled once per rounding mode and process, from the disk cache after the first time,
at once with the walk's rows (:data:`implc.engines.rows_native.ROWS`) that every voxelization uses.
"""

from __future__ import annotations

import functools

from ...native import abi
from ...native.jit import Source
from ...native.runtime import Library, Routines, Runtime
from ..rows_native import ROWS
from .engine_native import build_tape_engine

TAPE_ENGINE_OPT: int | str = "light"
"""LLVM's optimisation of the tape engine (:data:`implc.native.jit.LIGHT_PASSES`): its IR is written vectorised
and unrolled, so LLVM's pipelines find nothing to gain at run time and would spend most of a first compile
(``benchmarks/against_revision.py --task compile`` measures it)."""


@functools.cache
def tape_engine_library(directed: bool) -> Library:
    """The engine's module for one rounding mode; its entries are bound as ``interval``, ``gradient``,
    ``point``, ``subdivide``, ``box_gradient`` and ``grouped`` (signatures in :mod:`implc.native.abi`)."""
    source = Source(functools.partial(build_tape_engine, directed),
                    f"implc-tape-engine-{'directed' if directed else 'widened'}", TAPE_ENGINE_OPT, max_parts=4,
                    weight=6.0)
    return Library(source, abi.TAPE_ENTRIES, prefix="implc_tape_")


def tape_engine(directed: bool, runtime: Runtime | None = None) -> Routines:
    """The engine's entry points for one rounding mode, compiled on first use at once with the walk's rows."""
    return (runtime or Runtime.shared()).library(tape_engine_library(directed), ROWS.source)
