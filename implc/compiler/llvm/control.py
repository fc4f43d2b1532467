"""Structured control flow for hand-written IR: counted loops, while loops, ifs and local variables.

Locals live in allocas (the optimiser's SROA pass turns them into registers), which keeps imperative
routines such as the subdivider readable.
"""

from __future__ import annotations

from contextlib import contextmanager

from llvmlite import ir

I1 = ir.IntType(1)
I32 = ir.IntType(32)
I64 = ir.IntType(64)
DOUBLE = ir.DoubleType()


def const(type_, value):
    return ir.Constant(type_, value)


class Local:
    """A mutable local variable: ``v.get()``, ``v.set(x)``."""

    def __init__(self, builder: ir.IRBuilder, type_, initial=None, name=""):
        self.b = builder
        with builder.goto_entry_block():
            self.ptr = builder.alloca(type_, name=name)
        if initial is not None:
            self.set(initial if isinstance(initial, ir.Value) else ir.Constant(type_, initial))

    def get(self):
        return self.b.load(self.ptr)

    def set(self, value):
        self.b.store(value, self.ptr)


def local_array(builder: ir.IRBuilder, type_, count: int, name=""):
    """A fixed-size array on the stack frame; returns a pointer to its first element."""
    with builder.goto_entry_block():
        arr = builder.alloca(ir.ArrayType(type_, count), name=name)
    return builder.gep(arr, [const(I32, 0), const(I32, 0)], inbounds=True)


@contextmanager
def for_range(builder: ir.IRBuilder, count, start=None, step=1):
    """``for i in range(start, count, step)`` (i64, step > 0); yields the loop index."""
    entry = builder.block
    header = builder.append_basic_block("for.header")
    body = builder.append_basic_block("for.body")
    done = builder.append_basic_block("for.done")
    builder.branch(header)
    builder.position_at_end(header)
    index = builder.phi(count.type, name="i")
    index.add_incoming(start if start is not None else const(count.type, 0), entry)
    builder.cbranch(builder.icmp_signed("<", index, count), body, done)
    builder.position_at_end(body)
    yield index
    index.add_incoming(builder.add(index, const(count.type, step)), builder.block)
    builder.branch(header)
    builder.position_at_end(done)


def bit_intrinsic(module: ir.Module, op: str, type_=I32):
    """``llvm.<op>.<type>`` for op ctpop, cttz or ctlz, declared once (cttz and ctlz take a second, i1
    argument: whether a zero input is poison)."""
    name = f"llvm.{op}.{type_}"
    fn = module.globals.get(name)
    if fn is None:
        fn = ir.Function(module, ir.FunctionType(type_, [type_] if op == "ctpop" else [type_, I1]), name=name)
    return fn


@contextmanager
def for_set_bits(builder: ir.IRBuilder, mask):
    """``for bit in the set bits of mask`` (an integer, ascending): the loop runs once per set bit, so
    what the body skips for clear bits costs nothing. Yields the bit index (same type as mask)."""
    cttz = bit_intrinsic(builder.module, "cttz", mask.type)
    remaining = Local(builder, mask.type, mask, "bits")
    header = builder.append_basic_block("bits.header")
    body = builder.append_basic_block("bits.body")
    done = builder.append_basic_block("bits.done")
    builder.branch(header)
    builder.position_at_end(header)
    r = remaining.get()
    builder.cbranch(builder.icmp_unsigned("==", r, const(mask.type, 0)), done, body)
    builder.position_at_end(body)
    remaining.set(builder.and_(r, builder.sub(r, const(mask.type, 1))))
    yield builder.call(cttz, [r, const(I1, 1)])
    if not builder.block.is_terminated:
        builder.branch(header)
    builder.position_at_end(done)


class _VolatileLoad(ir.LoadInstr):
    def descr(self, buf):
        text = []
        super().descr(text)
        buf.append("".join(text).replace("load ", "load volatile ", 1))


def volatile_load(builder: ir.IRBuilder, ptr):
    """A load the optimiser may neither remove nor move: a value read in a conditional block through it
    keeps everything computed from it there (llvmlite's ``load`` has no volatile flag)."""
    instr = _VolatileLoad(builder.block, ptr)
    builder._insert(instr)
    return instr


class _While:
    def __init__(self, builder, exit_block):
        self.b = builder
        self.exit = exit_block

    def break_if(self, condition):
        """Leave the loop when ``condition`` holds; code after this runs otherwise."""
        cont = self.b.append_basic_block("while.cont")
        self.b.cbranch(condition, self.exit, cont)
        self.b.position_at_end(cont)


@contextmanager
def while_true(builder: ir.IRBuilder):
    """``while True:`` whose body leaves through ``loop.break_if(cond)``."""
    body = builder.append_basic_block("while.body")
    done = builder.append_basic_block("while.done")
    builder.branch(body)
    builder.position_at_end(body)
    loop = _While(builder, done)
    yield loop
    if not builder.block.is_terminated:
        builder.branch(body)
    builder.position_at_end(done)


@contextmanager
def if_(builder: ir.IRBuilder, condition):
    with builder.if_then(condition):
        yield


# -- exported functions and memory access by index -----------------------------------------------------
def define(module: ir.Module, entry):
    """The function of an :class:`implc.native.abi.Entry` in ``module``, and a builder at its entry block."""
    fn = ir.Function(module, entry.llvm_type(), name=entry.name)
    return fn, ir.IRBuilder(fn.append_basic_block("entry"))


def define_internal(module: ir.Module, name: str, returns, params):
    """A function of the module's own (internal linkage: LLVM may inline it, and it is not exported), and a
    builder at its entry block."""
    fn = ir.Function(module, ir.FunctionType(returns, params), name=name)
    fn.linkage = "internal"
    return fn, ir.IRBuilder(fn.append_basic_block("entry"))


def intrinsic(module: ir.Module, name: str, arity: int, type_=DOUBLE):
    """The LLVM intrinsic ``name`` taking ``arity`` values of ``type_`` and returning one (declared once)."""
    fn = module.globals.get(name)
    if fn is None:
        fn = ir.Function(module, ir.FunctionType(type_, [type_] * arity), name=name)
    return fn


def at(b: ir.IRBuilder, ptr, index):
    """&ptr[index] (index an i64 value or a Python int)."""
    return b.gep(ptr, [index if isinstance(index, ir.Value) else const(I64, index)], inbounds=True)


def load_at(b: ir.IRBuilder, ptr, index):
    return b.load(at(b, ptr, index))


def store_at(b: ir.IRBuilder, value, ptr, index):
    b.store(value, at(b, ptr, index))


def bump(b: ir.IRBuilder, ptr, index, amount=1):
    """ptr[index] += amount (an i64 counter)."""
    slot = at(b, ptr, index)
    b.store(b.add(b.load(slot), const(I64, amount)), slot)


def copy_words(b: ir.IRBuilder, src, src_at: int, dst, dst_at: int, count: int):
    """dst[dst_at + i] = src[src_at + i] for i < count."""
    with for_range(b, const(I64, count)) as i:
        store_at(b, load_at(b, src, b.add(i, const(I64, src_at))), dst, b.add(i, const(I64, dst_at)))
