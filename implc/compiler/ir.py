"""implc's intermediate representation: the op table and the hash-consed SSA tape.

A :class:`Tape` is a list of nodes ``(op, args, attr)`` in topological order; ``args`` are indices of
earlier nodes. Inserting a node that already exists returns the existing index, so common subexpressions
are shared by construction. Every interpretation of a tape (the numpy reference, the gradient builder,
the LLVM code generator) keys its rules on the op names listed in :data:`OPS`.
"""

from __future__ import annotations

import hashlib
import math
import sys
from dataclasses import dataclass
from fractions import Fraction
from typing import Any


@dataclass(frozen=True)
class Op:
    name: str
    arity: int
    doc: str


OPS = {op.name: op for op in (
    Op("const", 0, "a real constant; attr = (nearest, lo, hi) doubles with lo <= value <= hi"),
    Op("var", 0, "input coordinate; attr = 0, 1, 2 for x, y, z"),
    Op("neg", 1, "-a"),
    Op("add", 2, "a + b; attr = True when both terms are provably >= 0 (the sum's lower bound is clamped at 0)"),
    Op("scale", 1, "c * a for an exactly known constant c = attr"),
    Op("sub", 2, "a - b"),
    Op("mul", 2, "a * b"),
    Op("div", 2, "a / b (an interval divisor containing 0 gives the whole line)"),
    Op("powi", 1, "a ** n for an integer n >= 2 (attr = n); even powers are tight"),
    Op("powf", 1, "a ** e for a real exponent e = attr, a >= 0 (NaN below)"),
    Op("sqrt", 1, "square root, a >= 0 (NaN below)"),
    Op("cbrt", 1, "principal cube root a ** (1/3), a >= 0 (NaN below, as SymPy's principal root)"),
    Op("exp", 1, "e ** a"),
    Op("log", 1, "natural log, a >= 0 (log 0 = -inf, NaN below)"),
    Op("sin", 1, "sine"),
    Op("cos", 1, "cosine"),
    Op("tan", 1, "tangent (an interval containing a pole gives the whole line)"),
    Op("asin", 1, "arcsine, -1 <= a <= 1 (NaN outside)"),
    Op("acos", 1, "arccosine, -1 <= a <= 1 (NaN outside)"),
    Op("atan", 1, "arctangent"),
    Op("atan2", 2, "atan2(a, b) in (-pi, pi]; an interval across the cut gives [-pi, pi]"),
    Op("atan2_wrapped", 2, "atan2(a, b) for a 2pi-periodic use: the interval may wrap past pi"),
    Op("sinh", 1, "hyperbolic sine"),
    Op("cosh", 1, "hyperbolic cosine"),
    Op("tanh", 1, "hyperbolic tangent"),
    Op("abs", 1, "|a|"),
    Op("min", 2, "min(a, b)"),
    Op("max", 2, "max(a, b)"),
    Op("select_lt", 3, "b if a < 0 else c; attr 'continuous' (branches meet where a = 0), 'jump' (an "
                       "undecided interval is NaN: the derivative of a possibly discontinuous select) or None"),
    Op("select_le", 3, "b if a <= 0 else c; attr as select_lt"),
    Op("cut_guard", 3, "c; its interval is NaN where the box straddles atan2(a, b)'s branch cut (guards the "
                       "derivative of a non-wrapped atan2, whose value jumps there)"),
)}

LIBM_OPS = ("cbrt", "powf", "exp", "log", "sin", "cos", "tan", "asin", "acos", "atan", "atan2",
            "atan2_wrapped", "sinh", "cosh", "tanh")
"""Ops whose point value comes from the C math library (bounded by a few ulps, not correctly rounded)."""


def _next_down(v: float) -> float:
    return math.nextafter(v, -math.inf)


def _next_up(v: float) -> float:
    return math.nextafter(v, math.inf)


def const_attr_from_fraction(value: Fraction) -> tuple[float, float, float]:
    """(nearest, lo, hi) doubles of an exact rational. Beyond the largest double the bound on that side is
    infinite and the other the largest double (the value is there), and so is ``nearest``."""
    try:
        nearest = float(value)  # correctly rounded
    except OverflowError:
        return (math.inf, sys.float_info.max, math.inf) if value > 0 else (-math.inf, -math.inf, -sys.float_info.max)
    lo = nearest if Fraction(nearest) <= value else _next_down(nearest)
    hi = nearest if Fraction(nearest) >= value else _next_up(nearest)
    return (nearest, lo, hi)


class Tape:
    """A hash-consed SSA tape: build it with the op methods, read it through ``nodes`` and ``outputs``."""

    def __init__(self):
        self.nodes: list[tuple[str, tuple[int, ...], Any]] = []  # attr: per op (an axis, bounds, an exponent...)
        self.outputs: list[int] = []
        self._index: dict[tuple, int] = {}
        self._nonnegative: list[bool] = []
        self._axes: list[int] = []

    # -- insertion --------------------------------------------------------------------------------
    def node(self, op: str, args: tuple[int, ...] = (), attr=None) -> int:
        if op not in OPS:
            raise KeyError(f"unknown op {op!r}")
        if len(args) != OPS[op].arity:
            raise ValueError(f"{op} takes {OPS[op].arity} arguments, got {len(args)}")
        key = (op, tuple(args), attr)
        found = self._index.get(key)
        if found is not None:
            return found
        if op in ("add", "mul", "min", "max"):  # commutative: share a+b and b+a
            swapped = (op, (args[1], args[0]), attr)
            if swapped in self._index:
                return self._index[swapped]
        self.nodes.append(key)
        self._index[key] = len(self.nodes) - 1
        return len(self.nodes) - 1

    def const(self, value) -> int:
        """A constant from a Fraction/int (exact) or a float (taken as exact)."""
        return self.node("const", (), const_attr_from_fraction(Fraction(value)))

    def const_bounds(self, nearest: float, lo: float, hi: float) -> int:
        return self.node("const", (), (float(nearest), float(lo), float(hi)))

    def var(self, axis: int) -> int:
        return self.node("var", (), axis)

    def axes(self) -> list[int]:
        """For each node, the coordinate axes it depends on, as a bit mask (bit a: axis a)."""
        masks = self._axes
        for op, args, attr in self.nodes[len(masks):]:  # nodes are only ever appended
            mask = 1 << attr if op == "var" else 0
            for a in args:
                mask |= masks[a]
            masks.append(mask)
        return masks

    def exact_value(self, i: int) -> Fraction | None:
        """The exact value of node ``i`` if it is a constant known exactly, else None."""
        op, _, attr = self.nodes[i]
        if op == "const" and attr[1] == attr[2] and math.isfinite(attr[0]):
            return Fraction(attr[0])
        return None

    # Folding arithmetic used by the lowering and by the gradient builder. Only exact folds are made.
    def add(self, a: int, b: int) -> int:
        va, vb = self.exact_value(a), self.exact_value(b)
        if va is not None and vb is not None:
            return self.const(va + vb)
        if va == 0:
            return b
        if vb == 0:
            return a
        nonnegative = self.is_nonnegative(a) and self.is_nonnegative(b)
        return self.node("add", (a, b), True if nonnegative else None)

    def scale(self, a: int, c: float) -> int:
        if c == 1:
            return a
        if c == 0:
            return self.const(0)
        va = self.exact_value(a)
        if va is not None:  # exact: c is a double, va a Fraction
            return self.const(va * Fraction(c))
        return self.node("scale", (a,), float(c))

    def sub(self, a: int, b: int) -> int:
        va, vb = self.exact_value(a), self.exact_value(b)
        if va is not None and vb is not None:
            return self.const(va - vb)
        if vb == 0:
            return a
        if va == 0:
            return self.neg(b)
        if a == b:
            return self.const(0)
        return self.node("sub", (a, b))

    def neg(self, a: int) -> int:
        va = self.exact_value(a)
        if va is not None:
            return self.const(-va)
        op, args, _ = self.nodes[a]
        if op == "neg":
            return args[0]
        return self.node("neg", (a,))

    def mul(self, a: int, b: int) -> int:
        va, vb = self.exact_value(a), self.exact_value(b)
        if va is not None and vb is not None:
            return self.const(va * vb)
        if a == b:  # x * x as a square: tight over intervals that contain 0
            return self.powi(a, 2)
        for v, other in ((va, b), (vb, a)):
            if v == 0:
                return self.const(0)
            if v == 1:
                return other
            if v == -1:
                return self.neg(other)
            if v is not None and float(v) == v:
                return self.scale(other, float(v))
        return self.node("mul", (a, b))

    def div(self, a: int, b: int) -> int:
        va, vb = self.exact_value(a), self.exact_value(b)
        if va is not None and vb is not None and vb != 0:
            return self.const(va / vb)
        if vb == 1:
            return a
        return self.node("div", (a, b))

    def powi(self, a: int, n: int) -> int:
        if n == 0:
            return self.const(1)
        if n == 1:
            return a
        if n < 0:
            return self.div(self.const(1), self.powi(a, -n))
        va = self.exact_value(a)
        if va is not None:
            return self.const(va**n)
        return self.node("powi", (a,), n)

    def unary(self, op: str, a: int) -> int:
        return self.node(op, (a,))

    def is_nonnegative(self, i: int) -> bool:
        """Whether node ``i`` is >= 0 wherever it is defined, by a structural argument (decided for every
        node up to ``i`` in order, each from its operands: no recursion, whatever the depth)."""
        known = self._nonnegative
        while len(known) <= i:
            known.append(self._prove_nonnegative(len(known)))
        return known[i]

    def _prove_nonnegative(self, i: int) -> bool:
        op, args, attr = self.nodes[i]
        nn = self.is_nonnegative
        if op == "const":
            return attr[1] >= 0
        if op in ("sqrt", "cbrt", "powf", "exp", "cosh", "abs", "acos"):
            return True
        if op == "powi":
            return attr % 2 == 0 or nn(args[0])
        if op == "add":
            return attr is True
        if op in ("mul", "div", "min"):
            return nn(args[0]) and nn(args[1])
        if op == "max":
            return nn(args[0]) or nn(args[1])
        if op == "scale":
            return attr >= 0 and nn(args[0])
        if op in ("select_lt", "select_le"):
            return nn(args[1]) and nn(args[2])
        if op == "cut_guard":
            return nn(args[2])
        return False

    def compacted(self) -> Tape:
        """A copy holding only the nodes the outputs depend on (same order, renumbered)."""
        live = set(self.outputs)
        for i in range(len(self.nodes) - 1, -1, -1):
            if i in live:
                live.update(self.nodes[i][1])
        out = Tape()
        remap: dict[int, int] = {}
        for i, (op, args, attr) in enumerate(self.nodes):
            if i in live:
                remap[i] = out.node(op, tuple(remap[a] for a in args), attr)
        out.outputs = [remap[o] for o in self.outputs]
        return out

    def subtape(self, root: int) -> Tape:
        """A tape computing node ``root`` alone (with the nodes it depends on) as its only output."""
        view = Tape()
        view.nodes, view.outputs = self.nodes, [root]
        return view.compacted()

    # -- inspection -------------------------------------------------------------------------------
    def fingerprint(self) -> str:
        """A stable hash of the tape and its outputs (used to key the compiled-code cache)."""
        h = hashlib.sha256()
        for op, args, attr in self.nodes:
            h.update(f"{op}{args}{attr!r};".encode())
        h.update(f"out{self.outputs}".encode())
        return h.hexdigest()

    def verify(self) -> None:
        """Check the SSA invariants: known ops, right arity, arguments defined before use."""
        for i, (op, args, _) in enumerate(self.nodes):
            if op not in OPS or len(args) != OPS[op].arity:
                raise AssertionError(f"node {i}: bad op or arity {op}{args}")
            if any(not 0 <= a < i for a in args):
                raise AssertionError(f"node {i}: argument not defined before use {args}")
        if any(not 0 <= o < len(self.nodes) for o in self.outputs):
            raise AssertionError("an output names no node")

    def __len__(self) -> int:
        return len(self.nodes)

    def __str__(self) -> str:
        lines = []
        names = {0: "x", 1: "y", 2: "z"}
        for i, (op, args, attr) in enumerate(self.nodes):
            if op == "const":
                text = repr(attr[0]) if attr[1] == attr[2] else f"{attr[0]!r} in [{attr[1]!r}, {attr[2]!r}]"
            elif op == "var":
                text = names[attr]
            else:
                text = f"{op} " + ", ".join(f"%{a}" for a in args)
                if attr is not None:
                    text += f" [{attr}]"
            lines.append(f"%{i} = {text}")
        lines.append("return " + ", ".join(f"%{o}" for o in self.outputs))
        return "\n".join(lines)
