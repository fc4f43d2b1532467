"""The tape engine's program: a tape encoded as flat instructions for the native interpreter.

Large tapes, and tapes with Min/Max anywhere but at the top, are not compiled per surface: one generic
native interpreter (:mod:`implc.engines.tape.interpreter_native`) runs them, and below each octant it runs a shorter
program with every Min/Max that the octant's enclosure decided replaced by its winning operand and
everything that only fed the losing one dropped (:mod:`implc.engines.tape.plan_native`), as fidget, libfive
and MPR do. This module owns the encoding both sides agree on:

- every value lives in a slot. Constants and the coordinates x, y, z have slots of their own and are
  not instructions: their slots are filled before a program runs (constants once, coordinates per batch
  of boxes or points), so a program is only the work. The instructions' values share slots where their
  lives do not overlap (:func:`_allocate`, as a register allocator would: bear's 537 instructions and 128
  constants and coordinates take 215 slots instead of 665, so that the interval slots of its programs,
  128 bytes each, fit the first-level cache), a choice's value operands kept in place as long as its
  result is read, since a simplified program reads the winner of a decided choice in its place.
- an instruction is :data:`implc.native.abi.INSTRUCTION_WORDS` int32: ``opcode, out, a, b, c``: the result
  goes to slot ``out``, the operands come from slots ``a``, ``b``, ``c`` (as many as the op takes; a
  select reads its condition from a and its branches from b and c). Above its low
  :data:`implc.native.abi.OPCODE_BITS`, the first word has bit k set where the value does not depend on axis k
  (:attr:`TapeProgram.zeros`): the dual numbers and interval gradients make that partial 0 exactly, as the
  gradient tape does (:func:`implc.compiler.gradient.with_gradient`), not the rule's NaN where it would multiply
  the 0 by an infinity. The result of the program is slot ``output`` (a simplified program has its own: a
  decided Min/Max at the top makes its winner the output).
- the header (:data:`implc.native.abi.PROGRAM_WORDS` int64) is what native code receives: addresses and
  counts of the instructions, the constant table (rows ``nearest, lo, hi`` with lo <= value <= hi,
  certified as in :data:`implc.compiler.ir.OPS`) and its slots, the slots of x, y and z (-1: unused), the slot
  count.

Opcodes are numbered by arity, unary first, so that native code tells from two comparisons how many
operands an instruction reads. ``mul_const`` and ``div_const`` are a product and a quotient whose second
operand is a constant slot whose certified interval excludes 0 (a scale, a division by a constant): their
rules skip what that operand's sign and zero partials already decide (one product per bound, none of
the product rule's partials of the constant), with the same enclosures as ``mul`` and ``div``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...compiler.ir import Tape
from ...native import abi

UNARY = ("neg", "abs", "sqrt", "exp", "log", "sin", "cos", "square", "cube", "fourth")
BINARY = ("add", "add_nonneg", "add_watched", "add_nonneg_watched", "sub", "mul", "div", "mul_const", "div_const",
          "min", "max")
TERNARY = ("select_lt", "select_le")
OPCODES = {name: code for code, name in enumerate(UNARY + BINARY + TERNARY)}
"""Opcode of each instruction kind."""
FIRST_BINARY = len(UNARY)
FIRST_TERNARY = len(UNARY) + len(BINARY)
CHOICE_OPS = ("min", "max", "select_lt", "select_le")
"""The instructions whose choice an interval can decide, between two value operands (min, max: a and
b; selects: b where the condition holds, c where it fails): bit 0 of a choice byte says the first may
be the result over a box, bit 1 the second."""

TINY_EXPONENTS = tuple(range(2, 127, 2))
"""The constants [0, 2^-e] a program with a sum of an exponential has (slots 0, 1, ... in this order): below
an octant where the exponential's enclosure is at most 2^-e, and 2^-e at most :data:`NEGLIGIBLE` times the
width of the sum's enclosure, the sum reads the constant instead (:mod:`implc.engines.tape.plan_native`), and the
exponential's argument is not evaluated: far from a primitive, a smooth blend's term costs nothing. Such a
sum's third instruction word says which of its operands an exponential gives (bit 0: the first, bit 1: the
second), and its opcode is ``add_watched`` or ``add_nonneg_watched``: the same sums, which only
``tape_interval`` tells from the others (a plain sum costs nothing more)."""
NEGLIGIBLE = 2.0 ** -7
"""How small a sum's exponential term must be, relative to the width of the sum's enclosure over an
octant, for the octant's descendants to read a constant instead: scale-free, and the sum's enclosure over
a descendant widens by at most that share of its width over the octant (a few per cent of a leaf's two
levels down; in the median far less: docs/soundness.md)."""

_POWERS = {2: "square", 3: "cube", 4: "fourth"}
_DIRECT = {"neg", "abs", "sqrt", "exp", "log", "sin", "cos", "sub", "mul", "div", "min", "max", "select_lt",
           "select_le"}
SUPPORTED_OPS = frozenset(_DIRECT | {"var", "const", "add", "scale", "powi"})
"""Tape ops the engine runs (``powi`` for exponents 2 to 4, selects of value tapes: not the "jump" of a
derivative); a tape with any other op is compiled."""


@dataclass(frozen=True, eq=False)
class TapeProgram:
    """A tape encoded for the engine (see the module docstring)."""

    instructions: np.ndarray  # (n, INSTRUCTION_WORDS) int32
    constants: np.ndarray  # (m, 3) float64: nearest, lo, hi
    constant_slots: np.ndarray  # (m,) int32
    variable_slots: np.ndarray  # (3,) int32, -1 where the coordinate is unused
    output: int
    slot_count: int
    zero: int = -1  # the slot of the exact zero constant (every one the tape has), -1 if none
    header: np.ndarray = field(init=False, repr=False, compare=False)  # what native code receives

    def __post_init__(self):
        header = np.zeros(abi.PROGRAM_WORDS, dtype=np.int64)
        header[abi.PROGRAM_INSTRUCTIONS] = self.instructions.ctypes.data
        header[abi.PROGRAM_LENGTH] = len(self.instructions)
        header[abi.PROGRAM_OUTPUT] = self.output
        header[abi.PROGRAM_CONSTANTS] = self.constants.ctypes.data
        header[abi.PROGRAM_CONSTANT_SLOTS] = self.constant_slots.ctypes.data
        header[abi.PROGRAM_CONSTANT_COUNT] = len(self.constants)
        header[abi.PROGRAM_VARIABLES: abi.PROGRAM_VARIABLES + 3] = self.variable_slots
        header[abi.PROGRAM_SLOT_COUNT] = self.slot_count
        header[abi.PROGRAM_ZERO] = self.zero
        object.__setattr__(self, "header", header)  # holds addresses: the arrays live as long as self

    def __len__(self) -> int:
        return len(self.instructions)

    @property
    def opcodes(self) -> np.ndarray:
        """Each instruction's opcode."""
        return self.instructions[:, 0] & abi.OPCODE_MASK

    @property
    def zeros(self) -> np.ndarray:
        """Each instruction's axes its value does not depend on (bit k: axis k), whose partials are 0."""
        return self.instructions[:, 0] >> abi.OPCODE_BITS

    @property
    def choices(self) -> int:
        """How many Min/Max instructions the program has."""
        return int(np.isin(self.opcodes, [OPCODES[op] for op in CHOICE_OPS]).sum())


def unsupported_ops(tape: Tape) -> set[str]:
    """The ops of ``tape`` (of all its nodes where it has one output, else of those its first output
    needs) that the engine cannot run."""
    bad = set()
    for op, _, attr in (tape.nodes if len(tape.outputs) == 1 else tape.subtape(tape.outputs[0]).nodes):
        if op not in SUPPORTED_OPS or (op == "powi" and attr not in _POWERS) or attr == "jump":
            bad.add(f"powi({attr})" if op == "powi" else op)
    return bad


def encode(tape: Tape) -> TapeProgram:
    """The program computing ``tape``'s first output; ValueError if it has an op the engine lacks."""
    bad = unsupported_ops(tape)
    if bad:
        raise ValueError(f"the tape engine cannot run {', '.join(sorted(bad))}")
    # lower() and the .vm reader hand over compacted tapes (every node needed, the output last)
    sub = tape if tape.outputs == [len(tape.nodes) - 1] else tape.subtape(tape.outputs[0])
    rows: list[tuple[int, ...]] = []
    constants: list[tuple[float, float, float]] = []
    constant_slots: list[int] = []
    variables = [-1, -1, -1]
    slot_count = 0

    def new_slot() -> int:
        nonlocal slot_count
        slot_count += 1
        return slot_count - 1

    zero: list[int] = []  # the one slot of every exact zero: a simplified program tells a zero by its slot

    def constant(nearest, lo, hi) -> int:
        if zero and nearest == lo == hi == 0:
            return zero[0]
        constants.append((nearest, lo, hi))
        constant_slots.append(new_slot())
        if nearest == lo == hi == 0:
            zero.append(constant_slots[-1])
        return constant_slots[-1]

    axes = sub.axes()
    zeros: list[int] = []  # per row: the axes its value does not depend on

    def emit(name, a, b=0, c=0) -> int:
        slot = new_slot()
        rows.append((OPCODES[name], slot, a, b, c))
        zeros.append(0b111 & ~axes[node])
        return slot

    slot_of: list[int] = []
    signed: set[int] = set()  # the constants' slots whose interval excludes 0
    exponential = [op == "exp" for op, _, _ in sub.nodes]
    if any(op == "add" and any(exponential[a] for a in args) for op, args, _ in sub.nodes):
        for e in TINY_EXPONENTS:  # created first: slots 0, 1, ... (constants keep their order in _allocate)
            constant(0.0, 0.0, 2.0 ** -e)

    for node, (op, args, attr) in enumerate(sub.nodes):
        s = [slot_of[a] for a in args]
        if op == "var":
            slot = variables[attr] = new_slot()
        elif op == "const":
            slot = constant(*attr)
            if attr[1] > 0 or attr[2] < 0:
                signed.add(slot)
        elif op == "add":
            watched = exponential[args[0]] | exponential[args[1]] << 1
            slot = emit(("add_nonneg" if attr else "add") + ("_watched" if watched else ""), s[0], s[1], watched)
        elif op == "scale":  # c is exact: the product's rounding is the mul rule's
            slot = emit("mul_const", s[0], constant(attr, attr, attr)) if attr else emit("mul", constant(0, 0, 0), s[0])
        elif op == "mul" and (s[0] in signed or s[1] in signed):
            slot = emit("mul_const", *(s if s[1] in signed else s[::-1]))
        elif op == "div" and s[1] in signed:
            slot = emit("div_const", *s)
        elif op == "powi":
            slot = emit(_POWERS[attr], *s)
        else:
            slot = emit(op, *s)
        slot_of.append(slot)
    fixed = constant_slots + [v for v in variables if v >= 0]
    aliasing = zero_aliasing(rows, zero[0]) if zero else None
    if aliasing is None:
        zero.clear()  # a value that may simplify to the zero constant meets an operation that tells −0 from +0
    rows, rename, slot_count = _allocate(rows, fixed, slot_of[sub.outputs[0]], aliasing)
    rows = [(row[0] | zero_axes << abi.OPCODE_BITS, *row[1:]) for row, zero_axes in zip(rows, zeros)]
    return TapeProgram(np.array(rows, dtype=np.int32).reshape(-1, abi.INSTRUCTION_WORDS),
                       np.array(constants, dtype=np.float64).reshape(-1, 3),
                       np.array([rename[c] for c in constant_slots], dtype=np.int32),
                       np.array([rename[v] if v >= 0 else -1 for v in variables], dtype=np.int32),
                       rename[slot_of[sub.outputs[0]]], slot_count, rename[zero[0]] if zero else -1)


def _operands(row) -> tuple[int, ...]:
    code = row[0]
    return row[2:3] if code < FIRST_BINARY else row[2:4] if code < FIRST_TERNARY else row[2:5]


ZERO_KEEPING = ("neg", "square", "cube", "fourth", "mul_const", "div_const")
"""The operations whose value is 0 (its partials 0) wherever their first operand is the exact 0
(mul_const and div_const: a constant second operand that excludes 0): a simplified program reads the zero
constant in their place (:mod:`implc.engines.tape.plan_native`)."""
ALIASING_SUMS = ("add", "add_watched", "sub")
"""The sums a simplified program replaces by an operand where the other is the exact 0 (a difference: where
its second is): x + 0 and x − 0 are x exactly, in every rounding mode, and so are their partials."""
_ZERO_SIGN_SHOWN = ("sqrt", "log", "abs")
"""Operations whose value or partials differ for −0 and +0 (sqrt's and log's derivatives ±∞, abs's partial
±1), as a quotient's divisor does: a simplified program reads +0 where the whole program may compute −0
(−x, x·c with c < 0, a sum rounded down), so a value that may differ so must not reach one of them."""
_ZERO_SIGN_LOST = ("square", "fourth", "exp", "cos")
"""Operations whose value and partials are the same for −0 and +0: what they compute from a zero of either
sign is the same number."""


def zero_aliasing(rows: list, zero: int) -> list[bool] | None:
    """Per instruction (``rows`` before allocation, ``zero``: the zero constant's slot) whether it
    is a sum a simplified program may replace by an operand (:data:`ALIASING_SUMS`, the other operand a
    value that may be exactly 0: a :data:`ZERO_KEEPING` of one, a choice with one as a value operand, a sum
    or difference of two); None where a value computed from one, whose zero's sign may then differ from the
    whole program's, reaches an operation that shows it (a divisor, :data:`_ZERO_SIGN_SHOWN`), which the
    simplification then leaves alone (the program's header has no zero slot)."""
    prone, signed = {zero}, {zero}  # exactly 0 where simplified; its sign of zero perhaps not the program's
    keeping = {OPCODES[op] for op in ZERO_KEEPING}
    sums = {OPCODES[op] for op in ALIASING_SUMS}
    shown = {OPCODES[op] for op in _ZERO_SIGN_SHOWN}
    lost = {OPCODES[op] for op in _ZERO_SIGN_LOST}
    aliasing = []
    for row in rows:
        code, out, a, b, c = row
        values = _operands(row)[1:] if code >= FIRST_TERNARY else _operands(row)  # a select's condition: a sign test
        if (code in shown and a in signed) or (code == OPCODES["div"] and b in signed):
            return None
        if code in keeping:
            hit = a in prone
        elif code in (OPCODES["min"], OPCODES["max"]):
            hit = a in prone or b in prone
        elif code >= FIRST_TERNARY:
            hit = b in prone or c in prone
        elif code in sums:
            hit = a in prone and b in prone
        else:
            hit = False
        aliasing.append(code in sums and (b in prone or (a in prone and code != OPCODES["sub"])))
        if hit:
            prone.add(out)
        if hit or (code not in lost and any(v in signed for v in values)):
            signed.add(out)
    return aliasing


def _allocate(rows: list, fixed: list, output: int, aliasing: list[bool] | None = None) -> tuple[list, dict, int]:
    """The instructions ``rows`` (every value in a slot of its own) with their values in as few slots as
    they allow: a slot is taken again once its value has been read for the last time. Constants and
    coordinates (``fixed``) keep slots of their own. A choice's value operands stay in their slots as
    long as its result is read, so that a simplified program may read the winner where it read the
    choice (:mod:`implc.engines.tape.plan_native` makes a decided choice an alias of its winner); so do a
    sum's operands where the sum may become an alias of one (``aliasing``, per row: :func:`zero_aliasing`).
    Returns the rows, the new slot of each old one, the slot count."""
    choice_codes = {OPCODES[op] for op in CHOICE_OPS}
    operands = [_operands(row) for row in rows]
    aliasing = aliasing or [False] * len(rows)
    last = {output: len(rows)}  # each value's last read (a choice's value operands: its result's)
    for i in range(len(rows) - 1, -1, -1):  # backward: a value's first read seen is its last
        code = rows[i][0]
        if code in choice_codes or aliasing[i]:  # an aliasing sum is binary: both its operands kept
            until = last.get(rows[i][1], i)
            for k, operand in enumerate(operands[i]):
                kept = until if code < FIRST_TERNARY or k > 0 else i
                if last.get(operand, -1) < kept:
                    last[operand] = kept
        else:
            for operand in operands[i]:
                last.setdefault(operand, i)
    rename = {slot: n for n, slot in enumerate(fixed)}
    count, free, first_free = len(fixed), [], len(fixed)
    for i, row in enumerate(rows):
        read = [rename[o] for o in operands[i]]
        for o in set(operands[i]):
            if last[o] == i and rename[o] >= first_free:
                free.append(rename[o])
        if free:  # the result may take an operand's slot: every evaluator reads its operands first
            rename[row[1]] = free.pop()
        else:
            rename[row[1]] = count
            count += 1
        rows[i] = (row[0], rename[row[1]], *read, *row[2 + len(read):])  # a sum's third word kept
    return rows, rename, count


def slot_scratch(slot_count: int) -> np.ndarray:
    """The interpreter's slots for a program of ``slot_count`` slots (:data:`implc.native.abi.TAPE_SLOT_DOUBLES`
    doubles each: the interval slots, then the dual-number slots), starting on a 64-byte boundary: each
    slot's vectors are whole cache lines, so that loading what the previous instruction stored neither
    splits nor misses store forwarding (unaligned, the engine ran three times slower)."""
    count = slot_count * abi.TAPE_SLOT_DOUBLES
    raw = np.empty(count * 8 + 64, dtype=np.uint8)
    start = -raw.ctypes.data % 64
    return raw[start: start + count * 8].view(np.float64)
