"""The mean-value form: the natural enclosure intersected with F(c) + ∇F(B)·(B − c), c the box's centre."""

from __future__ import annotations

from .interval_rules import IntervalEmitter, emit_interval_outputs, whole_line_if_undefined
from .vector import VectorBuilder


def emit_mean_value(vb: VectorBuilder, value_tape, gradient_tape, lo_coords, hi_coords):
    """The natural enclosure intersected with the mean-value form F(c) + ∇F(B)·(B − c), c the centre.

    Mirrors :func:`implc.reference.eval_interval_mean_value`. The mean-value form is dropped wherever it
    is NaN: a gradient enclosure that is unbounded, undefined, or crosses a possible discontinuity.
    """
    natural, *grad = emit_interval_outputs(vb, gradient_tape, lo_coords, hi_coords)
    centre = box_centre(vb, lo_coords, hi_coords)
    at_centre = emit_interval_outputs(vb, value_tape, centre, centre)[0]
    return intersect_mean_value(vb, natural, at_centre, grad, lo_coords, hi_coords, centre)


def box_centre(vb: VectorBuilder, lo_coords, hi_coords):
    return [vb.mul(vb.add(lo, hi), vb.splat(0.5)) for lo, hi in zip(lo_coords, hi_coords)]


def intersect_mean_value(vb: VectorBuilder, natural, at_centre, grad, lo_coords, hi_coords, centre):
    """``natural`` ∩ (F(c) + Σₐ ∇ₐF(B)·(Bₐ − cₐ)) from the enclosures of F over the box, F at the centre
    and the three partials over the box; the form is dropped wherever it is NaN."""
    em = IntervalEmitter(vb)
    acc = at_centre
    for axis in range(3):
        offset = (vb.sub_down(lo_coords[axis], centre[axis]), vb.sub_up(hi_coords[axis], centre[axis]))
        acc = em.i_add([acc, em.i_mul([grad[axis], offset], None)], None)
    usable = vb.and_(vb.cmp("==", acc[0], acc[0]), vb.cmp("==", acc[1], acc[1]))  # not NaN
    lo = vb.select(usable, vb.maximum(natural[0], acc[0]), natural[0])
    hi = vb.select(usable, vb.minimum(natural[1], acc[1]), natural[1])
    return whole_line_if_undefined(vb, lo, hi)
