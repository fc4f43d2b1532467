"""The tape engine as the walk's driver sees it (:class:`implc.engines.walk.WalkEvaluator`)."""

from __future__ import annotations

import numpy as np

from ...native import abi
from ..walk import WalkEvaluator
from .program import slot_scratch


class TapeWalk(WalkEvaluator):
    """The tape engine over ``program`` (:mod:`implc.engines.tape.evaluator_native`): per worker, the words
    (:data:`implc.native.abi.TAPE_EVALUATOR_WORDS`) of a program and choices per level and the interpreter's
    scratch."""

    def __init__(self, surface, program, depth: int):
        self.walk = surface.tape_engine.subdivide
        self.program = program
        self.depth = depth  # the grid's (abi.TAPE_GRID_DEPTH)

    def worker_words(self) -> tuple[np.ndarray, tuple]:
        program = self.program
        n, slots = max(len(program), 1), program.slot_count
        buffers = (program.header,
                   np.empty(abi.WALK_LEVELS * n * abi.INSTRUCTION_WORDS, dtype=np.int32),  # untouched pages: free
                   np.empty(abi.WALK_LEVELS * n * 8, dtype=np.uint8),
                   slot_scratch(slots),
                   np.zeros(slots, dtype=np.int32),  # stamps (abi.TAPE_STAMP): zero is no call's
                   np.empty(n, dtype=np.uint8),
                   np.empty(slots, dtype=np.int32))
        words = np.zeros(abi.TAPE_EVALUATOR_WORDS, dtype=np.int64)
        words[abi.TAPE_HEADER: abi.TAPE_REMAP + 1] = [a.ctypes.data for a in buffers]
        words[abi.TAPE_GRID_DEPTH] = self.depth
        return words, buffers
