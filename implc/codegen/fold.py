"""The loop over the live terms of a :class:`implc.regions.Fold`, shared by the interval kernel and the
pruned gradient: one iteration per set bit of the live mask, a switch to that term's code, and an
accumulator that starts empty (a fold with no base) and combines each term through its spine node.

Values are flat lists of vectors (an interval: [lo, hi]; a dual number: [value, ∂x, ∂y, ∂z]).
"""

from __future__ import annotations

from llvmlite import ir

from .control import Local, for_set_bits

I1 = ir.IntType(1)


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
