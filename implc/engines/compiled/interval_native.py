"""The natural enclosure over the live terms only: per-region pruning inside the interval kernel.

Terms (:mod:`implc.engines.compiled.plan`) dead in a box's parent are skipped; each box gets its own live mask: a sum
term whose zero branch is decided over the box, and a Min/Max leaf that can never be the extremum there,
are dead for every descendant.
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm.control import Local, for_set_bits
from ...compiler.llvm.interval_rules import IntervalEmitter, emit_node, whole_line_if_undefined
from ...compiler.llvm.vector import VectorBuilder, broadcast
from .fold_native import IDENTITY, Accumulator, live_steps, live_terms


def emit_interval_regions(vb: VectorBuilder, tape, plan, lo_coords, hi_coords, live_mask):
    """Like :func:`implc.compiler.llvm.interval_rules.emit_interval`, skipping the terms dead in the parent
    (``live_mask``, an i64 shared by the W boxes) and returning, besides (lo, hi), each box's own live mask
    (a <W x i64> vector).

    Where the chain is a fold over the terms (:class:`implc.engines.compiled.plan.Fold`), a loop visits the live bits
    only, so a dead term costs nothing at all; otherwise every term's bit is tested in turn. With every
    term live both compute exactly what :func:`implc.compiler.llvm.interval_rules.emit_interval` does; with dead
    terms the fold skips their exact zeros (or infinities) instead of adding them, so its sums are equal or tighter.
    """
    b = vb.b
    em = IntervalEmitter(vb)
    vals: dict = {}
    for i in plan.before:
        emit_node(em, vb, tape, vals, i, lo_coords, hi_coords)
    kills = _Kills(vb)
    if plan.fold is not None:
        _emit_fold(em, vb, tape, plan, vals, lo_coords, hi_coords, live_mask, kills)
    else:
        _emit_term_by_term(em, vb, tape, plan, vals, lo_coords, hi_coords, live_mask, kills)
    lo, hi = whole_line_if_undefined(vb, *vals[tape.outputs[0]])
    return lo, hi, b.and_(broadcast(b, live_mask, vb.width), b.not_(kills.get()))


class _Kills:
    """The <W x i64> mask of the terms found dead per box, built up bit by bit."""

    def __init__(self, vb):
        self.vb = vb
        self.type = ir.VectorType(ir.IntType(64), vb.width)
        self.local = Local(vb.b, self.type, ir.Constant(self.type, [0] * vb.width))

    def add(self, dead, bits):
        """Mark ``bits`` (an i64, constant or not) dead in the boxes where ``dead`` holds."""
        b = self.vb.b
        bits = broadcast(b, bits, self.vb.width)
        self.local.set(b.or_(self.local.get(), b.select(dead, bits, ir.Constant(self.type, [0] * self.vb.width))))

    def get(self):
        return self.local.get()


def _emit_term(em, vb, tape, vals, term, bit, kills, lo_coords, hi_coords):
    """A term's own nodes; a sum term whose zero branch is decided over a whole box is marked dead there."""
    for i in term.private:
        emit_node(em, vb, tape, vals, i, lo_coords, hi_coords)
    if term.kind == "sum":
        g = vals[term.condition]
        strict = tape.nodes[term.root][0] == "select_lt"
        zero = vb.splat(0.0)
        if term.zero_when == "false":  # g < 0 (or <= 0) fails everywhere
            dead = vb.cmp(">=" if strict else ">", g[0], zero)
        else:
            dead = vb.cmp("<" if strict else "<=", g[1], zero)
        kills.add(dead, ir.Constant(ir.IntType(64), 1 << bit))
    return vals[term.root]


def _emit_term_by_term(em, vb, tape, plan, vals, lo_coords, hi_coords, live_mask, kills):
    """Each term in an if/else on its bit (dead: the identity of its chain); then the chain as written."""
    b = vb.b
    i64 = ir.IntType(64)
    for bit, term in enumerate(plan.terms):
        lo_local, hi_local = Local(b, vb.vtype), Local(b, vb.vtype)
        live = b.icmp_unsigned("!=", b.and_(live_mask, ir.Constant(i64, 1 << bit)), ir.Constant(i64, 0))
        with b.if_else(live) as (compute, skip):
            with compute:
                lo, hi = _emit_term(em, vb, tape, vals, term, bit, kills, lo_coords, hi_coords)
                lo_local.set(lo)
                hi_local.set(hi)
            with skip:
                lo_local.set(vb.splat(IDENTITY[term.kind]))
                hi_local.set(vb.splat(IDENTITY[term.kind]))
        vals[term.root] = (lo_local.get(), hi_local.get())
    if plan.chain_leaves:  # a leaf above another leaf's upper bound (min) can never be the minimum below
        op = tape.nodes[tape.outputs[0]][0]
        leaves = [vals[i] for i in plan.chain_leaves]
        if op == "min":
            bound = leaves[0][1]
            for leaf in leaves[1:]:
                bound = vb.minimum(bound, leaf[1])
        else:
            bound = leaves[0][0]
            for leaf in leaves[1:]:
                bound = vb.maximum(bound, leaf[0])
        for bit, term in enumerate(plan.terms):
            lo, hi = vals[term.root]
            kills.add(vb.cmp(">", lo, bound) if op == "min" else vb.cmp("<", hi, bound),
                      ir.Constant(i64, 1 << bit))
    for i in plan.after:
        emit_node(em, vb, tape, vals, i, lo_coords, hi_coords)


def _emit_fold(em, vb, tape, plan, vals, lo_coords, hi_coords, live_mask, kills):
    """The chain as a loop over the live terms only (see :class:`implc.engines.compiled.plan.Fold`)."""
    b = vb.b
    fold = plan.fold
    count = len(plan.terms)
    identity = vb.splat(IDENTITY[fold.op])
    acc = Accumulator(b, fold, vals.get(fold.base), [identity, identity])

    def combine(node, operands):
        op, _, attr = tape.nodes[node]
        return list(getattr(em, f"i_{op}")(operands, attr))
    minmax = fold.op != "sum"
    if minmax:  # the kill bound: min of the leaves' upper bounds (max of lower bounds for max)
        side, pick = (1, vb.minimum) if fold.op == "min" else (0, vb.maximum)
        roots = {t.root for t in plan.terms}
        bound_value = identity
        for leaf in plan.chain_leaves:
            if leaf not in roots:
                bound_value = pick(bound_value, vals[leaf][side])
        bound = Local(b, vb.vtype, bound_value)
        with b.goto_entry_block():
            kept = b.alloca(ir.ArrayType(vb.vtype, count), name="kept")  # the other side, per term
    reload = vb.reloadable([*lo_coords, *hi_coords])  # keeps each term's code inside its case
    var_nodes = [i for i in plan.before if tape.nodes[i][0] == "var"]
    for k, step in live_steps(b, fold, live_mask, count):
        own = dict(vals)
        fresh = reload()
        for i in var_nodes:
            axis = tape.nodes[i][2]
            own[i] = (fresh[axis], fresh[3 + axis])
        t = _emit_term(em, vb, tape, own, plan.terms[step.term], step.term, kills, lo_coords, hi_coords)
        for w in step.wrappers:
            emit_node(em, vb, tape, own, w, lo_coords, hi_coords)
        acc.take(step, list(own[step.wrappers[-1]] if step.wrappers else t), combine)
        if minmax:
            bound.set(pick(bound.get(), t[side]))
            b.store(t[1 - side], b.gep(kept, [ir.Constant(ir.IntType(32), 0), k], inbounds=True))
    vals[fold.top] = tuple(acc.result())
    if minmax:  # a live leaf entirely above the bound (below, for max) can never be the extremum below
        with for_set_bits(b, live_terms(b, live_mask, count)) as k:
            other = b.load(b.gep(kept, [ir.Constant(ir.IntType(32), 0), k], inbounds=True))
            dead = vb.cmp(">", other, bound.get()) if fold.op == "min" else vb.cmp("<", other, bound.get())
            kills.add(dead, b.shl(ir.Constant(k.type, 1), k))
    for i in fold.tail:
        emit_node(em, vb, tape, vals, i, lo_coords, hi_coords)


