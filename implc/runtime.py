"""The generic native routines (subdivision, normals, octree, splatting) as callable ctypes functions.

A :class:`Runtime` owns the JIT-compiled runtime module (see :mod:`implc.codegen.runtime`); like surface
kernels it is cached on disk, so creating one costs a few milliseconds after the first time.
"""

from __future__ import annotations

import ctypes

from .codegen.runtime import build_runtime
from .jit import NativeModule

_P = ctypes.c_void_p
_N = ctypes.c_int64


class Runtime:
    def __init__(self):
        self.native = NativeModule(build_runtime, source_key="implc-runtime")
        fn = self.native.function
        self.subdivide = fn("implc_subdivide", [_P, _P, _N, _N, _N, _P, _P, _P, _P, _P, _P, _N, _P, _P], _N)
        self.normals = fn("implc_normals", [_P, _P, _P, _P, _P, _N, _P])
        self.octree_insert = fn("implc_octree_insert", [_P, _N, _P, _P, _N, _N], _N)
        self.octree_traverse = fn("implc_octree_traverse", [_P, _N, _N, _P, _P], _N)
        self.splat = fn("implc_splat", [_P, _P, _P, _P, _N, _N, _P, _P])
