"""The loop over the live terms of a :class:`implc.engines.compiled.plan.Fold`, shared by the interval kernel, the
pruned gradient and the pruned mean-value form: one iteration per set bit of the live mask, a switch to
that term's code, and an accumulator that starts empty (a fold with no base) and combines each term
through its spine node.

Values are flat lists of vectors (an interval: [lo, hi]; a dual number: [value, ∂x, ∂y, ∂z]).
"""

from __future__ import annotations

import math

from llvmlite import ir

from ...compiler.llvm.control import Local, for_set_bits

I1 = ir.IntType(1)

IDENTITY = {"sum": 0.0, "min": math.inf, "max": -math.inf}
"""The value of a chain (a term's kind) with nothing in it."""


def live_terms(builder: ir.IRBuilder, mask, count: int):
    """The bits of ``mask`` that name one of ``count`` terms."""
    return builder.and_(mask, ir.Constant(mask.type, (1 << count) - 1 if count < 64 else -1))


def live_steps(builder: ir.IRBuilder, fold, mask, count: int):
    """For each live term in bit order, yield ``(bit, step)`` with the builder inside that term's case;
    code emitted there runs for that term only. Consume it fully (a plain ``for`` loop)."""
    with for_set_bits(builder, live_terms(builder, mask, count)) as k:
        after = builder.append_basic_block("fold.next")
        switch = builder.switch(k, after)
        for step in fold.steps:
            case = builder.append_basic_block(f"fold.term{step.term}")
            switch.add_case(ir.Constant(k.type, step.term), case)
            builder.position_at_end(case)
            yield k, step
            builder.branch(after)
        builder.position_at_end(after)


class Accumulator:
    """The fold's running value: ``start`` (the base's value) or empty until the first live term."""

    def __init__(self, builder: ir.IRBuilder, fold, start, identity):
        self.b = builder
        self.identity = identity
        self.slots = [Local(builder, v.type, v) for v in (start if fold.base is not None else identity)]
        self.empty = Local(builder, I1, ir.Constant(I1, int(fold.base is None)))
        self.has_base = fold.base is not None

    def take(self, step, value, combine):
        """Combine the term's ``value`` in through ``combine(node, operands)`` (its spine node's rule)."""
        b = self.b
        if step.node is None:  # the innermost term of a fold with no base: it starts the accumulator
            new = value
        else:
            current = [slot.get() for slot in self.slots]
            new = combine(step.node, [value, current] if step.term_left else [current, value])
            if not self.has_base:
                is_empty = self.empty.get()
                new = [b.select(is_empty, v, n) for v, n in zip(value, new)]
        for slot, v in zip(self.slots, new):
            slot.set(v)
        self.empty.set(ir.Constant(I1, 0))

    def result(self):
        """The folded value; the identity when no term was live and there is no base."""
        is_empty = self.empty.get()
        return [self.b.select(is_empty, i, slot.get()) for i, slot in zip(self.identity, self.slots)]


def fold_live_terms(vb, tape, plan, live_mask, inputs, evaluate, combine, identity):
    """The value of the whole chain (``plan.fold`` and its tail) over the live terms, where every operand
    is computed by ``evaluate(root, inputs)`` (a flat value of the subtape rooted there, from the
    coordinate vectors ``inputs``) and every chain node applied by ``combine(node, operands)``;
    ``identity``: the fold's value when no term is live and there is no base."""
    fold = plan.fold
    start = evaluate(fold.base, inputs) if fold.base is not None else None
    acc = Accumulator(vb.b, fold, start, identity)
    reload = vb.reloadable(inputs)  # keeps each term's code inside its case
    for _, step in live_steps(vb.b, fold, live_mask, len(plan.terms)):
        value = evaluate(plan.terms[step.term].root, reload())
        for w in step.wrappers:
            value = combine(w, [value])
        acc.take(step, value, combine)
    result, previous = acc.result(), fold.top
    for node in fold.tail:  # above the fold: combine with the non-term operand
        _, args, _ = tape.nodes[node]
        result = combine(node, [result if a == previous else evaluate(a, inputs) for a in args])
        previous = node
    return result
