"""The mean-value form over the live terms: the tightest enclosure, for the price of the terms near a box.

Where a tape's chain is a fold over terms (:class:`implc.engines.compiled.plan.Fold`), F equals the fold over the terms
live in a box's parent at every point of the box (a dead term is 0 there, or never the extremum), so the
mean-value form F(c) + ∇F(B)·(B − c) may be taken of that smaller function: its value at the centre and
its natural enclosure come from the pruned interval fold
(:func:`implc.engines.compiled.interval_native.emit_interval_regions`,
which also gives each box its own live mask), and ∇F(B) from a fold over the live terms of interval dual
numbers (value and three partials, each an interval): each term's on its own gradient tape
(:func:`implc.compiler.gradient.with_gradient` of :meth:`implc.compiler.ir.Tape.subtape`), combined by
:data:`DUAL_RULES`,
which mirror :mod:`implc.compiler.gradient`'s rules for neg, scale, add, sub, min and max in interval arithmetic.
"""

from __future__ import annotations

from ...compiler.gradient import with_gradient
from ...compiler.llvm.interval_rules import IntervalEmitter, emit_interval_outputs
from ...compiler.llvm.vector import VectorBuilder
from .fold_native import IDENTITY, fold_live_terms
from .interval_native import emit_interval_regions
from .mean_value_native import box_centre, intersect_mean_value, intersect_monotone, monotone_bound


def _pairs(flat):
    return [(flat[k], flat[k + 1]) for k in range(0, len(flat), 2)]


def _flat(pairs):
    return [v for pair in pairs for v in pair]


def _neg(em, a, attr):
    return [em.i_neg([p], None) for p in a]


def _scale(em, a, attr):
    return [em.i_scale([p], attr) for p in a]


def _add(em, a, b, attr):
    return [em.i_add([a[0], b[0]], attr)] + [em.i_add([p, q], False) for p, q in zip(a[1:], b[1:])]


def _sub(em, a, b, attr):
    return [em.i_sub([p, q], None) for p, q in zip(a, b)]


def _min(em, a, b, attr):  # d min(a, b) = select_le(a − b, da, db), as implc.compiler.gradient writes it
    difference = em.i_sub([a[0], b[0]], None)
    return [em.i_min([a[0], b[0]], None)] + [em.i_select_le([difference, p, q], None) for p, q in zip(a[1:], b[1:])]


def _max(em, a, b, attr):  # d max(a, b) = select_le(a − b, db, da)
    difference = em.i_sub([a[0], b[0]], None)
    return [em.i_max([a[0], b[0]], None)] + [em.i_select_le([difference, q, p], None) for p, q in zip(a[1:], b[1:])]


DUAL_RULES = {"neg": _neg, "scale": _scale, "add": _add, "sub": _sub, "min": _min, "max": _max}
"""Interval dual-number rules for a fold's chain ops: (emitter, *operands, attr) -> [value, ∂x, ∂y, ∂z],
each an interval (lo, hi)."""


def emit_pruned_mean_value(vb: VectorBuilder, tape, plan, lo_coords, hi_coords, live_mask):
    """(lo, hi, masks): the natural enclosure over the live terms intersected with their mean-value form,
    and each box's live mask (as :func:`implc.engines.compiled.interval_native.emit_interval_regions`)."""
    nat_lo, nat_hi, masks = emit_interval_regions(vb, tape, plan, lo_coords, hi_coords, live_mask)
    centre = box_centre(vb, lo_coords, hi_coords)
    c_lo, c_hi, _ = emit_interval_regions(vb, tape, plan, centre, centre, live_mask)
    grad = _live_gradient(vb, tape, plan, lo_coords, hi_coords, live_mask)
    lo, hi = intersect_mean_value(vb, (nat_lo, nat_hi), (c_lo, c_hi), grad, lo_coords, hi_coords, centre)
    return lo, hi, masks


def emit_pruned_monotone_form(vb: VectorBuilder, tape, plan, lo_coords, hi_coords, live_mask):
    """(lo, hi, masks): the natural enclosure over the live terms intersected with their monotonicity
    form (:func:`implc.engines.compiled.mean_value_native.intersect_monotone`), and each box's live mask."""
    nat_lo, nat_hi, masks = emit_interval_regions(vb, tape, plan, lo_coords, hi_coords, live_mask)
    grad = _live_gradient(vb, tape, plan, lo_coords, hi_coords, live_mask)
    lo, hi = intersect_monotone(vb, (nat_lo, nat_hi), grad, lo_coords, hi_coords,
                                _live_value_at(vb, tape, plan, live_mask))
    return lo, hi, masks


def emit_pruned_monotone_bound(vb: VectorBuilder, tape, plan, lo_coords, hi_coords, live_mask, above):
    """One bound of the monotonicity form over the live terms
    (:func:`implc.engines.compiled.mean_value_native.monotone_bound`)."""
    grad = _live_gradient(vb, tape, plan, lo_coords, hi_coords, live_mask)
    return monotone_bound(vb, grad, lo_coords, hi_coords, above, _live_value_at(vb, tape, plan, live_mask))


def _live_value_at(vb: VectorBuilder, tape, plan, live_mask):
    """F's enclosure at a point over the live terms (for the monotonicity form's corners)."""
    return lambda point: emit_interval_regions(vb, tape, plan, point, point, live_mask)[:2]


def _live_gradient(vb: VectorBuilder, tape, plan, lo_coords, hi_coords, live_mask):
    """∇F over the boxes from the fold of the live terms' interval dual numbers: three (lo, hi)."""
    em = IntervalEmitter(vb)

    def dual(root, corners):  # corners: [*lo, *hi]; flat: [value lo, value hi, ∂x lo, ∂x hi, ...]
        return _flat(emit_interval_outputs(vb, with_gradient(tape.subtape(root)), corners[:3], corners[3:]))

    def combine(node, operands):
        op, _, attr = tape.nodes[node]
        return _flat(DUAL_RULES[op](em, *[_pairs(o) for o in operands], attr))

    none = IDENTITY[plan.fold.op]
    identity = [vb.splat(none)] * 2 + [vb.splat(0.0)] * 6
    result = fold_live_terms(vb, tape, plan, live_mask, [*lo_coords, *hi_coords], dual, combine, identity)
    return _pairs(result)[1:]
