"""Per-region simplification: which terms of a tape can be dropped for every box below an octant.

F is often a sum of blend terms (each ``select(g, value, 0)``: zero wherever g > 0) or a Min/Max chain
(CSG). When an octant's enclosure decides that a term vanishes (the blend's "d > R" branch) or can never
be the minimum (its lower bound exceeds another term's upper bound), the term is *dead* for every point of
the octant, hence for all its descendants, which then skip its code entirely (as libfive's tape push and
fidget's simplify do). The interval kernel receives a live-term bitmask per parent and returns one per
child. This module finds the terms and partitions the tape into what is computed before them (inputs and what
the chain needs), inside each term's own block (everything else the term needs, recomputed per term if
shared), and after them (the chain that combines them).
"""

from __future__ import annotations

from dataclasses import dataclass, field

MAX_TERMS = 64
"""One bit per term in a 64-bit live mask."""


@dataclass(frozen=True)
class Term:
    root: int
    kind: str  # "sum" (a select with a zero branch), "min" or "max" (a leaf of the top-level chain)
    private: tuple[int, ...]  # nodes computed in this term's block, in tape order (the root included)
    condition: int | None = None  # sum terms: the select's condition node
    zero_when: str | None = None  # sum terms: "true" or "false", the condition outcome that gives 0


@dataclass(frozen=True)
class FoldStep:
    """One term's entry into the fold: ``node`` combines the accumulator with the term's value (after its
    ``wrappers``, neg/scale nodes in tape order); ``node`` is None for the innermost term of a fold with no
    base, which starts the accumulator."""

    term: int  # index into RegionPlan.terms (its live bit)
    node: int | None
    wrappers: tuple[int, ...] = ()
    term_left: bool = False  # the term's value is the node's first argument


@dataclass(frozen=True)
class Fold:
    """The combining chain as a left fold over the terms in bit order, so that a kernel can loop over the
    live bits only and pay nothing per dead term. ``base``: the non-term value the accumulator starts from
    (None: the first live term starts it); ``top``: the node whose value the finished accumulator is;
    ``tail``: the rest of ``after`` (nodes above ``top`` that combine it with non-term values)."""

    op: str  # "sum", "min" or "max"
    base: int | None
    steps: tuple[FoldStep, ...]
    top: int
    tail: tuple[int, ...]


@dataclass
class RegionPlan:
    terms: list[Term] = field(default_factory=list)
    before: list[int] = field(default_factory=list)  # computed first (needed by several terms or the chain)
    after: list[int] = field(default_factory=list)  # the chain combining the terms
    chain_leaves: list[int] = field(default_factory=list)  # min/max chains: every leaf, term or not
    fold: Fold | None = None  # the chain as a fold over the terms, where it is one

    @property
    def enabled(self) -> bool:
        return bool(self.terms)


def _is_zero(tape, i) -> bool:
    return tape.exact_value(i) == 0


def _leaves(tape, root, through) -> list[int]:
    """The nodes below ``root`` reached through ops in ``through`` (their operands, left to right), in
    order: an explicit stack, so that chains of any depth are fine."""
    out, stack = [], [root]
    while stack:
        i = stack.pop()
        op, args, _ = tape.nodes[i]
        if op in through:
            stack.extend(reversed(args))
        else:
            out.append(i)
    return out


def _sum_leaves(tape, i, out):
    out.extend(_leaves(tape, i, ("add", "sub", "neg", "scale")))
    return out


def _chain_leaves(tape, i, op, out):
    out.extend(_leaves(tape, i, (op,)))
    return out


def _closure(tape, roots, stop=frozenset()) -> set[int]:
    """Nodes the roots depend on (roots included), not looking past the ``stop`` nodes."""
    seen, todo = set(), list(roots)
    while todo:
        i = todo.pop()
        if i in seen:
            continue
        seen.add(i)
        if i not in stop or i in roots:
            todo.extend(tape.nodes[i][1])
    return seen


def _candidates(tape) -> tuple[list[tuple], list[int]]:
    out = tape.outputs[0]
    op = tape.nodes[out][0]
    if op in ("min", "max"):
        leaves = _chain_leaves(tape, out, op, [])
        return [(leaf, op, None, None) for leaf in leaves], leaves
    found = []
    for leaf in _sum_leaves(tape, out, []):
        leaf_op, args, _ = tape.nodes[leaf]
        if leaf_op in ("select_lt", "select_le"):
            if _is_zero(tape, args[2]):
                found.append((leaf, "sum", args[0], "false"))
            elif _is_zero(tape, args[1]):
                found.append((leaf, "sum", args[0], "true"))
    return found, []


def plan_regions(tape) -> RegionPlan:
    """The region plan of a single-output value tape (no terms: nothing to prune)."""
    candidates, chain_leaves = _candidates(tape)
    roots = [c[0] for c in candidates]
    while True:
        # a term needed inside another term cannot be dropped on its own (linear in the closures' sizes)
        candidates_set = set(roots)
        nested = set()
        for s in roots:
            nested |= (_closure(tape, [s]) & candidates_set) - {s}
        if not nested:
            break
        roots = [r for r in roots if r not in nested]
    roots = roots[:MAX_TERMS]
    if not roots:
        return RegionPlan()
    out = tape.outputs[0]
    root_set = frozenset(roots)
    chain = _closure(tape, [out], stop=root_set) - root_set  # reached from F without entering a term
    downstream = _closure_users(tape, root_set) - root_set  # the combining chain
    # Everything a term needs that the chain does not is computed inside the term's block, even when
    # another term needs it too (then it is computed in both): a dead term then costs nothing at all.
    # Inputs and constants stay outside, as free.
    in_terms = set()
    private = {}
    for r in roots:
        mine = [n for n in sorted(_closure(tape, [r])) if n not in chain and tape.nodes[n][0] not in ("var", "const")]
        private[r] = mine
        in_terms.update(mine)
    needed = _closure(tape, [out])
    before = [i for i in sorted(needed) if i not in in_terms and i not in downstream]
    after = [i for i in sorted(needed) if i in downstream and i not in root_set]
    info = {c[0]: c for c in candidates}
    terms = [Term(root=r, kind=info[r][1], private=tuple(private[r]), condition=info[r][2], zero_when=info[r][3])
             for r in roots]
    plan = RegionPlan(terms=terms, before=before, after=after, chain_leaves=chain_leaves)
    plan.fold = _fold(tape, plan)
    return plan


_FOLD_OPS = {"sum": ("add", "sub"), "min": ("min",), "max": ("max",)}


def _fold(tape, plan: RegionPlan) -> Fold | None:
    """The chain as a left fold over the terms in bit order, or None when it has another shape (then the
    kernel tests every term's bit in turn)."""
    kind = plan.terms[0].kind
    bit_of = {t.root: k for k, t in enumerate(plan.terms)}
    with_terms = _closure_users(tape, bit_of)

    def unwrap(i):
        """(bit, wrappers) when node i is a term root under neg/scale nodes (sums only), else None."""
        chain = []
        while i not in bit_of:
            op, args, _ = tape.nodes[i]
            if kind != "sum" or op not in ("neg", "scale"):
                return None
            chain.append(i)
            i = args[0]
        return bit_of[i], tuple(reversed(chain))

    ops = _FOLD_OPS[kind]
    tail, node = [], tape.outputs[0]
    while True:  # above the fold: nodes combining it with values that involve no term
        op, args, _ = tape.nodes[node]
        if op not in ops or unwrap(args[0]) or unwrap(args[1]):
            break
        inner = [a for a in args if a in with_terms]
        if len(inner) != 1 or (op == "sub" and inner[0] != args[0]):
            return None
        tail.append(node)
        node = inner[0]
    top, steps, base = node, [], None
    while True:
        op, args, _ = tape.nodes[node]
        if op not in ops:
            if node in with_terms:
                return None
            base = node
            break
        left, right = unwrap(args[0]), unwrap(args[1])
        if right is not None and left is not None:
            steps += [FoldStep(right[0], node, right[1]), FoldStep(left[0], None, left[1])]
            break
        if right is not None:
            steps.append(FoldStep(right[0], node, right[1]))
            node = args[0]
        elif left is not None and op != "sub":
            steps.append(FoldStep(left[0], node, left[1], term_left=True))
            node = args[1]
        else:
            return None
    steps.reverse()
    if [s.term for s in steps] != list(range(len(plan.terms))):
        return None  # not every term once, in bit order
    # the spine and wrappers feed only the next spine node: nothing else reads a partial fold
    owned = {s.node for s in steps if s.node is not None} | {w for s in steps for w in s.wrappers}
    consumers = {top} | {s.node for s in steps if s.node is not None} | set(tail)
    for i, (_, args, _) in enumerate(tape.nodes):
        if i not in consumers and i not in owned and any(a in owned or a in bit_of for a in args):
            return None
    if set(plan.after) != owned | set(tail) - set(bit_of):
        return None
    return Fold(op=kind, base=base, steps=tuple(steps), top=top, tail=tuple(reversed(tail)))


def _closure_users(tape, roots) -> set[int]:
    """Nodes that depend on any of ``roots`` (the roots included)."""
    found = set(roots)
    for i, (_, args, _) in enumerate(tape.nodes):
        if any(a in found for a in args):
            found.add(i)
    return found
