"""Pruned point gradients: F and ∇F at W points, with the terms dead around them left out.

Normals are computed at voxel centres, and each voxel comes with the live-term mask of its cell
(:mod:`implc.engines.compiled.plan`). A dead term is exactly 0 (a blend's zero branch) or never the extremum (a Min/Max
leaf) over the whole cell, so it adds nothing to F or ∇F anywhere in it: folding over the live terms
only gives the gradient of the full tape there, for the price of the one to three blobs or spheres near a
voxel instead of all of them.

Each term, and each non-term operand of the chain, is evaluated as a dual number (value, ∂x, ∂y, ∂z) by
the point emitter on its own gradient tape (:func:`implc.compiler.gradient.with_gradient` of
:meth:`implc.compiler.ir.Tape.subtape`); the chain's own ops combine dual numbers by :data:`DUAL_RULES`, which
mirror the derivative rules of :mod:`implc.compiler.gradient` for neg, scale, add, sub, min and max.
"""

from __future__ import annotations

from ...compiler.gradient import with_gradient
from ...compiler.llvm.point import emit_point
from ...compiler.llvm.vector import VectorBuilder
from .fold_native import IDENTITY, fold_live_terms


def _neg(vb, a, attr):
    return vb.neg(a[0]), [vb.neg(d) for d in a[1]]


def _scale(vb, a, attr):
    k = vb.splat(attr)
    return vb.mul(k, a[0]), [vb.mul(k, d) for d in a[1]]


def _add(vb, a, b, attr):
    return vb.add(a[0], b[0]), [vb.add(p, q) for p, q in zip(a[1], b[1])]


def _sub(vb, a, b, attr):
    return vb.sub(a[0], b[0]), [vb.sub(p, q) for p, q in zip(a[1], b[1])]


def _first_is_min(vb, a, b):
    return vb.cmp("<=", vb.sub(a[0], b[0]), vb.splat(0.0))


def _min(vb, a, b, attr):
    first = _first_is_min(vb, a, b)
    return vb.minimum(a[0], b[0]), [vb.select(first, p, q) for p, q in zip(a[1], b[1])]


def _max(vb, a, b, attr):
    first = _first_is_min(vb, a, b)
    return vb.maximum(a[0], b[0]), [vb.select(first, q, p) for p, q in zip(a[1], b[1])]


DUAL_RULES = {"neg": _neg, "scale": _scale, "add": _add, "sub": _sub, "min": _min, "max": _max}
"""Dual-number rules for the ops a fold's chain is made of: (vb, *operands, attr) -> (value, [∂x, ∂y, ∂z])."""


def emit_pruned_gradient(vb: VectorBuilder, tape, plan, coords, live_mask):
    """F and ∇F at points ``coords`` over the live terms of ``plan.fold`` (``live_mask``: an i64 for all
    W points). Returns (value, [∂x, ∂y, ∂z]) vectors."""

    def dual(root, xyz):  # flat: [value, ∂x, ∂y, ∂z]
        return emit_point(vb, with_gradient(tape.subtape(root)), xyz)

    def combine(node, operands):
        op, _, attr = tape.nodes[node]
        value, grad = DUAL_RULES[op](vb, *[(o[0], o[1:]) for o in operands], attr)
        return [value, *grad]

    none = IDENTITY[plan.fold.op]
    identity = [vb.splat(none)] + [vb.splat(0.0)] * 3
    result = fold_live_terms(vb, tape, plan, live_mask, coords, dual, combine, identity)
    return result[0], result[1:]
