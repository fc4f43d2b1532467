"""``tape_tighten``: the tape engine's second look at the leaves the normals flag, below each leaf.

The normals pass flags the kept leaves whose cell the linear model at their centre misses, with the side
F(c) lies on (:mod:`implc.engines.normals_native`). This pass tries to prove F on that side over each flagged
leaf's whole box with the program of the leaves' octant (simplified by every choice decided above it),
and marks the proven ones for ``implc_drop_marked`` to drop; the control (batches, the order of the
tests, the split) is :func:`implc.engines.second_look_native.emit_second_look`'s. The proof over a box, eight boxes
at a time (:func:`emit_tape_tighten`'s ``prove``):

- the enclosure of F over the box (``tape_box_gradient``), with those of its three partials;
- the monotonicity test: along each axis where a partial's enclosure is finite and keeps its sign, F is
  least (greatest) on one face, so the box shrinks to that face (to a corner where all three keep their
  sign) and ``tape_interval`` encloses F there. Sound where F is continuous on the box: never used where
  F's enclosure is undefined (NaN) or a partial's is NaN or infinite (a pole, a possible jump).

A leaf the test leaves open with one or two axes free is proven over the face (edge) its partials give in
pieces (:func:`emit_tape_tighten`'s ``prove_face``); one still open is split
(:mod:`implc.engines.second_look_native`), each box below it tested first over the face its parent's partials'
signs give (they hold over the box, which lies in the parent's), with its own partials only where that
fails; unless F at one of its corners (``tape_point``, in floating point) already lies across 0, as in
:mod:`implc.engines.compiled.tighten_native`: the surface crosses it, and splitting it would only spend time (most of
the flagged leaves that stay, on the peer models). Boxes are the subdivider's at the
finer levels (origin + i·h, padded outward)."""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import I32, I64, Local, const, define_internal, if_, load_at, local_array
from ...compiler.llvm.vector import DOUBLE, VectorBuilder, broadcast
from ..second_look_native import LEVELS_BELOW, Look, emit_second_look
from .interpreter_native import LANES, V8

I8 = ir.IntType(8)
_P = ir.PointerType
_AXES = ir.Constant(_P(DOUBLE), None)  # tape_box_gradient's seeds: the partials along the axes


def emit_tape_tighten(module: ir.Module, interval: ir.Function, box_gradient: ir.Function, point: ir.Function,
                      directed: bool) -> ir.Function:
    """``tape_tighten(header, program, length, output, slots, choices, geom, depth, coords, flags, n)``
    (internal): the flagged ones (:data:`implc.native.abi.TIGHTEN_ABOVE`, :data:`implc.native.abi.TIGHTEN_BELOW`) of
    the ``n`` voxels at ``coords`` (int32 cells at ``depth``) get :data:`~implc.engines.second_look_native.OUTSIDE` or
    :data:`~implc.engines.second_look_native.INSIDE` where F is proven on their side over the whole cell; ``choices``:
    scratch for ``tape_interval``'s choices. ``point``: ``tape_point`` (F alone at eight points)."""
    fn, b = define_internal(module, "implc.tape.tighten", ir.VoidType(),
                            [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(I8), _P(DOUBLE), I64, _P(I32), _P(I8), I64])
    header, program, length, output, slots, choices, geom, depth, coords, flags, n = fn.args
    vb = VectorBuilder(b, LANES, directed)
    box = local_array(b, DOUBLE, 6 * LANES, "box")
    reduced = local_array(b, DOUBLE, 6 * LANES, "reduced")
    gradient = local_array(b, DOUBLE, 8 * LANES, "gradient")
    result = local_array(b, DOUBLE, 2 * LANES, "result")
    cells = local_array(b, DOUBLE, 3 * LANES, "cells")  # the boxes' cells (as doubles) at the level tested
    corners = local_array(b, DOUBLE, 3 * LANES, "corners")  # a leaf's eight corners, axis by axis
    sides = local_array(b, DOUBLE, LANES, "sides")  # the open leaf's side in every lane (+1: F > 0, -1: F < 0)
    vbox, vreduced, vgradient = (b.bitcast(p, _P(V8)) for p in (box, reduced, gradient))
    origin = [broadcast(b, load_at(b, geom, a), LANES) for a in range(3)]
    pad = [broadcast(b, load_at(b, geom, 3 + a), LANES) for a in range(3)]
    leaf_h = [load_at(b, geom, b.add(b.mul(depth, const(I64, 3)), const(I64, 6 + a))) for a in range(3)]
    zero, one, inf = vb.splat(0.0), vb.splat(1.0), vb.splat(float("inf"))

    held = local_array(b, DOUBLE, 6 * LANES, "held")  # the partials' signs the boxes inherit (1.0 or 0.0)
    # the signs each level's boxes showed, per lane: the first test's (the leaves') at 0, then the split's
    signs = local_array(b, DOUBLE, (LEVELS_BELOW + 1) * 6 * LANES, "signs")
    vheld, vsigns = b.bitcast(held, _P(V8)), b.bitcast(signs, _P(V8))

    def hold(level, lane):
        """``held`` from the signs box ``lane`` (an i64) of ``level`` (an i64) showed, for the boxes below it."""
        for k in range(6):
            index = b.add(b.mul(b.add(b.mul(level, const(I64, 6)), const(I64, k)), const(I64, LANES)), lane)
            b.store(broadcast(b, load_at(b, signs, index), LANES), b.gep(vheld, [const(I64, k)]), align=8)

    def held_signs():
        """The partials' signs in ``held``: (rising, falling), three i1 vectors each."""
        return ([vb.cmp(">", b.load(b.gep(vheld, [const(I64, a)]), align=8), zero) for a in range(3)],
                [vb.cmp(">", b.load(b.gep(vheld, [const(I64, 3 + a)]), align=8), zero) for a in range(3)])

    def enclose_reduced(side_above, rising, falling):
        """``tape_interval`` over the face (edge, corner) of each lane's box where F is least (above) or
        greatest (below) along the axes where it rises or falls (three i1 vectors each); returns (lo, hi)."""
        for a in range(3):
            to_lo = b.select(side_above, rising[a], falling[a])  # F least on the lo face where it rises
            to_hi = b.and_(b.not_(to_lo), b.select(side_above, falling[a], rising[a]))
            lo = b.load(b.gep(vbox, [const(I64, a)]), align=8)
            hi = b.load(b.gep(vbox, [const(I64, 3 + a)]), align=8)
            b.store(b.select(to_hi, hi, lo), b.gep(vreduced, [const(I64, a)]), align=8)
            b.store(b.select(to_lo, lo, hi), b.gep(vreduced, [const(I64, 3 + a)]), align=8)
        b.call(interval, [header, program, length, output, slots, choices, reduced, result])
        vresult = b.bitcast(result, _P(V8))
        return b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)

    def prove(factor, level=None, box_sides=None):
        """The lanes (i8 mask) whose box (cells at ``cells``, of the leaves' size times ``factor``) is
        proven on its side (``box_sides``, default ``sides``): by its enclosure, or by the enclosure over
        the face or corner its monotone axes give. ``level`` (an i64, 1 or more): how far below one leaf
        the boxes lie (None: the leaves' own): those are tested first over the face their parent's signs
        (``held``) give (the box itself where they give none), and only where that leaves a box open with
        their own partials too. The signs are kept in ``signs`` at ``level`` (0 for the leaves) for the
        boxes below."""
        first = level is None
        vcells = b.bitcast(cells, _P(V8))
        for a in range(3):
            h = broadcast(b, b.fmul(leaf_h[a], factor), LANES)
            i = b.load(b.gep(vcells, [const(I64, a)]), align=8)
            b.store(b.fsub(b.fadd(origin[a], b.fmul(i, h)), pad[a]), b.gep(vbox, [const(I64, a)]), align=8)
            b.store(b.fadd(b.fadd(origin[a], b.fmul(b.fadd(i, one), h)), pad[a]), b.gep(vbox, [const(I64, 3 + a)]),
                    align=8)
        side = b.load(b.bitcast(sides if box_sides is None else box_sides, _P(V8)), align=8)
        above = vb.cmp(">", side, zero)

        def on_side(lo, hi):
            return b.select(above, vb.cmp(">", lo, zero), vb.cmp("<", hi, zero))

        verdict = Local(b, I8, const(I8, 0), "verdict")
        if not first:
            verdict.set(b.bitcast(on_side(*enclose_reduced(above, *held_signs())), I8))
        with if_(b, b.icmp_unsigned("!=", verdict.get(), const(I8, 0xFF))):
            b.call(box_gradient, [header, program, length, output, slots, box, gradient, _AXES])
            f_lo, f_hi = (b.load(b.gep(vgradient, [const(I64, k)]), align=8) for k in range(2))
            defined = b.not_(b.or_(vb.isnan(f_lo), vb.isnan(f_hi)))
            proven = on_side(f_lo, f_hi)
            rising, falling = [], []
            for a in range(3):
                d_lo, d_hi = (b.load(b.gep(vgradient, [const(I64, 2 + 2 * a + k)]), align=8) for k in range(2))
                rising.append(b.and_(defined, b.and_(vb.cmp(">=", d_lo, zero), vb.cmp("<", d_hi, inf))))
                falling.append(b.and_(defined, b.and_(vb.cmp("<=", d_hi, zero), vb.cmp(">", d_lo, vb.neg(inf)))))
            if not first:  # a sign the parent's partial keeps, the box's keeps too (its box lies in the parent's)
                inherited_rising, inherited_falling = held_signs()
                rising = [b.or_(r, i) for r, i in zip(rising, inherited_rising)]
                falling = [b.or_(f, i) for f, i in zip(falling, inherited_falling)]
            row = b.mul(const(I64, 0) if first else level, const(I64, 6))
            for a in range(3):
                for k, mask in ((a, rising[a]), (3 + a, falling[a])):
                    b.store(b.select(mask, one, zero), b.gep(vsigns, [b.add(row, const(I64, k))]), align=8)
            proven = b.or_(proven, b.and_(defined, on_side(*enclose_reduced(above, rising, falling))))
            verdict.set(b.or_(verdict.get(), b.bitcast(proven, I8)))
        return verdict.get()

    lane_index = ir.Constant(V8, [float(j) for j in range(LANES)])
    quarter_low, quarter_high = (ir.Constant(V8, [float(j & 3) for j in range(LANES)]),
                                 ir.Constant(V8, [float(j >> 2) for j in range(LANES)]))

    def prove_face(leaf):
        """The face (edge) of the leaf at ``leaf`` (three double cells) where its partials' signs (``held``)
        put F's least (greatest) value, proven on the side in pieces: an edge in eight, a face in 4 x 4
        (two enclosures). Where F is monotone along an axis over the leaf, F on the leaf's side of the
        surface at every point of that face puts the whole leaf there; unlike the leaf's split, no piece is
        spent inside the leaf. Returns an i1: proven (never where the signs leave one axis or none free)."""
        side = b.load(b.bitcast(sides, _P(V8)), align=8)
        above = vb.cmp(">", side, zero)
        rising, falling = held_signs()
        to_lo = [b.select(above, rising[a], falling[a]) for a in range(3)]
        to_hi = [b.and_(b.not_(to_lo[a]), b.select(above, falling[a], rising[a])) for a in range(3)]
        free = [b.not_(b.or_(lo, hi)) for lo, hi in zip(to_lo, to_hi)]
        count = b.add(b.add(b.zext(free[0], ir.VectorType(I32, LANES)), b.zext(free[1], ir.VectorType(I32, LANES))),
                      b.zext(free[2], ir.VectorType(I32, LANES)))
        edge = b.icmp_unsigned("==", count, ir.Constant(ir.VectorType(I32, LANES), [1] * LANES))
        face = b.icmp_unsigned("==", count, ir.Constant(ir.VectorType(I32, LANES), [2] * LANES))
        proven = Local(b, ir.IntType(1), ir.Constant(ir.IntType(1), 0), "face.proven")
        with if_(b, b.extract_element(b.or_(edge, face), const(I32, 0))):
            proven.set(ir.Constant(ir.IntType(1), 1))
            for half in range(2):  # an edge needs the first enclosure only
                with if_(b, b.and_(proven.get(), b.or_(const(ir.IntType(1), half == 0),
                                                       b.extract_element(face, const(I32, 0))))):
                    seen = ir.Constant(ir.VectorType(ir.IntType(1), LANES), [0] * LANES)  # a free axis before
                    for a in range(3):
                        # pieces along axis a: 8 on an edge, 4 by 4 on a face, the whole leaf on a bound axis
                        pieces = b.select(edge, vb.splat(8.0), vb.splat(4.0))
                        piece = b.select(edge, lane_index,
                                         b.select(seen, b.fadd(quarter_high, vb.splat(2.0 * half)), quarter_low))
                        pieces = b.select(free[a], pieces, one)
                        piece = b.select(free[a], piece, zero)
                        seen = b.or_(seen, free[a])
                        h = broadcast(b, leaf_h[a], LANES)
                        cell = broadcast(b, leaf[a], LANES)
                        low = b.fsub(b.fadd(origin[a], b.fmul(cell, h)), pad[a])
                        high = b.fadd(b.fadd(origin[a], b.fmul(b.fadd(cell, one), h)), pad[a])
                        width = b.fsub(high, low)
                        # the pieces share their ends (same expression), the first starts at low, the last ends at high
                        start = b.select(vb.cmp("==", piece, zero), low,
                                         b.fadd(low, b.fmul(width, b.fdiv(piece, pieces))))
                        after = b.fadd(piece, one)
                        end = b.select(vb.cmp("==", after, pieces), high,
                                       b.fadd(low, b.fmul(width, b.fdiv(after, pieces))))
                        b.store(b.select(to_hi[a], high, start), b.gep(vreduced, [const(I64, a)]), align=8)
                        b.store(b.select(to_lo[a], low, end), b.gep(vreduced, [const(I64, 3 + a)]), align=8)
                    b.call(interval, [header, program, length, output, slots, choices, reduced, result])
                    vresult = b.bitcast(result, _P(V8))
                    lo, hi = b.load(vresult, align=8), b.load(b.gep(vresult, [const(I64, 1)]), align=8)
                    on = b.select(above, vb.cmp(">", lo, zero), vb.cmp("<", hi, zero))
                    proven.set(b.and_(proven.get(), b.icmp_unsigned("==", b.bitcast(on, I8), const(I8, 0xFF))))
        return proven.get()

    corner_bits = [ir.Constant(ir.VectorType(ir.IntType(1), LANES), [bool((c >> a) & 1) for c in range(LANES)])
                   for a in range(3)]

    def crossed(leaf, side):
        """Whether F at one of the leaf's corners (``tape_point``, in floating point) lies across 0 from
        ``side``: the surface crosses the leaf, which no test can drop (an i1)."""
        vcorners = b.bitcast(corners, _P(V8))
        for a in range(3):
            h = broadcast(b, leaf_h[a], LANES)
            low = b.fadd(origin[a], b.fmul(broadcast(b, leaf[a], LANES), h))
            high = b.fadd(origin[a], b.fmul(broadcast(b, b.fadd(leaf[a], const(DOUBLE, 1.0)), LANES), h))
            b.store(b.select(corner_bits[a], high, low), b.gep(vcorners, [const(I64, a)]), align=8)
        b.call(point, [header, program, length, output, slots, corners, result])
        values = b.load(b.bitcast(result, _P(V8)), align=8)
        above = b.fcmp_ordered(">", side, const(DOUBLE, 0.0))
        across = b.select(above, vb.cmp("<", values, zero), vb.cmp(">", values, zero))
        return b.icmp_unsigned("!=", b.bitcast(across, I8), const(I8, 0))

    class TapeLook(Look):
        batches_once = True

        def first(self, cells, first_sides):
            return prove(const(DOUBLE, 1.0), box_sides=first_sides)

        def open(self, index, side, lane) -> None:
            b.store(broadcast(b, side, LANES), b.bitcast(sides, _P(V8)), align=8)
            hold(const(I64, 0), lane)

        def face(self, leaf):
            return prove_face(leaf)

        def crossed(self, leaf, side):
            return crossed(leaf, side)

        def prove(self, factor, level):
            return prove(factor, level)

        def descend(self, level, c) -> None:
            hold(level, b.zext(c, I64))

    emit_second_look(b, coords, flags, n, TapeLook(), cells)
    b.ret_void()
    return fn
