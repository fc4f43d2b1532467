"""A surface's compiled kernels as an evaluator of the walk (:mod:`implc.engines.walk_native`): ``implc_subdivide``.

Enclosing an octant's children calls the surface's octant kernel (``implc_octant``: the eight children
generated and enclosed in vector registers; from a given child level on a second, finer one, e.g. the
mean-value form's) through a function pointer, with the octant's live-term mask; it returns each child's
mask, which becomes the child's context as the walk enters it (all ones where pruning is off), and each
voxel keeps its own (``out_masks``). The normals come from the surface's gradient kernel over each block's
live terms (:mod:`implc.engines.normals_native`), the second look from its monotonicity bound
(:mod:`implc.engines.compiled.tighten_native`). The evaluator's words are
:data:`implc.native.abi.KERNEL_EVALUATOR_WORDS`.
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import I32, I64, at, const, load_at, local_array, store_at
from ...native import abi
from ...native.jit import Source
from ...native.runtime import Library
from ..normals_native import emit_normals
from ..walk_native import Evaluator, Walk, emit_walk
from .tighten_native import emit_tighten

I8 = ir.IntType(8)
_P = ir.PointerType


class KernelEvaluator(Evaluator):
    """The walk's evaluator over a surface's compiled kernels, called through the addresses in its words."""

    def __init__(self, normals: ir.Function, tighten: ir.Function):
        self.normals_fn, self.tighten = normals, tighten

    def begin(self, walk: Walk) -> None:
        b, words = walk.b, walk.evaluator
        self.words = words
        octant_type = _P(abi.OCTANT.llvm_type())
        self.box = b.inttoptr(load_at(b, words, abi.KERNEL_OCTANT), octant_type)
        self.fine = b.inttoptr(load_at(b, words, abi.KERNEL_FINE_OCTANT), octant_type)
        self.fine_level = load_at(b, words, abi.KERNEL_FINE_LEVEL)
        self.gradient = b.inttoptr(load_at(b, words, abi.KERNEL_GRADIENT), _P(I8))
        self.point = b.inttoptr(load_at(b, words, abi.KERNEL_POINT), _P(I8))
        self.bound = b.inttoptr(load_at(b, words, abi.KERNEL_BOUND), _P(I8))
        self.sub_cell = local_array(b, I32, 3, "sub_cell")

    def mask_at(self, b, level):
        return at(b, self.words, b.add(level, const(I64, abi.KERNEL_MASKS)))

    def child_masks(self, b, level):
        """The eight children's masks the octant kernel wrote at ``level``."""
        return at(b, self.words, b.add(b.mul(level, const(I64, 8)), const(I64, abi.KERNEL_MASKS + abi.WALK_LEVELS)))

    def child_mask(self, walk: Walk, level, c):
        """Child ``c``'s live-term mask (all ones where pruning is off)."""
        b = walk.b
        return b.select(walk.pruning, b.load(b.gep(self.child_masks(b, level), [b.zext(c, I64)])), const(I64, -1))

    def kernel(self, b, level):
        """The octant kernel for the children of an octant at ``level``."""
        return b.select(b.icmp_signed(">=", b.add(level, const(I64, 1)), self.fine_level), self.fine, self.box)

    def start(self, walk: Walk, level, cell) -> None:
        walk.b.store(const(I64, -1), self.mask_at(walk.b, level))  # every term live at a task's root

    def enclose(self, walk: Walk, level, cell):
        b = walk.b
        parent_mask = b.select(walk.pruning, b.load(self.mask_at(b, level)), const(I64, -1))
        decided = b.call(self.kernel(b, level), [walk.geom, walk.frame(level, 0), b.add(level, const(I64, 1)),
                                                 parent_mask, self.child_masks(b, level)])
        kept = b.and_(decided, const(I32, 0xFF))
        below = b.and_(b.lshr(decided, const(I32, abi.OCTANT_INSIDE_SHIFT)), const(I32, 0xFF))
        return kept, below, const(I32, 0xFF)

    def refine(self, walk: Walk, level, c, leaf):
        b = walk.b
        for a in range(3):
            store_at(b, leaf[a], self.sub_cell, a)
        sub_kept = b.call(self.kernel(b, level), [walk.geom, self.sub_cell, b.add(level, const(I64, 2)),
                                                  self.child_mask(walk, level, c), ir.Constant(_P(I64), None)])
        return b.icmp_unsigned("!=", b.and_(sub_kept, const(I32, 0xFF)), const(I32, 0))

    def enter(self, walk: Walk, level, c, decided) -> None:
        b = walk.b
        b.store(self.child_mask(walk, level, c), self.mask_at(b, b.add(level, const(I64, 1))))

    def leaf(self, walk: Walk, level, c, slot) -> None:
        store_at(walk.b, self.child_mask(walk, level, c), walk.out_masks, slot)

    def normals(self, walk: Walk, level, first, count) -> None:
        b = walk.b
        offset = b.mul(first, const(I64, 3))
        b.call(self.normals_fn, [self.gradient, self.point, walk.leaf_geom, b.gep(walk.out, [offset]),
                                 b.gep(walk.out_masks, [first]), count, b.gep(walk.out_normals, [offset]),
                                 walk.flags_from(first)])

    def second_look(self, walk: Walk, level, first, count) -> None:
        b = walk.b
        with b.if_then(b.icmp_unsigned("!=", self.bound, ir.Constant(self.bound.type, None))):
            b.call(self.tighten, [self.bound, self.point, walk.geom, walk.depth,
                                  b.gep(walk.out, [b.mul(first, const(I64, 3))]), b.gep(walk.out_masks, [first]),
                                  b.gep(walk.out_flags, [first]), count])


def emit_subdivide(module: ir.Module) -> ir.Function:
    """``implc_subdivide``: the walk over a surface's compiled kernels."""
    return emit_walk(module, abi.SUBDIVIDE, KernelEvaluator(emit_normals(module), emit_tighten(module)))


def build_kernel_walk() -> ir.Module:
    """The kernel-walk module."""
    module = ir.Module(name="implc_kernel_walk")
    emit_subdivide(module)
    return module


KERNEL_WALK = Library(Source(build_kernel_walk, "implc-kernel-walk", max_parts=2, weight=2.0), abi.KERNEL_WALK_ENTRIES)
"""The walk over compiled kernels: a process that only runs the tape engine never compiles it."""
