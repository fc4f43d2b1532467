"""The tape engine's per-region simplification: the program one box's descendants run.

``tape_simplify(program, length, output, choices, lane, out, need, stamp, mark, remap, out_output, zero) -> length'``
(internal): given the choices ``tape_interval`` wrote for box ``lane``, every Min/Max whose choice was
decided becomes an alias of its winning operand (a select: of the branch its condition takes), and every
instruction that only fed the losing one is dropped; the new program's output slot goes to ``out_output``.
Where that leaves an operand the exact zero constant (slot ``zero``, -1: none), an operation that keeps 0
(:data:`~implc.engines.tape.program.ZERO_KEEPING`) becomes an alias of it, and a sum of it and x an alias of x
(:data:`~implc.engines.tape.program.ALIASING_SUMS`): a blend's terms decided 0 far from their blobs cost nothing,
not a scale, a negation and a sum each.
Its variant ``tape_simplify_substituting(..., substituted)`` also makes a watched sum whose exponential term
was negligible over the box read the constant [0, 2^-e] that encloses it there
(:data:`implc.engines.tape.program.TINY_EXPONENTS`), so that what only fed the term is dropped too, and sets
``*substituted`` to 1 where it did: the program encloses F below the box (the term's value at every point of
it lies in the constant) but its partials are not F's (those of a family F_t, t the constant: enough for the
second look's proofs, not for normals, docs/soundness.md); its sums are plain (nothing below simplifies it
again).

Two passes, both linear in the program: backward from the output, marking what the result needs
(``need``, one int32 per slot: a slot is needed when it holds this call's ``stamp``, so nothing is cleared
between calls; slots are shared by values whose lives do not overlap, so a needed instruction clears its
slot's stamp before it marks its operands: what the slot held before is needed only if read after that)
and what each instruction becomes (``mark``: dropped, kept, or an alias of its first or
second value operand); forward, writing the kept instructions with their operands renamed through the
aliases (``remap``, one int32 per slot; constants and coordinates, which no instruction writes, name
themselves: :func:`~implc.engines.tape.interpreter_native.emit_tape_prefill` sets them). Kept instructions keep their
slots, so constants and the interval rules see exactly what they saw in the full program. Below the box
the result encloses F (a decided choice holds at every point of the box), and it equals the full
program's wherever the interval rules are inclusion-monotone (docs/soundness.md).
"""

from __future__ import annotations

import functools

from llvmlite import ir

from ...compiler.llvm.control import I32, I64, Local, const, define_internal, for_range, if_, load_at, store_at
from ...native import abi
from .interpreter_native import I8, LANES
from .program import ALIASING_SUMS, FIRST_BINARY, FIRST_TERNARY, OPCODES, ZERO_KEEPING

DROP, KEEP, ALIAS_FIRST, ALIAS_SECOND, SUBSTITUTE = 0, 1, 2, 3, 4
_P = ir.PointerType


def emit_tape_simplify(module: ir.Module, substitute: bool = False) -> ir.Function:
    """Define ``tape_simplify`` (see the module docstring) in ``module``; with ``substitute``, the variant
    that also replaces negligible terms (``implc.tape.simplify_substituting``, the same arguments and
    ``substituted``): a plain simplification does no work for them."""
    arguments = [_P(I32), I64, I64, _P(I8), I64, _P(I32), _P(I32), I32, _P(I8), _P(I32), _P(I64), I64]
    fn, b = define_internal(module, "implc.tape.simplify_substituting" if substitute else "implc.tape.simplify", I64,
                            arguments + ([_P(I64)] if substitute else []))
    program, length, output, choices, lane, out, need, stamp, mark, remap, out_output, zero = fn.args[:12]
    if substitute:
        substituted = fn.args[12]
        b.store(const(I64, 0), substituted)

    def choice_byte(i):
        return load_at(b, choices, b.add(b.mul(i, const(I64, LANES)), lane))

    def watched(code):
        return _is(b, code, ("add_watched", "add_nonneg_watched"))

    def field(i, k):
        return b.zext(load_at(b, program, b.add(b.mul(i, const(I64, abi.INSTRUCTION_WORDS)), const(I64, k))), I64)

    def fields(i):
        """The instruction's opcode, its slots, and its first word's bits above the opcode (kept as they are
        where it is written: a value independent of an axis stays so below the box)."""
        first = field(i, 0)
        return (b.and_(first, const(I64, abi.OPCODE_MASK)), *(field(i, f) for f in range(1, 5)),
                b.and_(first, const(I64, ~abi.OPCODE_MASK)))

    def need_operands(code, a, c, d, ternary):
        store_at(b, stamp, need, a)
        with if_(b, b.icmp_unsigned(">=", code, const(I64, FIRST_BINARY))):
            store_at(b, stamp, need, c)
        with if_(b, ternary):
            store_at(b, stamp, need, d)

    store_at(b, stamp, need, output)
    last = b.sub(length, const(I64, 1))

    with for_range(b, length) as k:  # backward: i = length - 1 - k
        i = b.sub(last, k)
        code, out_slot, a, c, d, _ = fields(i)
        ternary = b.icmp_unsigned(">=", code, const(I64, FIRST_TERNARY))
        first, second = b.select(ternary, c, a), b.select(ternary, d, c)  # the value operands a choice picks from
        store_at(b, const(I8, DROP), mark, i)
        with if_(b, b.icmp_unsigned("==", load_at(b, need, out_slot), stamp)):
            store_at(b, const(I32, 0), need, out_slot)  # what the slot held before this one wrote it: not yet
            is_choice = b.or_(ternary, b.or_(b.icmp_unsigned("==", code, const(I64, OPCODES["min"])),
                                             b.icmp_unsigned("==", code, const(I64, OPCODES["max"]))))
            choice = b.select(is_choice, choice_byte(i), const(I8, 3))
            with b.if_else(b.icmp_unsigned("==", choice, const(I8, 3))) as (both, one):
                with both:
                    if substitute:
                        tiny = Local(b, I8, const(I8, 0), "tiny")
                        with if_(b, watched(code)):
                            tiny.set(choice_byte(i))
                        with b.if_else(b.icmp_unsigned("!=", tiny.get(), const(I8, 0))) as (negligible, kept):
                            with negligible:  # the sum reads a constant for its exponential term: not the term
                                store_at(b, const(I8, SUBSTITUTE), mark, i)
                                kept_operand = b.select(b.icmp_unsigned(">=", tiny.get(), const(I8, 64)), a, c)
                                store_at(b, stamp, need, kept_operand)
                            with kept:
                                store_at(b, const(I8, KEEP), mark, i)
                                need_operands(code, a, c, d, ternary)
                    else:
                        store_at(b, const(I8, KEEP), mark, i)
                        need_operands(code, a, c, d, ternary)
                with one:
                    picks_first = b.icmp_unsigned("==", choice, const(I8, 1))
                    store_at(b, b.select(picks_first, const(I8, ALIAS_FIRST), const(I8, ALIAS_SECOND)), mark, i)
                    store_at(b, stamp, need, b.select(picks_first, first, second))

    def plain(code):
        """A watched sum's code as a plain sum's: a substituting call's output is only ever enclosed."""
        if not substitute:
            return code
        return b.select(b.icmp_unsigned("==", code, const(I64, OPCODES["add_watched"])), const(I64, OPCODES["add"]),
                        b.select(b.icmp_unsigned("==", code, const(I64, OPCODES["add_nonneg_watched"])),
                                 const(I64, OPCODES["add_nonneg"]), code))

    count = Local(b, I64, 0, "count")

    def write(code, out_slot, operands, high):
        """Append an instruction (``operands``: its last three words, already renamed; ``high``: its first
        word's bits above the opcode); its value is named by its own slot from here on."""
        row = b.mul(count.get(), const(I64, abi.INSTRUCTION_WORDS))
        for k, word in enumerate([b.trunc(b.or_(plain(code), high), I32), b.trunc(out_slot, I32), *operands]):
            store_at(b, word, out, b.add(row, const(I64, k)))
        store_at(b, b.trunc(out_slot, I32), remap, out_slot)
        count.set(b.add(count.get(), const(I64, 1)))

    with for_range(b, length) as i:  # forward: write what is kept, operands renamed through the aliases
        m = load_at(b, mark, i)
        code, out_slot, a, c, d, high = fields(i)
        ternary = b.icmp_unsigned(">=", code, const(I64, FIRST_TERNARY))
        with if_(b, b.icmp_unsigned("==", m, const(I8, KEEP))):
            binary = b.icmp_unsigned(">=", code, const(I64, FIRST_BINARY))
            first, second = load_at(b, remap, a), b.select(binary, load_at(b, remap, c), b.trunc(c, I32))
            # an exact 0 kept by its operation, or a sum with an exact 0 term: no instruction, its value named
            zero_slot = b.trunc(zero, I32)
            first_zero = b.icmp_signed("==", first, zero_slot)
            second_zero = b.and_(binary, b.icmp_signed("==", second, zero_slot))
            stays_zero = b.and_(first_zero, _is(b, code, ZERO_KEEPING))
            to_first = b.and_(second_zero, _is(b, code, ALIASING_SUMS))
            to_second = b.and_(first_zero, _is(b, code, ("add", "add_watched")))
            named = b.select(stays_zero, zero_slot, b.select(to_first, first, second))
            with b.if_else(b.or_(stays_zero, b.or_(to_first, to_second))) as (alias, kept):
                with alias:
                    store_at(b, named, remap, out_slot)
                with kept:
                    # a substituting call's sums watch nothing: what it writes is only enclosed, never simplified
                    fourth = const(I32, 0) if substitute else b.trunc(d, I32)
                    write(code, out_slot, [first, second, b.select(ternary, load_at(b, remap, d), fourth)], high)
        if substitute:
            with if_(b, b.icmp_unsigned("==", m, const(I8, SUBSTITUTE))):
                tiny = choice_byte(i)
                second_operand = b.icmp_unsigned(">=", tiny, const(I8, 64))
                constant = b.zext(b.sub(b.and_(tiny, const(I8, 63)), const(I8, 1)), I32)  # its slot: its index
                write(code, out_slot, [b.select(second_operand, load_at(b, remap, a), constant),
                                       b.select(second_operand, constant, load_at(b, remap, c)), const(I32, 0)],
                      high)
                b.store(const(I64, 1), substituted)
        with if_(b, b.icmp_unsigned("==", m, const(I8, ALIAS_FIRST))):
            store_at(b, load_at(b, remap, b.select(ternary, c, a)), remap, out_slot)
        with if_(b, b.icmp_unsigned("==", m, const(I8, ALIAS_SECOND))):
            store_at(b, load_at(b, remap, b.select(ternary, d, c)), remap, out_slot)
    b.store(b.sext(load_at(b, remap, output), I64), out_output)
    b.ret(count.get())
    return fn


def _is(b: ir.IRBuilder, code, names) -> ir.Value:
    """An i1: ``code`` (an i64) is the opcode of one of ``names``."""
    return functools.reduce(b.or_, [b.icmp_unsigned("==", code, const(I64, OPCODES[name])) for name in names])


def call_simplify(b: ir.IRBuilder, simplify: tuple, arguments: list, substituted, substituting):
    """Call ``tape_simplify`` with ``arguments``, or where ``substituting`` (i1) holds its substituting
    variant (``simplify``: the two functions, as :func:`emit_tape_simplify` defines them; ``substituted``: the
    i64 the variant sets): the simplified program's length (i64)."""
    plain, substituting_variant = simplify
    length = Local(b, I64, const(I64, 0), "simplified_length")
    with b.if_else(substituting) as (replacing, keeping):
        with replacing:
            length.set(b.call(substituting_variant, arguments + [substituted]))
        with keeping:
            length.set(b.call(plain, arguments))
    return length.get()
