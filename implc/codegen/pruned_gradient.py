"""Pruned point gradients: F and ∇F at W points, with the terms dead around them left out.

Normals are computed at voxel centres, and each voxel comes with the live-term mask of its cell
(:mod:`implc.regions`). A dead term is exactly 0 (a blend's zero branch) or never the extremum (a Min/Max
leaf) over the whole cell, so it adds nothing to F or ∇F anywhere in it: folding over the live terms
only gives the gradient of the full tape there, for the price of the one to three blobs or spheres near a
voxel instead of all of them.

Each term, and each non-term operand of the chain, is evaluated as a dual number (value, ∂x, ∂y, ∂z) by
the point emitter on its own gradient tape (:func:`implc.gradient.with_gradient` of
:meth:`implc.ir.Tape.subtape`); the chain's own ops combine dual numbers by :data:`DUAL_RULES`, which
mirror the derivative rules of :mod:`implc.gradient` for neg, scale, add, sub, min and max.
"""

from __future__ import annotations

import math

from llvmlite import ir

from ..gradient import with_gradient
from .control import Local, for_set_bits
from .point import emit_point
from .vector import VectorBuilder


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
    b = vb.b
    fold = plan.fold

    def dual(root, xyz):
        value, *grad = emit_point(vb, with_gradient(tape.subtape(root)), xyz)
        return value, grad

    def combine(node, operands):
        op, _, attr = tape.nodes[node]
        return DUAL_RULES[op](vb, *operands, attr)

    none = {"sum": 0.0, "min": math.inf, "max": -math.inf}[fold.op]
    identity = (vb.splat(none), [vb.splat(0.0)] * 3)
    start = dual(fold.base, coords) if fold.base is not None else identity
    acc = [Local(b, vb.vtype, v) for v in (start[0], *start[1])]
    empty = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), int(fold.base is None)))
    reload = vb.reloadable(coords)
    count = len(plan.terms)
    live = b.and_(live_mask, ir.Constant(live_mask.type, (1 << count) - 1 if count < 64 else -1))
    with for_set_bits(b, live) as k:
        after = b.append_basic_block("fold.next")
        switch = b.switch(k, after)
        for step in fold.steps:
            case = b.append_basic_block(f"fold.term{step.term}")
            switch.add_case(ir.Constant(k.type, step.term), case)
            b.position_at_end(case)
            value = dual(plan.terms[step.term].root, reload())
            for w in step.wrappers:
                value = combine(w, [value])
            if step.node is None:
                new = value
            else:
                current = (acc[0].get(), [a.get() for a in acc[1:]])
                new = combine(step.node, [value, current] if step.term_left else [current, value])
                if fold.base is None:
                    is_empty = empty.get()
                    new = (b.select(is_empty, value[0], new[0]),
                           [b.select(is_empty, p, q) for p, q in zip(value[1], new[1])])
            for slot, v in zip(acc, (new[0], *new[1])):
                slot.set(v)
            empty.set(ir.Constant(ir.IntType(1), 0))
            b.branch(after)
        b.position_at_end(after)
    is_empty = empty.get()
    result = [b.select(is_empty, i, a.get()) for i, a in zip((identity[0], *identity[1]), acc)]
    result = (result[0], result[1:])
    previous = fold.top
    for node in fold.tail:  # above the fold: combine with the non-term operand
        _, args, _ = tape.nodes[node]
        result = combine(node, [result if a == previous else dual(a, coords) for a in args])
        previous = node
    return result
