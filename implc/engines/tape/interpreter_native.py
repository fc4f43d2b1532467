"""The tape engine's evaluators: one native interpreter for every :class:`~implc.engines.tape.program.TapeProgram`.

Internal functions of the tape-engine module; the interpreters loop over a program's instructions with a
switch on the opcode, eight lanes (the eight children of an octant, or eight points) per instruction:

- ``tape_prefill(header, slots, remap)``: the constants into their interval and dual-number slots, and
  (``remap`` not NULL) each constant's and coordinate's slot as its own name for ``tape_simplify``.
- ``tape_interval(header, instructions, length, output, slots, choices, box, result) -> i8``: the
  enclosure of F over eight boxes (six vectors of eight: lo x, y, z, hi x, y, z), by the same interval
  rules as the compiled kernels (:class:`~implc.compiler.llvm.interval_rules.IntervalEmitter`, rule for rule),
  into ``result`` (lo, hi). For each Min/Max instruction at position p it writes eight choice bytes at
  ``choices[8p..]`` (bit 0: operand a may be the result over that box, bit 1: b may; NaN decides
  nothing) and returns the lanes in which some choice was decided (bit c: box c); for each sum of an
  exponential, bytes saying in which lanes that term is negligible
  (:data:`~implc.engines.tape.program.TINY_EXPONENTS`: its ``add_watched`` or ``add_nonneg_watched``), and those lanes
  in the returned i16's upper byte.
- ``tape_dual(header, instructions, length, output, slots, points, result)``: F and its gradient at eight
  points (three vectors), forward mode (value and three partials per slot), into ``result`` (value, dx,
  dy, dz): for normals.
- ``tape_point(header, instructions, length, output, slots, points, result)``: F alone at eight points, by
  ``tape_dual``'s value rules: for sampling (the mesher's).
- ``tape_box_gradient(header, instructions, length, output, slots, box, result, seeds)``: enclosures of F
  and of its three partials over eight boxes (as ``tape_interval``'s), forward mode with the interval rules
  (an interval and three interval partials per slot), into ``result`` (eight vectors: F's lo, hi, then
  each partial's lo, hi). Where a Min/Max may take either operand its partial is the hull of both (the
  generalized gradient of a kink); an undecided select's is NaN (it may jump); NaN stays NaN. For the
  monotonicity test of :mod:`.tape_tighten`. ``seeds`` not NULL: the derivatives along three directions
  instead of the axes (9 doubles: direction k's x, y, z at 3k), each with its own hull at a kink (where
  both sides of a crease rise along a diagonal, that derivative's enclosure excludes 0 while every
  partial's straddles it).

In both forward modes a value's partial (or derivative along a direction) is 0 exactly where the value
does not depend on the axes (the direction moves along), as the instruction's first word says
(:attr:`implc.engines.tape.program.TapeProgram.zeros`): as the gradient tape has it, not the rule's NaN where it
would multiply that 0 by an infinity.

``header`` is the full program's (:data:`implc.native.abi.PROGRAM_WORDS`); ``instructions``, ``length`` and
``output`` those of the program to run (the full one, or one simplified from it). ``slots``: the scratch
of :func:`implc.engines.tape.program.slot_scratch` (interval slots, then dual-number slots, then interval-gradient
slots).
"""

from __future__ import annotations

from llvmlite import ir

from ...compiler.llvm import elementary
from ...compiler.llvm.control import (
    I32,
    I64,
    Local,
    const,
    define_internal,
    for_range,
    if_,
    load_at,
    local_array,
    store_at,
)
from ...compiler.llvm.interval_rules import IntervalEmitter
from ...compiler.llvm.vector import DOUBLE, VectorBuilder, broadcast
from ...native import abi
from .program import NEGLIGIBLE, OPCODES, TINY_EXPONENTS

LANES = 8
I8, I16 = ir.IntType(8), ir.IntType(16)
SUMS = ("add", "add_nonneg", "add_watched", "add_nonneg_watched")
_TINY_FIRST, _TINY_LAST = TINY_EXPONENTS[0] // 2, TINY_EXPONENTS[-1] // 2
assert TINY_EXPONENTS == tuple(range(2 * _TINY_FIRST, 2 * _TINY_LAST + 1, 2)) and len(TINY_EXPONENTS) < 64
V8 = ir.VectorType(DOUBLE, LANES)
_P = ir.PointerType


def _instruction_loop(b: ir.IRBuilder, program, length, cases, zeros: bool = False):
    """``for each instruction: cases[op](i, out, a, b, c)``, dispatched threaded: every case ends with its
    own jump to the next instruction's case (an indirect branch through a table of the cases' addresses),
    so the branch predictor learns which opcode follows which (a program's sequence repeats at every
    octant) instead of guessing every opcode at one shared switch. Every case's emitter runs with the
    builder in its own block; an opcode without a case is skipped. With ``zeros``, each case also gets the
    axes the instruction's value does not depend on (an i64, bit k: axis k; the first word's bits above
    :data:`implc.native.abi.OPCODE_BITS`)."""
    fn = b.function
    pc = Local(b, I64, 0, "pc")
    finished = fn.append_basic_block("ops.finished")
    skip = fn.append_basic_block("op.skip")
    blocks = {name: fn.append_basic_block(f"op.{name}") for name in cases}
    codes = max(OPCODES.values()) + 1
    targets = [skip] * (codes + 1)  # the last: any code beyond the opcodes
    for name, block in blocks.items():
        targets[OPCODES[name]] = block
    address = ir.PointerType(I8)
    table = ir.GlobalVariable(b.module, ir.ArrayType(address, codes + 1), name=f"{fn.name}.dispatch")
    table.initializer = ir.Constant(ir.ArrayType(address, codes + 1), [ir.BlockAddress(fn, t) for t in targets])
    table.global_constant, table.linkage = True, "internal"

    def row_of(i):
        return b.gep(program, [b.mul(i, ir.Constant(I64, abi.INSTRUCTION_WORDS))], inbounds=True)

    def dispatch():
        i = pc.get()
        go = fn.append_basic_block("op.next")
        b.cbranch(b.icmp_signed("<", i, length), go, finished)
        b.position_at_end(go)
        code = b.and_(b.zext(b.load(row_of(i)), I64), ir.Constant(I64, abi.OPCODE_MASK))
        code = b.select(b.icmp_unsigned("<", code, ir.Constant(I64, codes)), code, ir.Constant(I64, codes))
        jump = b.branch_indirect(b.load(b.gep(table, [ir.Constant(I64, 0), code], inbounds=True)))
        for target in (*blocks.values(), skip):
            jump.add_destination(target)

    dispatch()
    for name, emit in cases.items():
        b.position_at_end(blocks[name])
        i = pc.get()
        row = row_of(i)
        fields = b.load(b.bitcast(row, _P(ir.VectorType(I32, 4))), align=4)
        first, out, a, c = [b.zext(b.extract_element(fields, ir.Constant(I32, k)), I64) for k in range(4)]
        d = b.zext(b.load(b.gep(row, [ir.Constant(I64, 4)])), I64)
        if zeros:
            emit(i, out, a, c, d, b.lshr(first, ir.Constant(I64, abi.OPCODE_BITS)))
        else:
            emit(i, out, a, c, d)
        pc.set(b.add(i, ir.Constant(I64, 1)))
        dispatch()
    b.position_at_end(skip)
    pc.set(b.add(pc.get(), ir.Constant(I64, 1)))
    dispatch()
    b.position_at_end(finished)


def _zero_partials(module: ir.Module, vectors: int, name: str) -> ir.Function:
    """``name(slots, slot, zeros, supports)`` (internal, out of line: called only for the values that ignore
    some axis): in slot ``slot`` of ``vectors`` vectors (the value's, then each partial's: one vector each
    in 4, a (lo, hi) pair each in 8), the partials along each direction k that moves only along axes the
    value does not depend on (``supports`` bits 3k..3k+2: the axes direction k moves along; ``zeros``: the
    axes the value ignores) set to 0."""
    fn, b = define_internal(module, name, ir.VoidType(), [_P(V8), I64, I64, I64])
    fn.attributes.add("noinline")
    slots, slot, zeros, supports = fn.args
    width = vectors // 4  # vectors per partial, after the value's as many
    base = b.mul(slot, ir.Constant(I64, vectors))
    ignored = b.xor(zeros, ir.Constant(I64, -1))
    for k in range(3):
        moves = b.and_(b.lshr(supports, ir.Constant(I64, 3 * k)), ir.Constant(I64, 0b111))
        with if_(b, b.icmp_unsigned("==", b.and_(moves, ignored), ir.Constant(I64, 0))):
            for w in range(width):
                b.store(ir.Constant(V8, [0.0] * LANES),
                        b.gep(slots, [b.add(base, ir.Constant(I64, width * (k + 1) + w))], inbounds=True), align=8)
    b.ret_void()
    return fn


def _header(b, header, word):
    return load_at(b, header, word)


def dual_slots(b: ir.IRBuilder, header, slots):
    """Where the dual-number slots start: after the interval slots (16 doubles per slot)."""
    return b.gep(slots, [b.mul(_header(b, header, abi.PROGRAM_SLOT_COUNT), ir.Constant(I64, 2 * LANES))])


def box_gradient_slots(b: ir.IRBuilder, header, slots):
    """Where the interval-gradient slots start (64 doubles each): after the dual-number slots (32 each)."""
    return b.gep(slots, [b.mul(_header(b, header, abi.PROGRAM_SLOT_COUNT), ir.Constant(I64, 6 * LANES))])


def emit_tape_prefill(module: ir.Module) -> ir.Function:
    """Define ``tape_prefill`` (see the module docstring) in ``module``."""
    fn, b = define_internal(module, "implc.tape.prefill", ir.VoidType(), [_P(I64), _P(DOUBLE), _P(I32)])
    header, slots, remap = fn.args
    constants = b.inttoptr(_header(b, header, abi.PROGRAM_CONSTANTS), _P(DOUBLE))
    constant_slots = b.inttoptr(_header(b, header, abi.PROGRAM_CONSTANT_SLOTS), _P(I32))
    vslots, vdual = b.bitcast(slots, _P(V8)), b.bitcast(dual_slots(b, header, slots), _P(V8))
    vgrad = b.bitcast(box_gradient_slots(b, header, slots), _P(V8))
    has_remap = b.icmp_unsigned("!=", remap, ir.Constant(_P(I32), None))
    zero = ir.Constant(V8, [0.0] * LANES)
    with for_range(b, _header(b, header, abi.PROGRAM_CONSTANT_COUNT)) as k:
        slot = b.sext(load_at(b, constant_slots, k), I64)
        row = b.mul(k, ir.Constant(I64, 3))
        nearest, lo, hi = (broadcast(b, load_at(b, constants, b.add(row, ir.Constant(I64, c))), LANES)
                           for c in range(3))
        b.store(lo, b.gep(vslots, [b.mul(slot, ir.Constant(I64, 2))]), align=8)
        b.store(hi, b.gep(vslots, [b.add(b.mul(slot, ir.Constant(I64, 2)), ir.Constant(I64, 1))]), align=8)
        for c, value in enumerate((nearest, zero, zero, zero)):
            b.store(value, b.gep(vdual, [b.add(b.mul(slot, ir.Constant(I64, 4)), ir.Constant(I64, c))]), align=8)
        for c, value in enumerate((lo, hi) + (zero,) * 6):
            b.store(value, b.gep(vgrad, [b.add(b.mul(slot, ir.Constant(I64, 8)), ir.Constant(I64, c))]), align=8)
        with if_(b, has_remap):
            store_at(b, b.trunc(slot, I32), remap, slot)
    for a in range(3):
        slot = _header(b, header, abi.PROGRAM_VARIABLES + a)
        with if_(b, b.and_(has_remap, b.icmp_signed(">=", slot, ir.Constant(I64, 0)))):
            store_at(b, b.trunc(slot, I32), remap, slot)
    b.ret_void()
    return fn


def _variables(b, header, store):
    """``store(axis, slot)`` for each coordinate the program uses."""
    for a in range(3):
        slot = _header(b, header, abi.PROGRAM_VARIABLES + a)
        with if_(b, b.icmp_signed(">=", slot, ir.Constant(I64, 0))):
            store(a, slot)


def interval_findings(b: ir.IRBuilder, found):
    """What ``tape_interval`` returned (i16), split: the lanes with a choice decided, those with a
    negligible term (two i8 masks)."""
    return b.trunc(found, I8), b.trunc(b.lshr(found, ir.Constant(found.type, 8)), I8)


def emit_tape_interval(module: ir.Module, directed: bool) -> ir.Function:
    """Define ``tape_interval`` (see the module docstring) in ``module``."""
    fn, b = define_internal(module, "implc.tape.interval", I16,
                            [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(I8), _P(DOUBLE), _P(DOUBLE)])
    header, program, length, output, slots, choices, box, result = fn.args
    vb = VectorBuilder(b, LANES, directed, outline_elementary=True)  # their constants stay in their functions
    em = IntervalEmitter(vb)
    vslots, vbox = b.bitcast(slots, _P(V8)), b.bitcast(box, _P(V8))
    decided = Local(b, I8, 0, "decided")
    negligible = Local(b, I8, 0, "negligible")

    def load(slot):
        base = b.mul(slot, ir.Constant(I64, 2))
        return (b.load(b.gep(vslots, [base], inbounds=True), align=8),
                b.load(b.gep(vslots, [b.add(base, ir.Constant(I64, 1))], inbounds=True), align=8))

    def store(slot, pair):
        base = b.mul(slot, ir.Constant(I64, 2))
        b.store(pair[0], b.gep(vslots, [base], inbounds=True), align=8)
        b.store(pair[1], b.gep(vslots, [b.add(base, ir.Constant(I64, 1))], inbounds=True), align=8)

    _variables(b, header, lambda a, slot: store(slot, (b.load(b.gep(vbox, [ir.Constant(I64, a)]), align=8),
                                                        b.load(b.gep(vbox, [ir.Constant(I64, 3 + a)]), align=8))))

    def unary(rule, attr=None):
        return lambda i, out, a, c, d: store(out, rule([load(a)], attr))

    def binary(rule, attr=None):
        return lambda i, out, a, c, d: store(out, rule([load(a), load(c)], attr))

    def choice(op):
        def emit(i, out, a, c, d):
            zero = vb.splat(0.0)
            if op in ("min", "max"):
                x, y = load(a), load(c)
                store(out, (em.i_min if op == "min" else em.i_max)([x, y], None))
            if op == "min":  # x is the minimum wherever x <= y throughout: x.hi <= y.lo
                x_only, y_only = vb.cmp("<=", x[1], y[0]), vb.cmp("<=", y[1], x[0])
            elif op == "max":
                x_only, y_only = vb.cmp(">=", x[0], y[1]), vb.cmp(">=", y[0], x[1])
            else:  # a select: the branch its condition takes over the whole box (never where it may be NaN)
                g = load(a)
                store(out, getattr(em, f"i_{op}")([g, load(c), load(d)], None))
                strict = op == "select_lt"
                x_only = vb.cmp("<" if strict else "<=", g[1], zero)
                y_only = vb.cmp(">=" if strict else ">", g[0], zero)
            y_only = b.and_(y_only, b.not_(x_only))
            vi8 = ir.VectorType(I8, LANES)
            bits = b.select(x_only, ir.Constant(vi8, [1] * LANES),
                            b.select(y_only, ir.Constant(vi8, [2] * LANES), ir.Constant(vi8, [3] * LANES)))
            b.store(bits, b.bitcast(b.gep(choices, [b.mul(i, ir.Constant(I64, LANES))], inbounds=True), _P(vi8)),
                    align=1)
            decided.set(b.or_(decided.get(), b.bitcast(b.or_(x_only, y_only), I8)))
        return emit

    vi64, vi8 = ir.VectorType(I64, LANES), ir.VectorType(I8, LANES)

    def splat_int(vtype, value):
        return ir.Constant(vtype, [value] * LANES)

    def tiny(term, limit):
        """Whether ``term`` (an exponential's enclosure) lies in [0, 2^-e] with 2^-e <= ``limit`` for an
        e of :data:`TINY_EXPONENTS` (i1 vector), and the byte naming the constant (index + 1)."""
        field = b.lshr(b.bitcast(term[1], vi64), splat_int(vi64, 52))  # a sign bit set makes it 2048 or more
        q = b.ashr(b.sub(splat_int(vi64, 1022), field), splat_int(vi64, 1))  # term <= 2^-m <= 2^-2q, m = 1022 - field
        q = b.select(b.icmp_signed(">", q, splat_int(vi64, _TINY_LAST)), splat_int(vi64, _TINY_LAST), q)
        bound = b.bitcast(b.shl(b.sub(splat_int(vi64, 1023), b.shl(q, splat_int(vi64, 1))), splat_int(vi64, 52)), V8)
        ok = b.and_(b.icmp_signed(">=", q, splat_int(vi64, _TINY_FIRST)),
                    b.and_(vb.cmp(">=", term[0], vb.splat(0.0)), vb.cmp("<=", bound, limit)))
        return ok, b.trunc(b.sub(q, splat_int(vi64, _TINY_FIRST - 1)), vi8)

    def watched_sum(nonnegative):
        """A sum whose third word marks an exponential operand: the choice bytes say in which lanes that
        operand is negligible (:data:`TINY_EXPONENTS`; 0: in none): the constant's index + 1, plus 64 where
        it is the second operand."""
        def emit(i, out, a, c, d):
            x, y = load(a), load(c)
            lo, hi = em.i_add([x, y], nonnegative)
            store(out, (lo, hi))
            limit = vb.mul(vb.sub(hi, lo), vb.splat(NEGLIGIBLE))
            first_ok, first_byte = tiny(x, limit)
            second_ok, second_byte = tiny(y, limit)
            none = ir.Constant(first_ok.type, [0] * LANES)
            first_ok = b.select(b.icmp_unsigned("!=", b.and_(d, ir.Constant(I64, 1)), ir.Constant(I64, 0)),
                                first_ok, none)
            second_ok = b.select(b.icmp_unsigned("!=", b.and_(d, ir.Constant(I64, 2)), ir.Constant(I64, 0)),
                                 second_ok, none)
            bytes_ = b.select(first_ok, first_byte, b.select(second_ok, b.add(second_byte, splat_int(vi8, 64)),
                                                             splat_int(vi8, 0)))
            b.store(bytes_, b.bitcast(b.gep(choices, [b.mul(i, ir.Constant(I64, LANES))], inbounds=True), _P(vi8)),
                    align=1)
            negligible.set(b.or_(negligible.get(), b.bitcast(b.or_(first_ok, second_ok), I8)))
        return emit

    cases = {"neg": unary(em.i_neg), "abs": unary(em.i_abs), "sqrt": unary(em.i_sqrt), "exp": unary(em.i_exp),
             "log": unary(em.i_log), "sin": unary(em.i_sin), "cos": unary(em.i_cos),
             "square": unary(em.i_powi, 2), "cube": unary(em.i_powi, 3), "fourth": unary(em.i_powi, 4),
             "add": binary(em.i_add, False), "add_nonneg": binary(em.i_add, True),
             "add_watched": watched_sum(False), "add_nonneg_watched": watched_sum(True), "sub": binary(em.i_sub),
             "mul": binary(em.i_mul), "div": binary(em.i_div), "mul_const": binary(em.i_mul_const),
             "div_const": binary(em.i_div_const), "min": choice("min"), "max": choice("max"),
             "select_lt": choice("select_lt"), "select_le": choice("select_le")}
    assert set(cases) == set(OPCODES), "every opcode has an interval case"
    _instruction_loop(b, program, length, cases)
    lo, hi = load(output)
    vresult = b.bitcast(result, _P(V8))
    b.store(lo, vresult, align=8)
    b.store(hi, b.gep(vresult, [ir.Constant(I64, 1)]), align=8)
    b.ret(b.or_(b.zext(decided.get(), I16), b.shl(b.zext(negligible.get(), I16), ir.Constant(I16, 8))))
    return fn


def emit_tape_dual(module: ir.Module, partials: bool = True) -> ir.Function:
    """Define ``tape_dual`` (see the module docstring) in ``module``; with ``partials=False``, ``tape_point``:
    the same value rules without the partials (F alone at eight points into ``result``), for sampling."""
    fn, b = define_internal(module, "implc.tape.dual" if partials else "implc.tape.point", ir.VoidType(),
                            [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(DOUBLE), _P(DOUBLE)])
    header, program, length, output, slots, points, result = fn.args
    vb = VectorBuilder(b, LANES, outline_elementary=True)
    vslots, vpoints = b.bitcast(dual_slots(b, header, slots), _P(V8)), b.bitcast(points, _P(V8))
    zero, one = vb.splat(0.0), vb.splat(1.0)
    width = 4 if partials else 1  # vectors used per slot (of four: the value, then its partials)

    def load(slot):  # the slots as tape_prefill lays them out: four vectors each, the constants' value first
        base = b.mul(slot, ir.Constant(I64, 4))
        return [b.load(b.gep(vslots, [b.add(base, ir.Constant(I64, k))], inbounds=True), align=8)
                for k in range(width)]

    def store(slot, dual):
        base = b.mul(slot, ir.Constant(I64, 4))
        for k, value in enumerate(dual):
            b.store(value, b.gep(vslots, [b.add(base, ir.Constant(I64, k))], inbounds=True), align=8)

    def chain(value, scale, x):
        """The dual number of f(x) with f(x) = value and f'(x) = scale."""
        return [value] + [vb.mul(scale, d) for d in x[1:]]

    _variables(b, header, lambda a, slot: store(slot, [b.load(b.gep(vpoints, [ir.Constant(I64, a)]), align=8)]
                                                 + [one if k == a else zero for k in range(width - 1)]))

    clear = _zero_partials(module, 4, "implc.tape.dual_zeros") if partials else None

    def store_zeroed(slot, dual, zeros):
        """Store ``dual``, then make 0 its partials along the axes the value does not depend on (bits of
        ``zeros``; most values depend on every axis: a branch around a call)."""
        store(slot, dual)
        if clear is not None:
            with if_(b, b.icmp_unsigned("!=", zeros, ir.Constant(I64, 0))):
                b.call(clear, [vslots, slot, zeros, ir.Constant(I64, 0b100_010_001)])

    def unary(rule):
        def emit(i, out, a, c, d, zeros):
            store_zeroed(out, rule(load(a)), zeros)
        return emit

    def binary(rule):
        def emit(i, out, a, c, d, zeros):
            store_zeroed(out, rule(load(a), load(c)), zeros)
        return emit

    def select(op):
        def emit(i, out, a, c, d, zeros):  # the branch the condition takes at the point; NaN where it is NaN
            g, t, f = load(a), load(c), load(d)
            taken = vb.cmp("<" if op == "select_lt" else "<=", g[0], zero)
            undefined = vb.isnan(g[0])
            store_zeroed(out, [vb.select(undefined, vb.splat(float("nan")), vb.select(taken, p, q))
                               for p, q in zip(t, f)], zeros)
        return emit

    def sqrt(x):
        s = vb.sqrt(x[0])
        return chain(s, vb.div(vb.splat(0.5), s), x)

    def exp(x):
        e = elementary.exp(vb, x[0])
        return chain(e, e, x)

    def power(n):
        def rule(x):
            square = vb.mul(x[0], x[0])
            value = {2: square, 3: vb.mul(square, x[0]), 4: vb.mul(square, square)}[n]
            below = {2: x[0], 3: square, 4: vb.mul(square, x[0])}[n]
            return chain(value, vb.mul(vb.splat(float(n)), below), x)
        return rule

    def pick(op):
        def rule(x, y):
            # ties as the gradient tape breaks them (implc.compiler.gradient): min takes a, max takes b
            first = vb.cmp("<=", x[0], y[0]) if op == "min" else vb.cmp(">", x[0], y[0])
            either_nan = vb.or_(vb.isnan(x[0]), vb.isnan(y[0]))
            value = vb.minimum(x[0], y[0]) if op == "min" else vb.maximum(x[0], y[0])
            return [value] + [vb.select(either_nan, vb.splat(float("nan")), vb.select(first, dx, dy))
                              for dx, dy in zip(x[1:], y[1:])]
        return rule

    def mul(x, y):
        return [vb.mul(x[0], y[0])] + [vb.add(vb.mul(x[0], dy), vb.mul(y[0], dx)) for dx, dy in zip(x[1:], y[1:])]

    def div(x, y):
        q = vb.div(x[0], y[0])
        return [q] + [vb.div(vb.sub(dx, vb.mul(q, dy)), y[0]) for dx, dy in zip(x[1:], y[1:])]

    cases = {"neg": unary(lambda x: [vb.neg(v) for v in x]),
             "abs": unary(lambda x: chain(vb.fabs(x[0]), vb.copysign(one, x[0]), x)),
             "sqrt": unary(sqrt), "exp": unary(exp),
             "log": unary(lambda x: chain(elementary.log(vb, x[0]), vb.div(one, x[0]), x)),
             "sin": unary(lambda x: chain(elementary.sin(vb, x[0]), elementary.cos(vb, x[0]), x)),
             "cos": unary(lambda x: chain(elementary.cos(vb, x[0]), vb.neg(elementary.sin(vb, x[0])), x)),
             "square": unary(power(2)), "cube": unary(power(3)), "fourth": unary(power(4)),
             **{name: binary(lambda x, y: [vb.add(p, q) for p, q in zip(x, y)]) for name in SUMS},
             "sub": binary(lambda x, y: [vb.sub(p, q) for p, q in zip(x, y)]),
             "mul": binary(mul), "div": binary(div),
             "mul_const": binary(lambda x, c: [vb.mul(p, c[0]) for p in x]),  # c's partials are 0
             "div_const": binary(lambda x, c: [vb.div(p, c[0]) for p in x]),
             "min": binary(pick("min")), "max": binary(pick("max")),
             "select_lt": select("select_lt"), "select_le": select("select_le")}
    assert set(cases) == set(OPCODES), "every opcode has a dual-number case"
    _instruction_loop(b, program, length, cases, zeros=True)
    dual = load(output)
    vresult = b.bitcast(result, _P(V8))
    for k, value in enumerate(dual):
        b.store(value, b.gep(vresult, [ir.Constant(I64, k)]), align=8)
    b.ret_void()
    return fn



def emit_tape_box_gradient(module: ir.Module, directed: bool) -> ir.Function:
    """Define ``tape_box_gradient`` (see the module docstring) in ``module``."""
    fn, b = define_internal(module, "implc.tape.box_gradient", ir.VoidType(),
                            [_P(I64), _P(I32), I64, I64, _P(DOUBLE), _P(DOUBLE), _P(DOUBLE), _P(DOUBLE)])
    header, program, length, output, slots, box, result, seeds = fn.args
    vb = VectorBuilder(b, LANES, directed, outline_elementary=True)
    em = IntervalEmitter(vb)
    vslots, vbox = b.bitcast(box_gradient_slots(b, header, slots), _P(V8)), b.bitcast(box, _P(V8))
    zero = vb.splat(0.0)

    def load(slot):
        """[F's (lo, hi), then each partial's (lo, hi)]."""
        base = b.mul(slot, ir.Constant(I64, 8))
        v = [b.load(b.gep(vslots, [b.add(base, ir.Constant(I64, k))], inbounds=True), align=8) for k in range(8)]
        return [(v[0], v[1]), (v[2], v[3]), (v[4], v[5]), (v[6], v[7])]

    def store(slot, pairs):
        base = b.mul(slot, ir.Constant(I64, 8))
        for k, value in enumerate(x for pair in pairs for x in pair):
            b.store(value, b.gep(vslots, [b.add(base, ir.Constant(I64, k))], inbounds=True), align=8)

    axes = local_array(b, DOUBLE, 9, "axes")  # the directions where ``seeds`` is NULL: the axes
    for k in range(3):
        for a in range(3):
            store_at(b, const(DOUBLE, 1.0 if k == a else 0.0), axes, const(I64, 3 * k + a))
    directions = b.select(b.icmp_unsigned("!=", seeds, ir.Constant(seeds.type, None)), seeds, axes)
    supports = ir.Constant(I64, 0)  # bits 3k..3k+2: the axes direction k moves along
    for k in range(3):
        for a in range(3):
            moves = b.fcmp_unordered("!=", load_at(b, directions, const(I64, 3 * k + a)), const(DOUBLE, 0.0))
            supports = b.or_(supports, b.select(moves, ir.Constant(I64, 1 << (3 * k + a)), ir.Constant(I64, 0)))
    clear = _zero_partials(module, 8, "implc.tape.box_gradient_zeros")

    def store_zeroed(slot, pairs, zeros):
        """Store ``pairs``, then make [0, 0] the partials along the directions that move only along axes the
        value does not depend on (bits of ``zeros``): the value is constant along them."""
        store(slot, pairs)
        with if_(b, b.icmp_unsigned("!=", zeros, ir.Constant(I64, 0))):
            b.call(clear, [vslots, slot, zeros, supports])

    def variable(a, slot):
        value = (b.load(b.gep(vbox, [ir.Constant(I64, a)]), align=8),
                 b.load(b.gep(vbox, [ir.Constant(I64, 3 + a)]), align=8))
        # the coordinate's derivative along direction k: component a of that direction
        along = [broadcast(b, load_at(b, directions, const(I64, 3 * k + a)), LANES) for k in range(3)]
        store(slot, [value] + [(d, d) for d in along])

    _variables(b, header, variable)

    def chain(value, scale, x):
        """f(x) with f(x) in ``value`` and f'(x) in ``scale`` over the box: the partials scale · ∂x."""
        return [value] + [em.i_mul([scale, d], None) for d in x[1:]]

    def hull(p, q):
        return vb.minimum(p[0], q[0]), vb.maximum(p[1], q[1])

    def unary(rule):
        return lambda i, out, a, c, d, zeros: store_zeroed(out, rule(load(a)), zeros)

    def binary(rule):
        return lambda i, out, a, c, d, zeros: store_zeroed(out, rule(load(a), load(c)), zeros)

    def power(n):
        def rule(x):
            below = x[0] if n == 2 else em.i_powi([x[0]], n - 1)
            return chain(em.i_powi([x[0]], n), em.i_scale([below], float(n)), x)
        return rule

    def exp(x):
        e = em.i_exp([x[0]], None)  # >= 0: one product per bound of each partial
        return [e] + [em.mul_signed(d, e, True) for d in x[1:]]

    def sqrt(x):
        s = em.i_sqrt([x[0]], None)
        return [s] + [em.i_div([d, em.i_scale([s], 2.0)], None) for d in x[1:]]

    def abs_(x):
        v = x[0]
        up, down = vb.cmp(">=", v[0], zero), vb.cmp("<=", v[1], zero)
        partials = []
        for d in x[1:]:
            negated = em.i_neg([d], None)
            either = hull(d, negated)
            partials.append(tuple(vb.select(up, p, vb.select(down, n, e)) for p, n, e in zip(d, negated, either)))
        return [em.i_abs([v], None)] + partials

    def pick(op):
        def rule(x, y):
            v, w = x[0], y[0]
            if op == "min":  # x is the minimum throughout where x.hi <= y.lo: its partials are F's
                value, x_only, y_only = em.i_min([v, w], None), vb.cmp("<=", v[1], w[0]), vb.cmp("<=", w[1], v[0])
            else:
                value, x_only, y_only = em.i_max([v, w], None), vb.cmp(">=", v[0], w[1]), vb.cmp(">=", w[0], v[1])
            partials = []
            for dx, dy in zip(x[1:], y[1:]):
                either = hull(dx, dy)
                partials.append(tuple(vb.select(x_only, p, vb.select(y_only, q, e)) for p, q, e in zip(dx, dy, either)))
            return [value] + partials
        return rule

    def select(op):
        def emit(i, out, a, c, d, zeros):
            g, t, f = load(a), load(c), load(d)
            rule = getattr(em, f"i_{op}")
            store_zeroed(out, [rule([g[0], t[0], f[0]], None)]
                         + [rule([g[0], p, q], "jump") for p, q in zip(t[1:], f[1:])], zeros)
        return emit

    def mul(x, y):
        return [em.i_mul([x[0], y[0]], None)] + [
            em.i_add([em.i_mul([x[0], dy], None), em.i_mul([y[0], dx], None)], False)
            for dx, dy in zip(x[1:], y[1:])]

    def div(x, y):
        q = em.i_div([x[0], y[0]], None)
        return [q] + [em.i_div([em.i_sub([dx, em.i_mul([q, dy], None)], None), y[0]], None)
                      for dx, dy in zip(x[1:], y[1:])]

    def add(nonnegative):
        return lambda x, y: [em.i_add([x[0], y[0]], nonnegative)] + [em.i_add([p, q], False)
                                                                      for p, q in zip(x[1:], y[1:])]

    cases = {"neg": unary(lambda x: [em.i_neg([p], None) for p in x]), "abs": unary(abs_),
             "sqrt": unary(sqrt),
             "exp": unary(exp),
             "log": unary(lambda x: [em.i_log([x[0]], None)] + [em.i_div([d, x[0]], None) for d in x[1:]]),
             "sin": unary(lambda x: chain(em.i_sin([x[0]], None), em.i_cos([x[0]], None), x)),
             "cos": unary(lambda x: chain(em.i_cos([x[0]], None), em.i_neg([em.i_sin([x[0]], None)], None), x)),
             "square": unary(power(2)), "cube": unary(power(3)), "fourth": unary(power(4)),
             "add": binary(add(False)), "add_nonneg": binary(add(True)), "add_watched": binary(add(False)),
             "add_nonneg_watched": binary(add(True)),
             "sub": binary(lambda x, y: [em.i_sub([p, q], None) for p, q in zip(x, y)]),
             "mul": binary(mul), "div": binary(div),
             "mul_const": binary(lambda x, c: [em.i_mul_const([p, c[0]], None) for p in x]),  # c's partials: 0
             "div_const": binary(lambda x, c: [em.i_div_const([p, c[0]], None) for p in x]),
             "min": binary(pick("min")), "max": binary(pick("max")),
             "select_lt": select("select_lt"), "select_le": select("select_le")}
    assert set(cases) == set(OPCODES), "every opcode has an interval-gradient case"
    _instruction_loop(b, program, length, cases, zeros=True)
    vresult = b.bitcast(result, _P(V8))
    for k, value in enumerate(x for pair in load(output) for x in pair):
        b.store(value, b.gep(vresult, [ir.Constant(I64, k)]), align=8)
    b.ret_void()
    return fn
