"""Vector arithmetic on ``<W x double>`` for the emitters: splats, NaN-propagating min/max, selects,
element-wise libm calls and outward rounding: the widening of :mod:`implc.compiler.rounding`, or, where the host
has AVX-512, arithmetic rounded directly downward or upward by the instruction itself."""

from __future__ import annotations

import math

from llvmlite import ir

from ..rounding import ARITH, TINY
from .control import volatile_load

DOUBLE = ir.DoubleType()
I64 = ir.IntType(64)

ROUND_DOWN, ROUND_UP = 8 | 1, 8 | 2
"""AVX-512 embedded rounding immediates: toward -inf / +inf, exceptions suppressed (``_MM_FROUND_*``)."""


def broadcast(builder: ir.IRBuilder, value, width: int):
    """A <width x T> vector with ``value`` (a scalar of type T, constant or not) in every lane."""
    vtype = ir.VectorType(value.type, width)
    one = builder.insert_element(ir.Constant(vtype, ir.Undefined), value, ir.Constant(ir.IntType(32), 0))
    return builder.shuffle_vector(one, ir.Constant(vtype, ir.Undefined),
                                  ir.Constant(ir.VectorType(ir.IntType(32), width), [0] * width))


_SPLATS: dict[tuple[int, str], ir.Constant] = {}
"""The vector constants :meth:`VectorBuilder.splat` made, by width and value (its bits: -0.0 is not 0.0)."""


class VectorBuilder:
    """Wraps an IRBuilder with the vector operations the point and interval emitters need."""

    def __init__(self, builder: ir.IRBuilder, width: int, directed: bool = False, outline_elementary: bool = False):
        """``directed``: round add, sub, mul and sqrt bounds with AVX-512 embedded rounding (the host
        must have AVX-512F); otherwise round to nearest and widen by :data:`implc.compiler.rounding.ARITH`.
        ``outline_elementary``: call the vector sin, cos and atan2 as functions of the module instead of
        expanding them at each use (:mod:`implc.compiler.llvm.elementary`; for tapes with many of them)."""
        self.b = builder
        self.width = width
        self.directed = directed
        self.outline_elementary = outline_elementary
        self.octant_lanes = False  # lane c holds child c of one octant (see depends_on, distinct_children)
        self.lane_sources = list(range(width))
        self._distinct: dict[int, DistinctChildren | None] = {}
        self.vtype = ir.VectorType(DOUBLE, width)
        self.module = builder.module

    # -- declarations ----------------------------------------------------------------------------
    def _function(self, name: str, ret, args):
        fn = self.module.globals.get(name)
        if fn is None:
            fn = ir.Function(self.module, ir.FunctionType(ret, args), name=name)
        return fn

    def _intrinsic(self, name: str, arity: int):
        return self._function(f"llvm.{name}.v{self.width}f64", self.vtype, [self.vtype] * arity)

    # -- values ------------------------------------------------------------------------------------
    def splat(self, value: float):
        """``value`` in every lane (a constant made once per width and value: llvmlite's vector constants
        are slow to make, about a fifth of building the tape engine's IR when each was made anew)."""
        value = float("nan") if math.isnan(value) else float(value)
        key = (self.width, value.hex())
        constant = _SPLATS.get(key)
        if constant is None:
            constant = _SPLATS[key] = ir.Constant(self.vtype, [ir.Constant(DOUBLE, value)] * self.width)
        return constant

    def add(self, a, b):
        return self.b.fadd(a, b)

    def sub(self, a, b):
        return self.b.fsub(a, b)

    def mul(self, a, b):
        return self.b.fmul(a, b)

    def div(self, a, b):
        return self.b.fdiv(a, b)

    def horner_step(self, x, p, c):
        """x·p + c, fused into one rounding where the CPU has a fused multiply-add (LLVM's fmuladd: two
        roundings elsewhere): a step of Horner's rule, whose error bound with two roundings a step holds
        for either."""
        return self.b.call(self._intrinsic("fmuladd", 3), [x, p, c])

    def neg(self, a):
        return self.b.fneg(a)

    def fabs(self, a):
        return self.b.call(self._intrinsic("fabs", 1), [a])

    def sqrt(self, a):
        return self.b.call(self._intrinsic("sqrt", 1), [a])

    def ceil(self, a):
        return self.b.call(self._intrinsic("ceil", 1), [a])

    def rint(self, a):
        """Round to the nearest integer, ties to even."""
        return self.b.call(self._intrinsic("rint", 1), [a])

    def floor(self, a):
        return self.b.call(self._intrinsic("floor", 1), [a])

    def copysign(self, magnitude, sign):
        return self.b.call(self._intrinsic("copysign", 2), [magnitude, sign])

    def minimum(self, a, b):
        """min that propagates NaN (the sign of zero may go either way: bounds do not care)."""
        return self.b.call(self._intrinsic("minimum", 2), [a, b], fastmath=("nsz",))

    def maximum(self, a, b):
        return self.b.call(self._intrinsic("maximum", 2), [a, b], fastmath=("nsz",))

    def cmp(self, op: str, a, b):
        """Ordered comparison: false where either side is NaN."""
        return self.b.fcmp_ordered(op, a, b)

    def select(self, mask, a, b):
        return self.b.select(mask, a, b)

    def and_(self, a, b):
        return self.b.and_(a, b)

    def or_(self, a, b):
        return self.b.or_(a, b)

    def isnan(self, a):
        return self.b.fcmp_unordered("uno", a, a)

    def reloadable(self, vectors):
        """Spill ``vectors`` to the stack; returns a function that reads them back through volatile loads.

        Code computed from such a reload stays where it is: a loop that switches to one of many
        loop-invariant computations per iteration (a fold over live terms) would otherwise have the
        optimiser hoist all of them out of the loop and compute every one.
        """
        b = self.b
        with b.goto_entry_block():
            slots = b.alloca(ir.ArrayType(self.vtype, len(vectors)), name="spilled")
        ptrs = [b.gep(slots, [ir.Constant(ir.IntType(32), 0), ir.Constant(ir.IntType(32), j)], inbounds=True)
                for j in range(len(vectors))]
        for ptr, value in zip(ptrs, vectors):
            b.store(value, ptr)
        return lambda: [volatile_load(b, ptr) for ptr in ptrs]

    # -- the C math library, one lane at a time ------------------------------------------------------
    def depends_on(self, axes: int):
        """Declare the axes (bit a: axis a) the values emitted next depend on. Where lane c holds child c
        of one octant (``octant_lanes``), children that differ only in other axes hold equal values, and
        the C library is then called once for each group of such lanes."""
        if self.octant_lanes:
            same = ~axes & (self.width - 1)  # child-index bits that vary across the lanes but not the values
            self.lane_sources = [lane & ~same for lane in range(self.width)]

    def distinct_children(self, axes: int) -> DistinctChildren | None:
        """Where lane c holds child c of one octant (``octant_lanes``), the lanes a value that depends only
        on ``axes`` (bit a: axis a) takes distinct values in, with a builder as wide as they are; None where
        every lane may differ."""
        if not self.octant_lanes:
            return None
        kept = axes & (self.width - 1)
        if kept not in self._distinct:
            lanes = [c for c in range(self.width) if c & ~kept == 0]
            self._distinct[kept] = DistinctChildren(self, lanes) if len(lanes) < self.width else None
        return self._distinct[kept]

    def libm(self, name: str, *args):
        fn = self._function(name, DOUBLE, [DOUBLE] * len(args))
        out = ir.Constant(self.vtype, ir.Undefined)
        results = {}
        for lane, source in enumerate(self.lane_sources):
            if source not in results:
                idx = ir.Constant(ir.IntType(32), source)
                results[source] = self.b.call(fn, [self.b.extract_element(a, idx) for a in args])
            out = self.b.insert_element(out, results[source], ir.Constant(ir.IntType(32), lane))
        return out

    # -- outward rounding (see implc.compiler.rounding) -------------------------------------------------------
    def add_down(self, a, b):
        return self._rounded("add", [a, b], up=False)

    def add_up(self, a, b):
        return self._rounded("add", [a, b], up=True)

    def sub_down(self, a, b):
        return self._rounded("sub", [a, b], up=False)

    def sub_up(self, a, b):
        return self._rounded("sub", [a, b], up=True)

    def mul_down(self, a, b):
        return self._rounded("mul", [a, b], up=False)

    def mul_up(self, a, b):
        return self._rounded("mul", [a, b], up=True)

    def sqrt_down(self, a):
        return self._rounded("sqrt", [a], up=False)

    def sqrt_up(self, a):
        return self._rounded("sqrt", [a], up=True)

    def _rounded(self, op: str, args, up: bool):
        """``op`` on ``args`` with a result at or below (``up``: at or above) the exact one."""
        if not self.directed:
            nearest = getattr(self, op)(*args)
            return self.widen_up(nearest, ARITH) if up else self.widen_down(nearest, ARITH)
        mode = ir.Constant(ir.IntType(32), ROUND_UP if up else ROUND_DOWN)
        i32 = ir.IntType(32)
        if self.width == 1:  # the scalar (sd) forms, on lane 0 of an xmm register
            v2 = ir.VectorType(DOUBLE, 2)
            pair = ir.Constant(ir.VectorType(i32, 2), [0, 1])
            wide = [self.b.shuffle_vector(a, ir.Constant(a.type, ir.Undefined), pair) for a in args]
            name = "llvm.x86.avx512.mask.sqrt.sd" if op == "sqrt" else f"llvm.x86.avx512.mask.{op}.sd.round"
            fn = self._function(name, v2, [v2, v2, v2, ir.IntType(8), i32])
            operands = [wide[0], wide[0]] if op == "sqrt" else wide
            out = self.b.call(fn, [*operands, ir.Constant(v2, ir.Undefined), ir.Constant(ir.IntType(8), -1), mode])
            return self.b.shuffle_vector(out, ir.Constant(v2, ir.Undefined), ir.Constant(ir.VectorType(i32, 1), [0]))
        v8 = ir.VectorType(DOUBLE, 8)
        if self.width < 8:  # the 512-bit forms on the low lanes (the others are don't-care)
            pad = ir.Constant(ir.VectorType(i32, 8), list(range(self.width)) + [self.width] * (8 - self.width))
            args = [self.b.shuffle_vector(a, ir.Constant(a.type, ir.Undefined), pad) for a in args]
        fn = self._function(f"llvm.x86.avx512.{op}.pd.512", v8, [v8] * len(args) + [i32])
        out = self.b.call(fn, [*args, mode])
        if self.width < 8:
            out = self.b.shuffle_vector(out, ir.Constant(v8, ir.Undefined),
                                        ir.Constant(ir.VectorType(i32, self.width), list(range(self.width))))
        return out

    def widen_down(self, v, c: float, tiny: float = TINY):
        return self.sub(self.sub(v, self.mul(self.fabs(v), self.splat(c))), self.splat(tiny))

    def widen_up(self, v, c: float, tiny: float = TINY):
        return self.add(self.add(v, self.mul(self.fabs(v), self.splat(c))), self.splat(tiny))


class DistinctChildren:
    """The lanes of an octant's children in which a value differs: children that differ only along axes it
    does not depend on hold equal values, so it is computed once for each (on a vector as wide as there
    are such lanes, ``vb``) and spread back to every lane."""

    def __init__(self, full: VectorBuilder, lanes: list[int]):
        self.vb = VectorBuilder(full.b, len(lanes), full.directed, full.outline_elementary)
        self.emitters: dict[type, object] = {}  # an emitter class's instance over ``vb``, made once
        i32 = ir.IntType(32)
        self._take = ir.Constant(ir.VectorType(i32, len(lanes)), lanes)
        kept = max(lanes)  # the child-index bits the value depends on
        self._spread = ir.Constant(ir.VectorType(i32, full.width), [lanes.index(c & kept) for c in range(full.width)])

    def emitter(self, kind):
        """The emitter ``kind(vb)`` over the narrow builder (one per kind)."""
        if kind not in self.emitters:
            self.emitters[kind] = kind(self.vb)
        return self.emitters[kind]

    def take(self, value):
        """The distinct lanes of a full-width vector."""
        return self.vb.b.shuffle_vector(value, ir.Constant(value.type, ir.Undefined), self._take)

    def spread(self, value):
        """A narrow vector back at full width, each child's lane from its distinct one."""
        return self.vb.b.shuffle_vector(value, ir.Constant(value.type, ir.Undefined), self._spread)
