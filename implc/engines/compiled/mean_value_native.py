"""The mean-value form, the natural enclosure intersected with F(c) + ∇F(B)·(B − c), c the box's centre;
and the monotonicity form, its one-sided refinement: along each axis where ∂F/∂xₐ excludes 0 over the box,
F's extremes lie on the box's faces, so each bound is taken at the corner where F is least (or greatest)
along those axes, and the mean-value term is kept for the other axes only."""

from __future__ import annotations

from ...compiler.llvm.interval_rules import IntervalEmitter, emit_interval_outputs, whole_line_if_undefined
from ...compiler.llvm.vector import VectorBuilder


def emit_mean_value(vb: VectorBuilder, value_tape, gradient_tape, lo_coords, hi_coords):
    """The natural enclosure intersected with the mean-value form F(c) + ∇F(B)·(B − c), c the centre.

    Mirrors :func:`implc.compiler.reference.eval_interval_mean_value`. The mean-value form is dropped wherever it
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


def emit_monotone_form(vb: VectorBuilder, value_tape, gradient_tape, lo_coords, hi_coords):
    """The natural enclosure intersected with the monotonicity form (mirrors
    :func:`implc.compiler.reference.eval_interval_monotone`)."""
    natural, *grad = emit_interval_outputs(vb, gradient_tape, lo_coords, hi_coords)
    return intersect_monotone(vb, natural, grad, lo_coords, hi_coords,
                              lambda point: emit_interval_outputs(vb, value_tape, point, point)[0])


def emit_monotone_bound(vb: VectorBuilder, value_tape, gradient_tape, lo_coords, hi_coords, above):
    """One bound of the monotonicity form: the lower where the lane mask ``above`` is set, else the upper
    (NaN where the form is undefined); the same value as that bound of :func:`emit_monotone_form`'s form,
    for one evaluation of F instead of two."""
    grad = emit_interval_outputs(vb, gradient_tape, lo_coords, hi_coords)[1:]
    return monotone_bound(vb, grad, lo_coords, hi_coords, above,
                          lambda point: emit_interval_outputs(vb, value_tape, point, point)[0])


def _monotone_parts(vb: VectorBuilder, grad, lo_coords, hi_coords):
    """Per axis: the coordinate of c⁻ and of c⁺, and the axis's term of the lower and of the upper bound.
    Where ∇ₐF(B) ≥ 0, c⁻ₐ is the box's low face and c⁺ₐ its high face (the other way round where
    ∇ₐF(B) ≤ 0) and the axis adds nothing: F grows away from c⁻ along it (mean value theorem, the
    gradient's sign known on the whole box); elsewhere both are the centre and the axis adds
    ∇ₐF(B)·(Bₐ − cₐ). A partial that is NaN or unbounded makes its terms NaN: the form needs F Lipschitz
    on the box (a finite gradient enclosure), which a pole inside it is not."""
    em = IntervalEmitter(vb)
    centre = box_centre(vb, lo_coords, hi_coords)
    zero, nan, inf = vb.splat(0.0), vb.splat(float("nan")), vb.splat(float("inf"))
    parts = []
    for axis in range(3):
        g_lo, g_hi = grad[axis]
        rising, falling = vb.cmp(">=", g_lo, zero), vb.cmp("<=", g_hi, zero)
        monotone = vb.or_(rising, falling)
        bounded = vb.and_(vb.cmp("<", vb.fabs(g_lo), inf), vb.cmp("<", vb.fabs(g_hi), inf))  # false for NaN
        least = vb.select(rising, lo_coords[axis], vb.select(falling, hi_coords[axis], centre[axis]))
        most = vb.select(rising, hi_coords[axis], vb.select(falling, lo_coords[axis], centre[axis]))
        offset = (vb.sub_down(lo_coords[axis], centre[axis]), vb.sub_up(hi_coords[axis], centre[axis]))
        term_lo, term_hi = em.i_mul([grad[axis], offset], None)
        lower = vb.select(bounded, vb.select(monotone, zero, term_lo), nan)
        upper = vb.select(bounded, vb.select(monotone, zero, term_hi), nan)
        parts.append((least, most, lower, upper))
    return parts


def intersect_monotone(vb: VectorBuilder, natural, grad, lo_coords, hi_coords, value_at):
    """``natural`` ∩ [F(c⁻) + Σ lowₐ, F(c⁺) + Σ highₐ] (:func:`_monotone_parts`); ``value_at(point)``: F's
    enclosure at a point (three vectors). Dropped wherever it is NaN, as the mean-value form."""
    parts = _monotone_parts(vb, grad, lo_coords, hi_coords)
    lo, hi = value_at([p[0] for p in parts])[0], value_at([p[1] for p in parts])[1]
    for _, _, lower, upper in parts:
        lo, hi = vb.add_down(lo, lower), vb.add_up(hi, upper)
    usable = vb.and_(vb.cmp("==", lo, lo), vb.cmp("==", hi, hi))  # not NaN
    out_lo = vb.select(usable, vb.maximum(natural[0], lo), natural[0])
    out_hi = vb.select(usable, vb.minimum(natural[1], hi), natural[1])
    return whole_line_if_undefined(vb, out_lo, out_hi)


def monotone_bound(vb: VectorBuilder, grad, lo_coords, hi_coords, above, value_at):
    """F(c⁻) + Σ lowₐ where ``above``, else F(c⁺) + Σ highₐ: the bound of :func:`intersect_monotone`'s
    form on that side, F evaluated once (at the corner that side needs)."""
    parts = _monotone_parts(vb, grad, lo_coords, hi_coords)
    f_lo, f_hi = value_at([vb.select(above, least, most) for least, most, _, _ in parts])
    bound = vb.select(above, f_lo, f_hi)
    for _, _, lower, upper in parts:
        bound = vb.select(above, vb.add_down(bound, lower), vb.add_up(bound, upper))
    return bound
