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


@dataclass
class RegionPlan:
    terms: list[Term] = field(default_factory=list)
    before: list[int] = field(default_factory=list)  # computed first (needed by several terms or the chain)
    after: list[int] = field(default_factory=list)  # the chain combining the terms
    chain_leaves: list[int] = field(default_factory=list)  # min/max chains: every leaf, term or not

    @property
    def enabled(self) -> bool:
        return bool(self.terms)


def _is_zero(tape, i) -> bool:
    return tape.exact_value(i) == 0


def _sum_leaves(tape, i, out):
    op, args, _ = tape.nodes[i]
    if op in ("add", "sub"):
        _sum_leaves(tape, args[0], out)
        _sum_leaves(tape, args[1], out)
    elif op in ("neg", "scale"):
        _sum_leaves(tape, args[0], out)
    else:
        out.append(i)
    return out


def _chain_leaves(tape, i, op, out):
    node_op, args, _ = tape.nodes[i]
    if node_op == op:
        _chain_leaves(tape, args[0], op, out)
        _chain_leaves(tape, args[1], op, out)
    else:
        out.append(i)
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
        closures = {r: _closure(tape, [r]) for r in roots}
        # a term needed inside another term cannot be dropped on its own
        nested = {r for r in roots for s in roots if s != r and r in closures[s]}
        if not nested:
            break
        roots = [r for r in roots if r not in nested]
    roots = roots[:MAX_TERMS]
    if not roots:
        return RegionPlan()
    out = tape.outputs[0]
    root_set = frozenset(roots)
    chain = _closure(tape, [out], stop=root_set) - root_set  # reached from F without entering a term
    downstream = set()  # nodes that depend on a term root: the combining chain
    for i, (_, args, _) in enumerate(tape.nodes):
        if any(a in root_set or a in downstream for a in args):
            downstream.add(i)
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
    return RegionPlan(terms=terms, before=before, after=after, chain_leaves=chain_leaves)
