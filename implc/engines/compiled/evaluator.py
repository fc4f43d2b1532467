"""The compiled kernels as the walk's driver sees them (:class:`implc.engines.walk.WalkEvaluator`)."""

from __future__ import annotations

import numpy as np

from ...native import abi
from ...native.runtime import Runtime
from ..walk import WalkEvaluator
from .evaluator_native import KERNEL_WALK


class KernelWalk(WalkEvaluator):
    """A surface's compiled kernels (:mod:`implc.engines.compiled.evaluator_native`): their addresses in the words
    (:data:`implc.native.abi.KERNEL_EVALUATOR_WORDS`), the same for every worker."""

    def __init__(self, surface, runtime: Runtime, mean_value_levels: int, fine_level: int, tightens: bool):
        self.walk = runtime.library(KERNEL_WALK).subdivide
        self.words = np.zeros(abi.KERNEL_EVALUATOR_WORDS, dtype=np.int64)
        box = surface.kernel_address(abi.OCTANT)
        self.words[:abi.KERNEL_MASKS] = (
            box, surface.kernel_address(abi.OCTANT_MVF) if mean_value_levels > 0 else box, fine_level,
            surface.kernel_address(abi.GRADIENT_LIVE), surface.kernel_address(abi.POINT_FAST),
            surface.kernel_address(abi.BOUND_MONOTONE) if tightens else 0)

    def worker_words(self) -> tuple[np.ndarray, tuple]:
        return self.words.copy(), ()
