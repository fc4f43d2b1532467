"""Models from other tools: the ``.vm`` tapes of fidget and MPR, read straight into implc's IR.

A ``.vm`` file is one SSA instruction per line, ``NAME OP ARG...``, ``#`` starting a comment; the last
instruction is F (F < 0 inside). Each instruction becomes one node of a :class:`~implc.compiler.ir.Tape` as it is
read (hash-consed, so repeated subexpressions are shared), in one pass and without recursion: a model of
any size and depth loads in time linear in its length. Constants are decimal texts, enclosed exactly
(``0.1`` is the interval of doubles around the decimal 0.1). A header comment ``--scale S`` (fidget's
render setting) suggests the bounds [-1/S, 1/S]³; otherwise [-1, 1]³.

:func:`load_vm` returns a :class:`VmModel`, which :func:`implc.compile` accepts like a SymPy expression.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from fractions import Fraction
from pathlib import Path
from typing import TYPE_CHECKING

from ..common.untrusted import decimal, printable, read_text
from ..errors import VmError
from .ir import Tape, const_attr_from_fraction

if TYPE_CHECKING:
    import sympy

MAX_BYTES = 1 << 30
"""The largest ``.vm`` file read (fidget's models are a few MiB)."""


_UNARY = {"neg": None, "square": None, "sqrt": "sqrt", "exp": "exp", "ln": "log", "sin": "sin", "cos": "cos",
          "abs": "abs", "tan": "tan", "asin": "asin", "acos": "acos", "atan": "atan"}
_BINARY = {"add", "sub", "mul", "div", "min", "max", "atan2"}
OPS = sorted({"var-x", "var-y", "var-z", "const", *_UNARY, *_BINARY})
"""Every op this reader accepts (the models' README lists the ones in use)."""


@dataclass(frozen=True)
class VmModel:
    """A model read from a ``.vm`` file: its tape (one output, F), suggested bounds and where it came from."""

    name: str
    tape: Tape
    bounds: tuple
    instructions: int
    source: str = ""
    """The ``.vm`` text it was read from: what travels to a cluster's workers (:mod:`implc.cluster.recipe`)."""

    def __str__(self) -> str:
        return f"{self.name}.vm ({self.instructions} instructions)"

    def __call__(self, x, y, z) -> sympy.Expr:
        """F of this model at (x, y, z) (SymPy expressions): an application of a SymPy function that
        :func:`implc.compile` inlines, so that a model composes with SymPy (CSG, transforms, extrusion:
        ``Max(model(x, y, z), Abs(z) - 1/10)``)."""
        import sympy  # only here: reading and compiling a model needs no SymPy

        function = sympy.Function(f"{self.name}_{self.tape.fingerprint()[:8]}")
        function.implc_tape = self.tape  # what implc.compiler.lower inlines (the name tells tapes apart)
        return function(x, y, z)


def load_vm(path: str | os.PathLike[str]) -> VmModel:
    """Read a ``.vm`` file; :class:`VmError` for an unknown op, an undefined or redefined name, a bad
    argument count or constant, an empty file.

    >>> import tempfile, implc
    >>> from pathlib import Path
    >>> folder = tempfile.TemporaryDirectory()
    >>> path = Path(folder.name) / "ball.vm"
    >>> lines = ["# --scale 0.5", "x var-x", "y var-y", "z var-z", "xx square x", "yy square y", "zz square z",
    ...          "s add xx yy", "t add s zz", "c const 1", "out sub t c"]
    >>> _ = path.write_text(chr(10).join(lines))
    >>> model = implc.load_vm(path)
    >>> model.instructions, model.bounds[0]                 # the header's --scale 0.5: bounds [-2, 2]³
    (10, (-2.0, 2.0))
    >>> voxels = implc.voxelize(implc.compile(model), depth=5)   # the unit sphere on a 32³ grid over [-2, 2]³
    >>> bool(abs(voxels.centers()).max() < 1.2)              # every kept cell lies near it
    True
    >>> folder.cleanup()
    """
    path = Path(path)
    text = read_text(path, MAX_BYTES, VmError, "model file")
    where = str(path) if not path.is_symlink() else f"{path} (a link to {os.path.realpath(path)})"
    return parse_vm(text, name=path.stem, where=where)


def parse_vm(text: str, name: str = "model", where: str = "<vm>") -> VmModel:
    """A :class:`VmModel` from ``.vm`` text (see :func:`load_vm`)."""
    tape = Tape()
    names: dict[str, int] = {}
    last = None
    count = 0
    scale = None
    for number, raw in enumerate(text.splitlines(), start=1):
        line, _, comment = raw.partition("#")
        found = re.search(r"--scale\s+([0-9.eE+-]+)", comment)
        if found and scale is None:
            scale = _number(found.group(1), where, number)
        words = line.split()
        if not words:
            continue
        if len(words) < 2:
            raise VmError(f"{where}:{number}: expected 'NAME OP ARG...', got '{printable(line.strip(), 40)}'")
        target, op, args = words[0], words[1], words[2:]
        if target in names:
            raise VmError(f"{where}:{number}: '{printable(target, 40)}' is defined twice (a .vm tape is SSA)")
        names[target] = last = _instruction(tape, names, op, args, where, number)
        count += 1
    if last is None:
        raise VmError(f"{where}: no instructions (an empty model)")
    tape.outputs = [last]
    tape = tape.compacted()
    tape.verify()
    half = _half_width(scale, where)
    return VmModel(name, tape, ((-half, half),) * 3, count, text)


def _half_width(scale: Fraction | None, where) -> float:
    """The bounds' half width 1/S for a header's ``--scale S`` (1 without one): VmError unless it is a
    positive double the grid can be divided by."""
    if scale is None:
        return 1.0
    if not Fraction(1, 10**300) <= scale <= 10**300:
        raise VmError(f"{where}: the header's --scale is {'not positive' if scale <= 0 else 'out of range'} (it "
                      "gives the bounds [-1/S, 1/S]³: S must be from 1e-300 to 1e300)")
    return float(1 / scale)


def _number(text, where, number) -> Fraction:
    try:
        return decimal(text)
    except ValueError as exc:
        raise VmError(f"{where}:{number}: {exc}") from None


def _instruction(tape: Tape, names, op, args, where, number) -> int:
    if op.startswith("var-") and op[4:] in ("x", "y", "z"):
        _arity(op, args, 0, where, number)
        return tape.var("xyz".index(op[4:]))
    if op == "const":
        _arity(op, args, 1, where, number)
        value = _number(args[0], where, number)
        return tape.const_bounds(*const_attr_from_fraction(value))
    if op not in _UNARY and op not in _BINARY:
        raise VmError(f"{where}:{number}: unknown op '{printable(op, 40)}' (known: {', '.join(OPS)})")
    _arity(op, args, 1 if op in _UNARY else 2, where, number)
    operands = []
    for arg in args:
        if arg not in names:
            raise VmError(f"{where}:{number}: '{printable(arg, 40)}' is not defined before its use")
        operands.append(names[arg])
    if op == "neg":
        return tape.neg(operands[0])
    if op == "square":
        return tape.powi(operands[0], 2)
    if op in _UNARY:
        return tape.unary(_UNARY[op] or op, operands[0])
    a, b = operands
    if op in ("add", "sub", "mul", "div"):
        return getattr(tape, op)(a, b)
    return tape.node(op, (a, b))


def _arity(op, args, expected, where, number):
    if len(args) != expected:
        raise VmError(f"{where}:{number}: {op} takes {expected} argument{'s' * (expected != 1)}, got {len(args)}")
