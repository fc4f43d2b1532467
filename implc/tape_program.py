"""The tape engine's program: a tape encoded as flat instructions for the native interpreter.

Large tapes, and tapes with Min/Max anywhere but at the top, are not compiled per surface: one generic
native interpreter (:mod:`implc.codegen.tape_eval`) runs them, and below each octant it runs a shorter
program with every Min/Max that the octant's enclosure decided replaced by its winning operand and
everything that only fed the losing one dropped (:mod:`implc.codegen.tape_simplify`), as fidget, libfive
and MPR do. This module owns the encoding both sides agree on:

- an instruction is four int32: ``opcode, out, a, b``. ``out`` is the slot the result goes to (each
  instruction of the full program has its own slot, its index; a simplified program keeps the slots of the
  instructions it keeps), ``a`` and ``b`` the operand slots (``var``: the axis; ``const``: the row of the
  constant table).
- the constant table: one row ``(nearest, lo, hi)`` per constant (lo <= value <= hi, certified as in
  :data:`implc.ir.OPS`).
- the last instruction computes F (a simplified program keeps this true: everything it keeps is an
  ancestor of its last instruction).

Opcodes are numbered by arity: nullary first, then unary, then binary, so that native code tells how
many operands an instruction reads from two comparisons.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .abi import TAPE_SLOT_DOUBLES
from .ir import Tape

NULLARY = ("var", "const")
UNARY = ("neg", "abs", "sqrt", "exp", "log", "sin", "cos", "square", "cube", "fourth")
BINARY = ("add", "add_nonneg", "sub", "mul", "div", "min", "max")
OPCODES = {name: code for code, name in enumerate(NULLARY + UNARY + BINARY)}
"""Opcode of each instruction kind."""
FIRST_UNARY = len(NULLARY)
FIRST_BINARY = len(NULLARY) + len(UNARY)
CHOICE_OPS = ("min", "max")
"""The instructions whose choice an interval can decide (bit 0: operand a may be the result; bit 1: b)."""

_POWERS = {2: "square", 3: "cube", 4: "fourth"}
_DIRECT = {"neg", "abs", "sqrt", "exp", "log", "sin", "cos", "sub", "mul", "div", "min", "max"}
SUPPORTED_OPS = frozenset(_DIRECT | {"var", "const", "add", "scale", "powi"})
"""Tape ops the engine runs (``powi`` for exponents 2 to 4); a tape with any other op is compiled."""


@dataclass(frozen=True)
class TapeProgram:
    """A tape encoded for the engine: ``instructions`` (n, 4) int32 and ``constants`` (m, 3) float64."""

    instructions: np.ndarray
    constants: np.ndarray

    def __len__(self) -> int:
        return len(self.instructions)

    @property
    def choices(self) -> int:
        """How many Min/Max instructions the program has."""
        codes = self.instructions[:, 0]
        return int(np.isin(codes, [OPCODES[op] for op in CHOICE_OPS]).sum())


def unsupported_ops(tape: Tape) -> set[str]:
    """The ops of ``tape`` (reachable from its first output) that the engine cannot run."""
    bad = set()
    for op, _, attr in tape.subtape(tape.outputs[0]).nodes:
        if op not in SUPPORTED_OPS or (op == "powi" and attr not in _POWERS):
            bad.add(f"powi({attr})" if op == "powi" else op)
    return bad


def encode(tape: Tape) -> TapeProgram:
    """The program computing ``tape``'s first output; ValueError if it has an op the engine lacks."""
    bad = unsupported_ops(tape)
    if bad:
        raise ValueError(f"the tape engine cannot run {', '.join(sorted(bad))}")
    sub = tape.subtape(tape.outputs[0])
    rows: list[tuple[int, int, int, int]] = []
    constants: list[tuple[float, float, float]] = []
    slot_of: list[int] = []

    def emit(name, a=0, b=0) -> int:
        rows.append((OPCODES[name], len(rows), a, b))
        return len(rows) - 1

    def constant(nearest, lo, hi) -> int:
        constants.append((nearest, lo, hi))
        return emit("const", len(constants) - 1)

    for op, args, attr in sub.nodes:
        s = [slot_of[a] for a in args]
        if op == "var":
            slot = emit("var", attr)
        elif op == "const":
            slot = constant(*attr)
        elif op == "add":
            slot = emit("add_nonneg" if attr else "add", *s)
        elif op == "scale":  # c is exact: the product's rounding is the mul rule's
            slot = emit("mul", constant(attr, attr, attr), s[0])
        elif op == "powi":
            slot = emit(_POWERS[attr], *s)
        else:
            slot = emit(op, *s)
        slot_of.append(slot)
    return TapeProgram(np.array(rows, dtype=np.int32).reshape(-1, 4),
                       np.array(constants, dtype=np.float64).reshape(-1, 3))



def slot_scratch(length: int) -> np.ndarray:
    """The interpreter's slots for a program of ``length`` instructions (:data:`implc.abi.TAPE_SLOT_DOUBLES`
    doubles each), starting on a 64-byte boundary: each slot's vectors are whole cache lines, so that
    loading what the previous instruction stored neither splits nor misses store forwarding (unaligned,
    the engine ran three times slower)."""
    count = length * TAPE_SLOT_DOUBLES
    raw = np.empty(count * 8 + 64, dtype=np.uint8)
    start = -raw.ctypes.data % 64
    return raw[start: start + count * 8].view(np.float64)
