"""The conformance harness, fidget-style: a table of op cases and a list of evaluators, every evaluator
running every case against the numpy reference, each op with its declared tolerance.

Tolerances (:data:`OP_BUDGET`): the IEEE-exact ops (+, −, ×, ÷, sqrt, integer powers, min, max, abs,
selects, ...) must agree **bit for bit** with the reference, in widened kernels, where both compute the
same rounded operations and the same widening (:mod:`implc.compiler.rounding`). Ops that call a math library may
differ by what the two libraries differ by (numpy's and the C library's results are each within 1-2 ulps
of the true value; the widening of either is 4 ulps): a budget of :data:`LIBM_ULPS` ulps of the size of
the values computed in the case. sin, cos and atan2 run in vector registers in the kernels
(:mod:`implc.compiler.llvm.elementary`: error proven below 1.1e-15, interval bounds widened by 2^-45 absolute,
:data:`implc.compiler.rounding.SIN_ERROR`) and in numpy in the reference: their budget is that absolute widening
twice. A case's budget adds its nodes' budgets (a case that multiplies an elementary result by a constant
states the factor, :data:`AMPLIFICATION`). Kernels compiled with directed rounding are checked separately:
they nest inside the widened ones and hold the high-precision truth. Truth tests (40 digits) check
every op's enclosures, values and gradients independently of the reference.
"""

import zlib
from dataclasses import dataclass

import numpy as np
import pytest
import sympy
from sympy import (
    Abs,
    Max,
    Min,
    Piecewise,
    Rational,
    acos,
    asin,
    atan,
    atan2,
    cbrt,
    cos,
    cosh,
    exp,
    log,
    sin,
    sinh,
    sqrt,
    tan,
    tanh,
)

import implc
from implc.compiler import ir, reference
from implc.compiler import rounding as R
from implc.compiler.gradient import DERIVATIVE_RULES
from implc.compiler.llvm.interval_rules import IntervalEmitter
from implc.compiler.reference import INTERVAL_RULES
from implc.compiler.symbols import phi, r, theta, x, y, z
from implc.compiler.vm import parse_vm
from implc.engines.tape.program import OPCODES, unsupported_ops
from implc.native import abi
from implc.native.jit import host_has_avx512

from ..support.truth import TrueValues, adversarial_boxes, assert_encloses

# One or more expressions per op of the IR (the ids name the op they exercise).
OP_CASES = {
    "const": sympy.pi * x + Rational(1, 3),
    "neg": -x + y,
    "add": x + y + z,
    "sub": x - 2 * y,
    "mul": x * y * z,
    "scale": Rational(3, 7) * x + 3 * y,
    "div": x / (y + Rational(1, 2)),
    "div_pole": (x + 1) / y,
    "powi_even": (x - Rational(1, 3)) ** 4 + y**2,
    "powi_odd": (x + y) ** 3 - z**5,
    "powi_neg": 1 / (x**2 + Rational(1, 10)) - (y + 2) ** -3,
    "powf": (x**2 + y**2) ** Rational(3, 4),
    "powf_irrational": Abs(x) ** sympy.pi,
    "sqrt": sqrt(x + Rational(1, 2)) - y,
    "cbrt": cbrt(x**2 + y) * 2,
    "exp": exp(x * 3) - y,
    "log": log(x**2 + y**2) + z,
    "log_domain": log(x + Rational(1, 4)),
    "sin": sin(7 * x + y) - z,
    "cos": cos(5 * x) * cos(3 * y),
    "tan": tan(x + y) - z,
    "asin": asin(x / 2) + y,
    "asin_domain": asin(x + y),
    "acos": acos(y / 2) - x,
    "atan": atan(x * 4) * y,
    "atan2": atan2(y, x) - z,
    "atan2_wrapped": sin(3 * phi) - x,
    "sinh": sinh(x * 2) + y,
    "cosh": cosh(x - y) - 2,
    "tanh": tanh(3 * x) - y,
    "abs": Abs(x) + Abs(y - z) - 1,
    "min": Min(x, y, z + 1),
    "max": Max(x**2, y - z),
    "select_lt": Piecewise((x**2, y < 0), (x + 1, True)),
    "select_le": Piecewise((x - 1, x**2 + y**2 <= Rational(1, 4)), (z, True)),
    "piecewise_and": Piecewise((y, (x > 0) & (z < 0)), (-y, True)),
    "piecewise_or": Piecewise((y + 1, (x > 0) | (z > Rational(1, 2))), (2 * x, True)),
    "piecewise_eq_ne": Piecewise((y, sympy.Eq(x, 0)), (z, sympy.Ne(y, 1)), (x, True)),
    "piecewise_ge_not": Piecewise((y, x >= Rational(1, 3)), (z, ~(y <= 0)), (x, True)),
    "spherical": sin(4 * theta) * sin(8 * phi) - r,
    "spherical_mixed": r - 1 + x * cos(theta),
    "var": x,
}




# -- tolerances -------------------------------------------------------------------------------------------
LIBM_ULPS = 4
"""ulps (of the case's scale) two math libraries may differ by per call, widening included."""

VECTOR_OPS = ("sin", "cos", "atan2", "atan2_wrapped")
"""Ops the kernels compute with :mod:`implc.compiler.llvm.elementary` in interval kernels and normals, with an
absolute widening; exp and log (below) have a relative one."""
RELATIVE_VECTOR_OPS = ("exp", "log")


@dataclass(frozen=True)
class Budget:
    """|kernel − reference| <= ulps · ulp(scale) + absolute, scale the largest magnitude of any node's value
    (or bound) at that point (box); Budget() means bit-identical."""

    ulps: float = 0.0
    absolute: float = 0.0

    def __add__(self, other):
        return Budget(self.ulps + other.ulps, self.absolute + other.absolute)

    def __mul__(self, k):
        return Budget(self.ulps * k, self.absolute * k)

    @property
    def exact(self) -> bool:
        return self.ulps == 0 and self.absolute == 0


EXACT = Budget()
OP_BUDGET = {op: EXACT for op in ir.OPS}
OP_BUDGET.update({op: Budget(ulps=LIBM_ULPS) for op in ir.LIBM_OPS})
INTERVAL_BUDGET = dict(OP_BUDGET)
INTERVAL_BUDGET.update({op: Budget(ulps=LIBM_ULPS, absolute=2 * R.SIN_ERROR) for op in VECTOR_OPS})
# the vector exp and log are widened by a relative 2^-45, the reference's libm by 2^-50: twice the former
INTERVAL_BUDGET.update({op: Budget(ulps=2 * R.EXP_ERROR / 2.0**-52) for op in RELATIVE_VECTOR_OPS})
VECTOR_POINT_BUDGET = dict(OP_BUDGET)  # the normals' kernel: vector functions without widening
VECTOR_POINT_BUDGET.update({op: Budget(ulps=LIBM_ULPS, absolute=2.0**-48) for op in VECTOR_OPS})  # > 1.1e-15
VECTOR_POINT_BUDGET.update({op: Budget(ulps=LIBM_ULPS + 28) for op in RELATIVE_VECTOR_OPS})  # proven: 27.6 ulps

AMPLIFICATION = {"cos": 5, "sin": 7, "spherical": 8, "atan2_wrapped": 3, "powf_irrational": 40}
"""Cases that scale a math-library result before using it: sin(7x + y) moves a bound by up to 7 times
the difference of its argument's bounds; sin(8·phi) by 8; sin(3·phi) by 3; cos(5x) by 5; |x|^π =
exp(π·log|x|) turns log's relative widening into a relative move of exp's result π·|log|x|| times as
large (<= 37 for the boxes' |x| < 1e5)."""


def case_budget(tape, table) -> Budget:
    total = EXACT
    for op, _, _ in tape.nodes:
        total = total + table[op]
    return total


def _scale(nodes):
    scale = np.zeros(len(nodes[0][0]) if isinstance(nodes[0], tuple) else len(nodes[0]))
    for node in nodes:
        for v in (node if isinstance(node, tuple) else (node,)):
            scale = np.maximum(scale, np.where(np.isfinite(v), np.abs(v), 0.0))
    return scale


def assert_conforms(got, expected, budget: Budget, scale, what):
    """Equal where the budget is exact (NaN and infinities included); else the same non-finite values and
    finite ones within the budget."""
    got, expected = np.asarray(got, dtype=np.float64), np.asarray(expected, dtype=np.float64)
    if budget.exact:
        np.testing.assert_array_equal(got, expected, err_msg=f"{what}: not bit-identical")
        return
    finite = np.isfinite(expected)
    np.testing.assert_array_equal(got[~finite], expected[~finite], err_msg=f"{what}: non-finite values differ")
    assert np.all(np.isfinite(got[finite])), f"{what}: non-finite where the reference is finite"
    scale = np.broadcast_to(scale.reshape(scale.shape + (1,) * (expected.ndim - 1)), expected.shape)
    allowed = budget.ulps * np.spacing(np.maximum(np.abs(scale), np.abs(expected))) + budget.absolute
    with np.errstate(invalid="ignore"):  # inf - inf where both are infinite: those were compared above
        excess = np.abs(got - expected) - allowed
    worst = int(np.argmax(np.where(finite, excess, -np.inf)))
    assert np.all(excess[finite] <= 0), (
        f"{what}: {got.flat[worst]!r} vs reference {expected.flat[worst]!r} exceeds {budget} at scale "
        f"{scale.flat[worst]!r}")


# -- evaluators ---------------------------------------------------------------------------------------------
def seed(name: str) -> int:
    return zlib.crc32(name.encode())  # stable across runs, unlike hash()


def _boxes(name, n=64):
    return adversarial_boxes(np.random.default_rng(seed(name) + 5), n)


def _points(name, n=64):
    return np.random.default_rng(seed(name) + 6).uniform(-1.5, 1.5, (n, 3))


def _padded(arrays, width):
    """Zero-pad (n, 3) arrays to a multiple of the vector width (the raw kernels take whole vectors)."""
    n = len(arrays[0])
    m = -(-n // width) * width
    out = []
    for a in arrays:
        p = np.zeros((m, 3))
        p[:n] = a
        out.append(p)
    return out, n


def _interval_with_all_live(s, lo, hi, entry):
    """The kernel ``entry`` with a live-term mask of all ones: the pruned path with every term live."""
    (lo_p, hi_p), n = _padded([lo, hi], 8)
    f_lo, f_hi = np.empty(len(lo_p)), np.empty(len(lo_p))
    live_in = np.full(len(lo_p) // 8, -1, dtype=np.int64)
    live_out = np.empty(len(lo_p), dtype=np.int64)
    s.kernel(entry)(lo_p.ctypes.data, hi_p.ctypes.data, f_lo.ctypes.data, f_hi.ctypes.data, len(lo_p),
                    live_in.ctypes.data, live_out.ctypes.data)
    return f_lo[:n], f_hi[:n]


def _gradient_live(s, pts):
    (p,), n = _padded([pts], s.width)
    value, grad = np.empty(len(p)), np.empty((len(p), 3))
    s.kernel(abi.GRADIENT_LIVE)(p.ctypes.data, value.ctypes.data, grad.ctypes.data, len(p), -1)
    return value[:n], grad[:n]


def _point_fast(s, pts):
    (p,), n = _padded([pts], s.width)
    value = np.empty(len(p))
    s.kernel(abi.POINT_FAST)(p.ctypes.data, value.ctypes.data, len(p))
    return value[:n]


INTERVAL_EVALUATORS = {
    "kernel": lambda s, lo, hi: s.interval(lo, hi),
    "pruned kernel, every term live": lambda s, lo, hi: _interval_with_all_live(s, lo, hi, abi.INTERVAL),
}
MEAN_VALUE_EVALUATORS = {
    "mean-value kernel": lambda s, lo, hi: s.interval(lo, hi, mean_value=True),
    "pruned mean-value kernel, every term live": lambda s, lo, hi: _interval_with_all_live(s, lo, hi,
                                                                                           abi.INTERVAL_MVF),
}
MONOTONE_EVALUATORS = {
    "monotone kernel": lambda s, lo, hi: s.interval(lo, hi, monotone=True),
    "pruned monotone kernel, every term live": lambda s, lo, hi: _interval_with_all_live(s, lo, hi,
                                                                                        abi.INTERVAL_MONOTONE),
}
WIDTHS = (8, 1, pytest.param(4, marks=pytest.mark.slow), pytest.param(2, marks=pytest.mark.slow))
"""Every vector width runs every case; 4 and 2 (the same code as 8 on fewer lanes) only in the slow run."""


@pytest.fixture(scope="module")
def compiled():
    """Surfaces compiled on first use: (case, rounding, width) -> Surface."""
    cache = {}

    def get(name, rounding="widen", width=8, engine="jit"):
        key = (name, rounding, width, engine)
        if key not in cache:
            cache[key] = implc.compile(OP_CASES[name], rounding=rounding, vector_width=width, engine=engine)
        return cache[key]
    return get


def runs_on_tape_engine(name) -> bool:
    """Whether the tape engine runs op case ``name`` (it runs a subset of the ops: the .vm models')."""
    return not unsupported_ops(implc.compile(OP_CASES[name], engine="jit").tape)


TAPE_CASES = [name for name in sorted(OP_CASES) if runs_on_tape_engine(name)]


def test_every_op_has_every_rule():
    ops = set(ir.OPS) - {"const", "var"}
    assert ops == set(INTERVAL_RULES), "numpy interval rules"
    assert ops == set(DERIVATIVE_RULES), "derivative rules"
    assert ops <= set(reference.POINT_RULES) | {"powi", "powf", "scale"}, "point rules"
    assert all(hasattr(IntervalEmitter, f"i_{op}") for op in ops), "LLVM interval emitters"
    assert set(OP_BUDGET) == set(INTERVAL_BUDGET) == set(ir.OPS), "a declared tolerance per op"


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_interval_evaluators_conform(name, width, compiled):
    s = compiled(name, width=width)
    lo, hi = _boxes(name)
    nodes = reference.interval_nodes(s.tape, lo, hi)
    scale = _scale(nodes)
    budget = case_budget(s.tape, INTERVAL_BUDGET) * AMPLIFICATION.get(name, 1)
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    evaluators = INTERVAL_EVALUATORS if width == 8 else {"kernel": INTERVAL_EVALUATORS["kernel"]}
    if width == 8 and name in TAPE_CASES:  # the tape engine's interpreter, rule for rule the same
        evaluators = {**evaluators, "tape engine": lambda _, lo, hi: compiled(name, engine="tape").interval(lo, hi)}
    for label, evaluate in evaluators.items():
        f_lo, f_hi = evaluate(s, lo, hi)
        assert_conforms(f_lo, r_lo, budget, scale, f"{name} {label} width {width}: lower bounds")
        assert_conforms(f_hi, r_hi, budget, scale, f"{name} {label} width {width}: upper bounds")


CONSTANT_OPERANDS = {  # each over an operand on both sides of 0: x + y, and z
    "times 0.3": ("mul", "0.3", (x + y) * Rational(3, 10)),  # not a double: an interval of two
    "times -2.5": ("mul", "-2.5", (x + y) * Rational(-5, 2)),
    "over 7": ("div", "7", (x + y) / 7),
    "over -0.07": ("div", "-0.07", (x + y) / Rational(-7, 100)),
}
"""Products and quotients by constants of both signs, exact or not: the tape engine's ``mul_const`` and
``div_const`` instructions (the .vm text and the same function in SymPy)."""


@pytest.mark.parametrize("rounding", ["widen", "auto"])
@pytest.mark.parametrize("case", sorted(CONSTANT_OPERANDS))
def test_products_and_quotients_by_constants_conform_on_the_engine(case, rounding):
    """The engine's rules for a product and a quotient by a constant (one product or quotient per bound,
    chosen by the signs) give the reference's general rules' bounds bit for bit where rounding is
    widened as there; where it is directed (``auto`` on a host with AVX-512: each bound rounded outward by
    its instruction, which widening only moves further) they lie within the reference's and within a few
    ulps of them; and they enclose the true values (mpmath)."""
    op, constant, truth = CONSTANT_OPERANDS[case]
    model = parse_vm(f"x var-x\ny var-y\nc const {constant}\ns add x y\no {op} s c\n")
    s = implc.compile(model, ((-2, 2),) * 3, engine="tape", rounding=rounding)
    assert list(s.program.opcodes) == [OPCODES["add"], OPCODES[f"{op}_const"]]
    rng = np.random.default_rng(11)
    lo, hi = adversarial_boxes(rng, 64)
    nodes = reference.interval_nodes(s.tape, lo, hi)
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    f_lo, f_hi = s.interval(lo, hi)
    if rounding == "auto" and host_has_avx512():
        assert np.all(f_lo >= r_lo) and np.all(f_hi <= r_hi), f"{case}: wider than the widened reference"
        budget = Budget(ulps=16)
    else:
        budget = case_budget(s.tape, INTERVAL_BUDGET)
    assert_conforms(f_lo, r_lo, budget, _scale(nodes), f"{case}, {rounding}: lower bounds")
    assert_conforms(f_hi, r_hi, budget, _scale(nodes), f"{case}, {rounding}: upper bounds")
    assert_encloses(s, truth, lo, hi, rng)


@pytest.mark.parametrize("form", ["mean_value", "monotone"])
@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_mean_value_and_monotone_evaluators_conform(name, form, compiled):
    """The mean-value and monotonicity forms' kernels against the reference, rule for rule, on boxes of
    every size."""
    s = compiled(name)
    lo, hi = _boxes_half_small(name)
    scale = _scale(reference.interval_nodes(s.gradient_tape, lo, hi))
    # the gradient tape's nodes and F at a point, each as the reference's (their budgets add up)
    budget = (case_budget(s.gradient_tape, INTERVAL_BUDGET) + case_budget(s.tape, INTERVAL_BUDGET)) * \
        AMPLIFICATION.get(name, 1)
    r_lo, r_hi = {"mean_value": reference.eval_interval_mean_value,
                  "monotone": reference.eval_interval_monotone}[form](s.tape, lo, hi)
    for label, evaluate in {"mean_value": MEAN_VALUE_EVALUATORS, "monotone": MONOTONE_EVALUATORS}[form].items():
        f_lo, f_hi = evaluate(s, lo, hi)
        assert_conforms(f_lo, r_lo, budget, scale, f"{name} {label}: lower bounds")
        assert_conforms(f_hi, r_hi, budget, scale, f"{name} {label}: upper bounds")


def _boxes_half_small(name):
    """The case's boxes, half of them shrunk a thousandfold (where the forms pay)."""
    lo, hi = _boxes(name)
    small = np.random.default_rng(seed(name)).random(len(lo)) < 0.5
    hi[small] = lo[small] + (hi[small] - lo[small]) * 1e-3
    return lo, hi


@pytest.mark.parametrize("width", WIDTHS)
@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_point_and_gradient_evaluators_conform(name, width, compiled):
    s = compiled(name, width=width)
    pts = _points(name)
    scale = _scale(reference.point_nodes(s.gradient_tape, pts))
    budget = case_budget(s.gradient_tape, OP_BUDGET) * AMPLIFICATION.get(name, 1)
    ref_value, ref_grad = reference.eval_gradient(s.tape, pts)
    assert_conforms(s.eval(pts), ref_value, budget, scale, f"{name} point width {width}")
    value, grad = s.value_and_gradient(pts)
    assert_conforms(value, ref_value, budget, scale, f"{name} gradient's value width {width}")
    assert_conforms(grad, ref_grad, budget, scale, f"{name} gradient width {width}")
    value, grad = _gradient_live(s, pts)
    live_budget = case_budget(s.gradient_tape, VECTOR_POINT_BUDGET) * AMPLIFICATION.get(name, 1)
    assert_conforms(value, ref_value, live_budget, scale, f"{name} gradient over live terms' value width {width}")
    assert_conforms(grad, ref_grad, live_budget, scale, f"{name} gradient over live terms width {width}")
    assert_conforms(_point_fast(s, pts), ref_value, live_budget, scale, f"{name} fast point width {width}")
    assert_conforms(s.eval(pts, fast=True), ref_value, live_budget, scale, f"{name} eval(fast=True) width {width}")
    value, grad = s.value_and_gradient(pts, fast=True)  # the mesher's samples
    assert_conforms(value, ref_value, live_budget, scale, f"{name} value_and_gradient(fast=True) width {width}")
    assert_conforms(grad, ref_grad, live_budget, scale, f"{name} value_and_gradient(fast=True) width {width}")
    if width == 8 and name in TAPE_CASES:  # dual numbers in the tape engine (sin and cos in vector registers)
        value, grad = compiled(name, engine="tape").value_and_gradient(pts)
        assert_conforms(value, ref_value, live_budget, scale, f"{name} tape engine's value")
        assert_conforms(grad, ref_grad, live_budget, scale, f"{name} tape engine's gradient")


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_octant_kernel_conforms(name, compiled):
    """implc_octant generates an octant's eight children from its cell index and geometry: its keep and
    inside bits and child masks are those of the batched kernel on the same eight boxes, exactly."""
    s = compiled(name)
    parents_lo, parents_hi = _boxes(name, 24)
    bits = np.array([[(c >> a) & 1 for a in range(3)] for c in range(8)], dtype=np.float64)
    octant = s.kernel(abi.OCTANT)
    cell = np.zeros(3, dtype=np.int32)
    for p_lo, p_hi in zip(parents_lo, parents_hi):
        geom = np.zeros(abi.GEOMETRY_DOUBLES)
        h = (p_hi - p_lo) / 2
        geom[:3], geom[9:12] = p_lo, h  # origin; level 1's cell size (the pad stays 0)
        lo, hi = p_lo + bits * h, p_lo + (bits + 1) * h  # the same rounded operations as the kernel
        masks = np.empty(8, dtype=np.int64)
        kept = octant(geom.ctypes.data, cell.ctypes.data, 1, -1, masks.ctypes.data)
        f_lo, f_hi = _interval_with_all_live(s, lo, hi, abi.INTERVAL)
        expected = sum(1 << c for c in range(8) if f_lo[c] <= 0 <= f_hi[c])
        expected |= sum(1 << (abi.OCTANT_INSIDE_SHIFT + c) for c in range(8) if f_hi[c] < 0)  # inside
        assert kept == expected, f"{name}: parent {p_lo}..{p_hi}"
        live_out, all_live = np.empty(8, dtype=np.int64), np.array([-1], dtype=np.int64)
        out_lo, out_hi = np.empty(8), np.empty(8)
        s.kernel(abi.INTERVAL)(lo.ctypes.data, hi.ctypes.data, out_lo.ctypes.data, out_hi.ctypes.data, 8,
                               all_live.ctypes.data, live_out.ctypes.data)
        np.testing.assert_array_equal(masks, live_out)


needs_avx512 = pytest.mark.skipif(not host_has_avx512(), reason="directed rounding needs AVX-512F; this CPU has none")


@needs_avx512
@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_directed_rounding_is_never_looser_than_widening(name, compiled):
    """Each directed bound is the nearest double outward of its operation's exact result; widening moves
    at least as far, and every rule is monotone in its operands' bounds, so the enclosures nest."""
    directed, widened = compiled(name, "directed"), compiled(name)
    rng = np.random.default_rng(seed(name) + 3)
    lo, hi = adversarial_boxes(rng, 200)
    for mean_value in (False, True):
        d_lo, d_hi = directed.interval(lo, hi, mean_value)
        w_lo, w_hi = widened.interval(lo, hi, mean_value)
        assert np.all(d_lo >= w_lo) and np.all(d_hi <= w_hi), f"mean_value={mean_value}"
    assert_encloses(directed, OP_CASES[name], lo[:40], hi[:40], rng)


def test_directed_rounding_is_refused_without_avx512(monkeypatch):
    """On a CPU without AVX-512F, asking for directed rounding is a CompileError that says why, and
    "auto" widens (simulated here by hiding the host's AVX-512 features)."""
    from implc.engines import surface
    monkeypatch.setattr(surface, "host_has_avx512", lambda: False)
    with pytest.raises(implc.CompileError, match="AVX-512"):
        implc.compile(x + y, rounding="directed")
    assert not implc.compile(x + y, rounding="auto").directed


def test_the_harness_sees_a_lost_ulp():
    """A kernel that lost its one-ulp widening on add would differ from the reference in the last bit:
    an exact budget must fail on it."""
    expected = np.array([1.0, -2.5, 3.0e-300])
    with pytest.raises(AssertionError, match="not bit-identical"):
        assert_conforms(np.nextafter(expected, 0), expected, EXACT, np.abs(expected), "add")
    with pytest.raises(AssertionError, match="exceeds"):
        assert_conforms(expected + 1e-9, expected, Budget(ulps=4), np.abs(expected), "exp")


# -- against the truth (40 digits), independent of the reference ---------------------------------------------
@pytest.fixture(scope="module")
def surfaces(compiled):
    return {name: compiled(name, "auto") for name in OP_CASES}


@pytest.fixture(scope="module")
def widened(compiled):
    return {name: compiled(name) for name in OP_CASES}


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_interval_encloses_true_values(name, surfaces):
    rng = np.random.default_rng(seed(name))
    lo, hi = adversarial_boxes(rng, 60)
    assert_encloses(surfaces[name], OP_CASES[name], lo, hi, rng)


@pytest.mark.parametrize("name", TAPE_CASES)
def test_tape_engine_encloses_true_values(name, compiled):
    rng = np.random.default_rng(seed(name) + 3)
    lo, hi = adversarial_boxes(rng, 60)
    assert_encloses(compiled(name, "auto", engine="tape"), OP_CASES[name], lo, hi, rng)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_the_one_sided_bound_is_the_monotone_kernels(name, compiled):
    """The voxelizer's one-sided bound is the monotonicity form, bit for bit, where the form binds the
    two-sided kernel's bound (elsewhere the natural enclosure does, and the raw form is at most as tight)."""
    s = compiled(name)
    lo, hi = _boxes_half_small(name)
    n_lo, n_hi = s.interval(lo, hi)
    t_lo, t_hi = s.interval(lo, hi, monotone=True)
    lower, upper = _one_sided_bound(s, lo, hi, True), _one_sided_bound(s, lo, hi, False)
    binds_lo, binds_hi = t_lo > n_lo, t_hi < n_hi
    assert np.array_equal(lower[binds_lo], t_lo[binds_lo]) and np.array_equal(upper[binds_hi], t_hi[binds_hi]), name
    assert np.all(np.isnan(lower) | (lower <= t_lo)) and np.all(np.isnan(upper) | (upper >= t_hi)), name


def _one_sided_bound(s, lo, hi, above):
    """``implc_bound_monotone`` over the boxes: the lower bounds (``above``) or the upper ones."""
    (lo_p, hi_p), n = _padded([lo, hi], 8)
    side = np.full(len(lo_p), 1.0 if above else -1.0)
    out = np.empty(len(lo_p))
    s.kernel(abi.BOUND_MONOTONE)(lo_p.ctypes.data, hi_p.ctypes.data, side.ctypes.data, out.ctypes.data,
                                 len(lo_p), None)
    return out[:n]


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_widened_intervals_enclose_true_values(name, widened):
    rng = np.random.default_rng(seed(name) + 2)
    lo, hi = adversarial_boxes(rng, 40)
    assert_encloses(widened[name], OP_CASES[name], lo, hi, rng)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_mean_value_form_encloses_and_never_loosens(name, surfaces):
    s = surfaces[name]
    rng = np.random.default_rng(seed(name) + 1)
    lo, hi = adversarial_boxes(rng, 60)
    small = rng.random(60) < 0.5  # the form pays on small boxes: shrink half of them
    hi[small] = lo[small] + (hi[small] - lo[small]) * 1e-3
    assert_encloses(s, OP_CASES[name], lo, hi, rng, mean_value=True)
    n_lo, n_hi = s.interval(lo, hi)
    m_lo, m_hi = s.interval(lo, hi, mean_value=True)
    assert np.all(m_lo >= n_lo) and np.all(m_hi <= n_hi)


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_monotone_form_encloses_and_is_tighter_than_the_mean_value_form(name, surfaces):
    """Against 40-digit values at each box's corners (where the form is exact when every partial keeps its
    sign) and inside points; never looser than the natural enclosure, and never looser than the mean-value
    form by more than rounding."""
    s = surfaces[name]
    rng = np.random.default_rng(seed(name) + 3)
    lo, hi = adversarial_boxes(rng, 60)
    small = rng.random(60) < 0.5
    hi[small] = lo[small] + (hi[small] - lo[small]) * 1e-3
    assert_encloses(s, OP_CASES[name], lo, hi, rng, monotone=True)
    n_lo, n_hi = s.interval(lo, hi)
    f_lo, f_hi = s.interval(lo, hi, monotone=True)
    m_lo, m_hi = s.interval(lo, hi, mean_value=True)
    assert np.all(f_lo >= n_lo) and np.all(f_hi <= n_hi)
    width = np.where(np.isfinite(m_hi - m_lo), m_hi - m_lo, 0.0)
    slack = 1e-12 * (np.abs(m_lo) + np.abs(m_hi) + width)
    assert np.all(~np.isfinite(m_lo) | (f_lo >= m_lo - slack)), name
    assert np.all(~np.isfinite(m_hi) | (f_hi <= m_hi + slack)), name


def test_monotone_form_is_exact_where_every_partial_keeps_its_sign():
    """F = x + 2y − z + x³ over a box where every partial is positive or negative: the form's bounds are F
    at two corners (within rounding), the natural enclosure is wider."""
    s = implc.compile(x + 2 * y - z + x**3, rounding="widen")
    lo, hi = np.array([[0.1, -0.3, 0.2]]), np.array([[0.2, -0.25, 0.3]])
    f_lo, f_hi = s.interval(lo, hi, monotone=True)
    exact_lo = 0.1 + 2 * -0.3 - 0.3 + 0.1**3
    exact_hi = 0.2 + 2 * -0.25 - 0.2 + 0.2**3
    assert exact_lo - 1e-14 <= f_lo[0] <= exact_lo and exact_hi <= f_hi[0] <= exact_hi + 1e-14


def test_op_cases_cover_every_op():
    covered = set()
    for expr in OP_CASES.values():
        covered.update(op for op, _, _ in implc.compile(expr).gradient_tape.nodes)
    assert covered == set(ir.OPS)


def test_mean_value_form_is_tighter_on_small_boxes():
    s = implc.compile(x * (1 - x) + sin(x) * y - x * y)  # x and y repeat: the dependency problem
    rng = np.random.default_rng(0)
    lo = rng.uniform(-1, 1, (500, 3))
    hi = lo + 1e-2
    n_lo, n_hi = s.interval(lo, hi)
    m_lo, m_hi = s.interval(lo, hi, mean_value=True)
    assert np.mean(m_hi - m_lo) < 0.9 * np.mean(n_hi - n_lo)


@pytest.mark.parametrize("name", ["atan2", "atan2_wrapped", "spherical"])
def test_atan2_corners_match_the_reference_on_every_kind_of_box(name, widened):
    """The kernels call atan2 at the two corners where it is extreme; the reference evaluates all four.
    Boxes with every placement of their edges: on, across and beside both axes, tiny, huge, infinite."""
    edges = [-np.inf, -3.0, -1.0, -1e-300, -0.0, 0.0, 1e-300, 0.5, 2.0, np.inf]
    pairs = [(a, b) for a in edges for b in edges if a <= b]
    xs, ys = np.array(pairs * len(pairs)), np.repeat(np.array(pairs), len(pairs), axis=0)
    lo = np.column_stack([xs[:, 0], ys[:, 0], np.full(len(xs), -0.5)])
    hi = np.column_stack([xs[:, 1], ys[:, 1], np.full(len(xs), 0.25)])
    s = widened[name]
    f_lo, f_hi = s.interval(lo, hi)
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    scale = _scale(reference.interval_nodes(s.tape, lo, hi))
    budget = case_budget(s.tape, INTERVAL_BUDGET) * AMPLIFICATION.get(name, 1)
    assert_conforms(f_lo, r_lo, budget, scale, f"{name}: lower bounds")
    assert_conforms(f_hi, r_hi, budget, scale, f"{name}: upper bounds")


def test_jumps_never_use_the_mean_value_form():
    step = implc.compile(Piecewise((1, x < 0), (-1, True)) + y / 100)
    lo, hi = np.array([[-1e-3, 0, 0]]), np.array([[1e-3, 1e-3, 1e-3]])
    f_lo, f_hi = step.interval(lo, hi, mean_value=True)
    assert f_lo[0] <= -1 and f_hi[0] >= 1  # both sides of the jump
    cut = implc.compile(atan2(y, x))
    lo, hi = np.array([[-1.0, -1e-3, 0]]), np.array([[-0.999, 1e-3, 0]])
    f_lo, f_hi = cut.interval(lo, hi, mean_value=True)
    assert f_lo[0] <= -3.14 and f_hi[0] >= 3.14


@pytest.mark.parametrize("width", [1, pytest.param(2, marks=pytest.mark.slow), pytest.param(4, marks=pytest.mark.slow)])
@pytest.mark.parametrize("name", ["spherical", "select_le", "atan2_wrapped", "powi_even", "div_pole", "min"])
def test_every_vector_width_computes_the_same(name, width, surfaces):
    s8, s = surfaces[name], implc.compile(OP_CASES[name], vector_width=width)
    rng = np.random.default_rng(5)
    pts = rng.uniform(-1.5, 1.5, (37, 3))
    np.testing.assert_array_equal(s.eval(pts), s8.eval(pts))
    np.testing.assert_array_equal(s.gradient(pts), s8.gradient(pts))
    lo, hi = adversarial_boxes(rng, 37)
    for mean_value in (False, True):
        np.testing.assert_array_equal(s.interval(lo, hi, mean_value), s8.interval(lo, hi, mean_value))


@pytest.mark.parametrize("name", sorted(OP_CASES))
def test_gradient_matches_differences(name, surfaces):
    s = surfaces[name]
    truth = TrueValues(OP_CASES[name])
    rng = np.random.default_rng(11)
    pts = rng.uniform(-1.2, 1.2, (25, 3))
    grad = s.gradient(pts)
    checked = 0
    for p, g in zip(pts, grad):
        expected = truth.gradient(p)
        if expected is None:
            continue  # F is undefined around p (e.g. log of a negative)
        np.testing.assert_allclose(g, expected, rtol=1e-8, atol=1e-8, err_msg=f"{name} at {p}")
        checked += 1
    assert checked >= 5, f"{name}: too few points inside the domain to check"


def test_point_values_match_true_values(surfaces):
    rng = np.random.default_rng(3)
    pts = rng.uniform(-1.2, 1.2, (40, 3))
    for name, s in surfaces.items():
        truth = TrueValues(OP_CASES[name])
        values = s.eval(pts)
        for p, v in zip(pts, values):
            t = truth.at(p)
            if t is None or t == "pole":
                assert not np.isfinite(v) or t == "pole", f"{name} at {p}: {v} where undefined"
                continue
            assert abs(v - float(t)) <= 1e-12 * (1 + abs(float(t))), f"{name} at {p}: {v} vs {t}"


def test_an_undefined_condition_makes_the_piecewise_undefined():
    """Found by the property test: cbrt(x) < 0 is undefined for x < 0 (principal root), so the Piecewise
    is, and a box reaching x < 0 must not be pruned, whichever branch the comparison would pick."""
    s = implc.compile(Piecewise((x**3, cbrt(x) < 0), (x, True)))
    lo, hi = np.array([[-2.0, 0, 0], [0.5, 0, 0]]), np.array([[3.0, 1, 1], [1.0, 1, 1]])
    f_lo, f_hi = s.interval(lo, hi)
    assert f_lo[0] == -np.inf and f_hi[0] == np.inf
    assert f_lo[1] <= 0.5 and f_hi[1] >= 1.0 and np.isfinite(f_hi[1])
    r_lo, r_hi = reference.eval_interval(s.tape, lo, hi)
    assert r_lo[0] == -np.inf and r_hi[0] == np.inf
    assert np.isnan(s.eval(np.array([[-1.0, 0, 0]]))[0])
    assert np.isnan(reference.eval_point(s.tape, np.array([[-1.0, 0, 0]]))[0][0])


def test_a_condition_whose_sides_cancel_keeps_their_undefinedness():
    """Found by the property test: in cbrt(x + y) <= cbrt(x + y) SymPy's lhs − rhs is 0, which would make
    the condition always true; it is undefined where x + y < 0, and so is the Piecewise there."""
    u = cbrt(x + y)
    s = implc.compile(Piecewise((x + y, u <= u), (8 * x + 8 * y, True)))
    lo, hi = np.array([[-2.0, -1, 0], [0.25, 0.25, 0]]), np.array([[1.0, 1, 1], [0.5, 0.5, 1]])
    f_lo, f_hi = s.interval(lo, hi)
    assert f_lo[0] == -np.inf and f_hi[0] == np.inf
    assert f_lo[1] <= 0.5 and f_hi[1] >= 1.0 and np.isfinite(f_hi[1])
    values = s.eval(np.array([[-1.0, 0.5, 0], [0.5, 0.25, 0]]))
    assert np.isnan(values[0]) and values[1] == 0.75
