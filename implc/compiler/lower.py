"""The SymPy front end: lowers an expression in x, y, z, r, theta, phi to a :class:`~implc.compiler.ir.Tape`.

Spherical symbols become their exact Cartesian forms on the tape: r = sqrt(x²+y²+z²) (tight because
even powers are tight), theta = atan2(sqrt(x²+y²), z) and phi = atan2(y, x). When the whole expression is
2π-periodic in phi, phi uses the ``atan2_wrapped`` op, whose interval may wrap past π instead of covering
[−π, π] on boxes that straddle the branch cut. Anything the tape cannot express raises CompileError.
"""

from __future__ import annotations

import contextlib
import signal
import threading
from fractions import Fraction

import sympy

from ..errors import CompileError, shorten
from .ir import Tape, const_attr_from_fraction
from .rounding import POWI_MAX
from .symbols import NAMES

_UNARY = {
    sympy.exp: "exp", sympy.sin: "sin", sympy.cos: "cos", sympy.tan: "tan", sympy.asin: "asin",
    sympy.acos: "acos", sympy.atan: "atan", sympy.sinh: "sinh", sympy.cosh: "cosh", sympy.tanh: "tanh",
    sympy.Abs: "abs",
}


_PERIODIC_FUNCTIONS = (sympy.sin, sympy.cos, sympy.tan)


def is_periodic_in_phi(expr: sympy.Expr) -> bool:
    """True when replacing phi by phi + 2π provably leaves ``expr`` unchanged.

    A structural test, linear in the size of the expression: phi may occur only inside sin, cos or tan of
    an argument k·phi + c with k an integer and c free of phi (then phi + 2π shifts the argument by a
    multiple of 2π). Anything else counts as not periodic, which only costs tightness: phi then covers
    [−π, π] on boxes that straddle its branch cut.
    """
    seen_phi = False
    stack, seen = [expr], set()
    while stack:
        node = stack.pop()
        if node in seen:
            continue
        seen.add(node)
        if node.is_Symbol:
            if node.name == "phi":
                return False  # phi outside a periodic function
            continue
        if isinstance(node, _PERIODIC_FUNCTIONS):
            argument = node.args[0]
            phis = [a for a in sympy.preorder_traversal(argument) if a.is_Symbol and a.name == "phi"]
            if not phis:
                continue
            k = argument.diff(phis[0])
            if not (k.is_Integer and (argument - k * phis[0]).free_symbols.isdisjoint({phis[0]})):
                return False
            seen_phi = True
            continue
        stack.extend(node.args)
    return seen_phi


BINARY_EXPONENT_LIMIT = 4000
"""A float's binary magnitude is clamped to ±this before its exact rational is built: beyond it the value
lies far outside the doubles' range either way (above 1.8e308 or below 4.9e-324), and its enclosure is the
same; without the clamp exp(exp(exp(9))) would be a power of two with about 10^3500 digits."""


def _fraction_of_float(value: sympy.Float) -> Fraction:
    man_sign, man, exp, _ = value._mpf_
    man, exp = int(man), int(exp)
    magnitude = exp + man.bit_length()
    if magnitude > BINARY_EXPONENT_LIMIT:
        exp = BINARY_EXPONENT_LIMIT - man.bit_length()
    elif magnitude < -BINARY_EXPONENT_LIMIT:
        exp = -BINARY_EXPONENT_LIMIT - man.bit_length()
    f = Fraction(man) * (Fraction(2) ** exp)
    return -f if man_sign else f


_UNEVALUATED = (sympy.Integral, sympy.Sum, sympy.Product, sympy.Limit, sympy.Derivative)
PRECISION = 60
"""Decimal digits a numeric constant is evaluated to; it must agree with an evaluation at 80 to 50."""


class UnevaluatedNumber(CompileError):
    """A numeric constant SymPy cannot evaluate to certified digits (too large, or too ill-conditioned):
    the lowering then builds it from its parts (each evaluated, or built so in turn) as ops that the
    kernels enclose soundly, with an infinite bound where a part overflows."""


EVALUATION_SECONDS = 20.0
"""The time one numeric constant's evaluation may take (enforced in the main thread, where the signal
that interrupts it can be delivered)."""


@contextlib.contextmanager
def _time_limit(seconds: float):
    """TimeoutError in the block after ``seconds`` (in the main thread, through SIGALRM; elsewhere, or
    where a timer is already set, no limit)."""
    usable = (hasattr(signal, "setitimer") and threading.current_thread() is threading.main_thread()
              and signal.getitimer(signal.ITIMER_REAL)[0] == 0)
    if not usable:
        yield
        return

    def expired(signum, frame):
        raise TimeoutError

    previous = signal.signal(signal.SIGALRM, expired)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, previous)


def number_bounds(expr: sympy.Expr) -> tuple[float, float, float]:
    """(nearest, lo, hi) doubles enclosing a real SymPy number; CompileError for complex or non-finite
    numbers, and for numbers SymPy cannot evaluate to certified digits. A number beyond the largest double
    gets an infinite bound on its side (see :func:`implc.compiler.ir.const_attr_from_fraction`)."""
    if expr.is_Integer or expr.is_Rational:
        return const_attr_from_fraction(Fraction(int(expr.p), int(expr.q)))
    if expr.is_Float:
        if not expr.is_finite:
            raise CompileError(f"unsupported non-finite number {expr}")
        return const_attr_from_fraction(_fraction_of_float(expr))
    if expr.has(*_UNEVALUATED):  # a sum, integral, ... in closed form if SymPy finds one
        closed = expr.doit()
        if closed.has(*_UNEVALUATED):
            raise CompileError(f"the number {shorten(expr)} has no closed form SymPy can find, and a numerical "
                               "value carries no guarantee: give it in closed form or as a literal")
        return number_bounds(closed)
    try:
        with _time_limit(EVALUATION_SECONDS):
            value = expr.evalf(PRECISION, strict=True)
            check = expr.evalf(PRECISION + 20, strict=True)
    except TimeoutError:
        raise CompileError(f"evaluating the number {shorten(expr)} took more than {EVALUATION_SECONDS:g} s: give "
                           "it in a simpler closed form or as a literal") from None
    except sympy.core.evalf.PrecisionExhausted:
        raise UnevaluatedNumber(f"the number {shorten(expr)} cannot be evaluated to {PRECISION} certified "
                                "digits") from None
    except (OverflowError, MemoryError, RecursionError):
        raise UnevaluatedNumber(f"the number {shorten(expr)} is too large to evaluate") from None
    if value.has(sympy.zoo, sympy.oo, -sympy.oo, sympy.nan):
        raise CompileError(f"unsupported non-finite number {shorten(expr)}")
    if not value.is_real or value.has(sympy.I):
        raise CompileError(f"complex number {shorten(expr)} is not supported (surfaces are real)")
    if not (value.is_Float and check.is_Float):
        raise CompileError(f"cannot evaluate the number {shorten(expr)}")
    approx = _fraction_of_float(value)
    err = abs(approx) * Fraction(1, 10**50) + Fraction(1, 10**300)
    if abs(_fraction_of_float(check) - approx) > err:  # the two evaluations disagree: no digits to trust
        raise UnevaluatedNumber(f"the number {shorten(expr)} cannot be evaluated to {PRECISION} certified digits")
    _, lo, _ = const_attr_from_fraction(approx - err)
    _, _, hi = const_attr_from_fraction(approx + err)
    nearest, _, _ = const_attr_from_fraction(approx)
    return (nearest, lo, hi)


def _meets_on_boundary(then_expr, else_expr, g) -> bool:
    """Whether then − else = g^k·h (k >= 1, h free of poles): the branches agree where g = 0, so the
    Piecewise is continuous there (needed before a mean-value enclosure may cross the boundary).

    A structural test (g, or −g, as a factor) and, for small polynomials, exact division; anything else
    counts as possibly discontinuous, which only costs tightness.
    """
    difference = then_expr - else_expr
    if difference == 0:
        return True
    if difference.has(sympy.nan, sympy.Piecewise):
        return False
    for factor in sympy.Mul.make_args(difference):
        base, exponent = factor.as_base_exp()
        if exponent.is_Integer and exponent > 0 and (base == g or base == -g):
            return True
    try:
        gens = sorted(difference.free_symbols | g.free_symbols, key=lambda s: s.name)
        p, q = sympy.Poly(difference, *gens), sympy.Poly(g, *gens)
        if p.total_degree() > 6 or q.total_degree() < 1:
            return False
        return p.domain.is_Exact and q.domain.is_Exact and p.rem(q).is_zero
    except (sympy.PolynomialError, sympy.GeneratorsNeeded, ValueError):
        return False


def _integer_exponent(exp: sympy.Integer, base) -> int:
    n = int(exp)
    if abs(n) > POWI_MAX:
        raise CompileError(f"the exponent {shorten(exp)} of {shorten(base)} is beyond ±{POWI_MAX}, the largest "
                           "integer power implc compiles")
    return n


def _opens(node) -> bool:
    """Whether the front end looks into ``node``'s parts: not atoms, and not the nodes with bound
    variables (Sum, Integral, ...), which SymPy decides as wholes."""
    if not node.args:
        return False
    number = getattr(type(node), "is_number", None)
    return not isinstance(node, sympy.Expr) or number is sympy.Expr.is_number


class _Lowerer:
    def __init__(self, tape: Tape, wrap_phi: bool):
        self.tape = tape
        self.wrap_phi = wrap_phi
        self.memo: dict[sympy.Basic, int] = {}
        self.numeric: dict[sympy.Basic, bool] = {}  # SymPy's is_number, decided bottom up (it recurses)

    # spherical coordinates, built once and shared
    def _symbol(self, name: str) -> int:
        t = self.tape
        x, y, z = t.var(0), t.var(1), t.var(2)
        if name in ("x", "y", "z"):
            return t.var("xyz".index(name))
        rho2 = t.add(t.powi(x, 2), t.powi(y, 2))
        if name == "r":
            return t.unary("sqrt", t.add(rho2, t.powi(z, 2)))
        if name == "theta":
            return t.node("atan2", (t.unary("sqrt", rho2), z))
        if name == "phi":
            return t.node("atan2_wrapped" if self.wrap_phi else "atan2", (y, x))
        raise CompileError(f"unknown symbol {name} (use x, y, z, r, theta, phi)")

    def lower(self, e: sympy.Basic) -> int:
        """The tape node of ``e``. Its subexpressions are lowered first, bottom up, with an explicit stack
        (each shared one once), so that the rules below only look up their operands: no recursion, however
        deep the expression. Numbers are lowered whole (never their parts)."""
        found = self.memo.get(e)
        if found is not None:
            return found
        self._mark_numbers(e)
        stack, expanded = [(e, False)], set()
        while stack:
            node, ready = stack.pop()
            if node in self.memo or (not ready and node in expanded):
                continue
            if not ready and _opens(node) and not self.numeric.get(node, False):
                expanded.add(node)
                stack.append((node, True))
                stack.extend((arg, False) for arg in node.args if arg not in self.memo)
            elif isinstance(node, sympy.Expr):
                self.memo[node] = self._lower(node)
            # other nodes (conditions, pairs, tuples) are lowered by their rule, from their lowered parts
        return self.memo[e]

    def _mark_numbers(self, e):
        """SymPy's ``is_number`` for every subexpression, decided bottom up (SymPy's own recurses)."""
        stack = [(e, False)]
        while stack:
            node, ready = stack.pop()
            if node in self.numeric:
                continue
            if not ready and _opens(node):
                stack.append((node, True))
                stack.extend((arg, False) for arg in node.args if arg not in self.numeric)
            else:
                self.numeric[node] = (isinstance(node, sympy.Expr) and all(self.numeric[a] for a in node.args)
                                      if _opens(node) else bool(getattr(node, "is_number", False)))

    def _lower(self, e: sympy.Basic) -> int:
        t = self.tape
        if e.is_Symbol:
            if e.name not in NAMES:
                raise CompileError(f"unknown symbol {e.name} (use x, y, z, r, theta, phi)")
            return self._symbol(e.name)
        if self.numeric[e]:  # marked by lower() before any node is lowered
            try:
                return t.const_bounds(*number_bounds(e))
            except UnevaluatedNumber:
                if not e.args:
                    raise
                self.numeric[e] = False  # built from its parts below, as a function of them
        if e.is_Add:
            terms = [self.lower(a) for a in e.args]
            acc = terms[0]
            for term in terms[1:]:
                acc = t.add(acc, term)
            return acc
        if e.is_Mul:
            return self._lower_mul(e)
        if e.is_Pow:
            return self._lower_pow(e.base, e.exp)
        if isinstance(e, sympy.log):
            return t.unary("log", self.lower(e.args[0]))
        if isinstance(e, sympy.atan2):
            return t.node("atan2", (self.lower(e.args[0]), self.lower(e.args[1])))
        if isinstance(e, (sympy.Min, sympy.Max)):
            op = "min" if isinstance(e, sympy.Min) else "max"
            args = [self.lower(a) for a in e.args]
            acc = args[0]
            for a in args[1:]:
                acc = t.node(op, (acc, a))
            return acc
        if isinstance(e, sympy.Piecewise):
            return self._lower_piecewise(list(e.args))
        for cls, op in _UNARY.items():
            if isinstance(e, cls):
                return t.unary(op, self.lower(e.args[0]))
        inlined = getattr(e.func, "implc_tape", None)
        if inlined is not None:  # a model's function (implc.compiler.vm.VmModel.__call__): its tape, at its arguments
            return self._inline(inlined, [self.lower(a) for a in e.args])
        if isinstance(e, sympy.Function):
            raise CompileError(f"unsupported function {e}")
        raise CompileError(f"unsupported expression {e} ({type(e).__name__})")

    def _inline(self, tape: Tape, coords: list[int]) -> int:
        """``tape``'s output with its x, y, z replaced by the nodes ``coords``, one pass over its nodes."""
        if len(coords) != 3:
            raise CompileError(f"a model takes (x, y, z), got {len(coords)} arguments")
        nodes: list[int] = []
        for op, args, attr in tape.nodes:
            nodes.append(coords[attr] if op == "var" else self.tape.node(op, tuple(nodes[a] for a in args), attr))
        return nodes[tape.outputs[0]]

    def _lower_mul(self, e: sympy.Mul) -> int:
        t = self.tape
        coeff, rest = e.as_coeff_mul()
        numer, denom = [], []
        for factor in rest:
            if factor.is_Pow and factor.exp.is_number and factor.exp.is_negative and factor.exp.is_Rational:
                denom.append(self._lower_pow(factor.base, -factor.exp))
            else:
                numer.append(self.lower(factor))
        acc = numer[0] if numer else t.const(1)
        for f in numer[1:]:
            acc = t.mul(acc, f)
        if denom:
            d = denom[0]
            for f in denom[1:]:
                d = t.mul(d, f)
            acc = t.div(acc, d)
        if coeff == -1:
            return t.neg(acc)
        if coeff != 1:
            return t.mul(t.const_bounds(*number_bounds(coeff)), acc)
        return acc

    def _lower_pow(self, base: sympy.Expr, exp: sympy.Expr) -> int:
        t = self.tape
        if base == sympy.E:
            return t.unary("exp", self.lower(exp))
        if exp.is_Float and exp.is_finite and _fraction_of_float(exp).denominator == 1:
            exp = sympy.Integer(int(_fraction_of_float(exp)))  # x ** 2.0 is x ** 2, also for x < 0
        if exp.is_Integer:
            return t.powi(self.lower(base), _integer_exponent(exp, base))
        b = self.lower(base)
        if exp.is_Rational:
            p, q = int(exp.p), int(exp.q)
            root = {2: "sqrt", 3: "cbrt"}.get(q)
            if root is not None:
                return t.powi(t.unary(root, b), _integer_exponent(sympy.Integer(p), base))
            if p > 0:
                return t.node("powf", (b,), float(exp))
            return t.div(t.const(1), t.node("powf", (b,), float(-exp)))
        if exp.is_number:
            nearest, lo, hi = number_bounds(exp)
            if lo == hi and lo > 0:
                return t.node("powf", (b,), lo)
        # general power b ** e = exp(e * log b), defined for b >= 0
        return t.unary("exp", t.mul(self.lower(exp), t.unary("log", b)))

    def _lower_piecewise(self, pieces: list) -> int:
        t = self.tape
        if not pieces:
            return t.const_bounds(float("nan"), float("nan"), float("nan"))
        value, cond = pieces[0]
        if cond == sympy.true:
            return self.lower(value)
        then = self.lower(value)
        otherwise = self._lower_piecewise(pieces[1:])
        # the branches' SymPy forms, to prove continuity: only for a final "otherwise" piece
        final = len(pieces) == 2 and pieces[1][1] == sympy.true
        return self._lower_condition(cond, then, otherwise, branches=(value, pieces[1][0]) if final else None)

    def _lower_condition(self, cond, then: int, otherwise: int, branches=None) -> int:
        """``then`` where ``cond`` holds, else ``otherwise``; ``branches`` are their SymPy forms when the
        condition is a single relational (used to prove the select continuous)."""
        t = self.tape
        if cond == sympy.true:
            return then
        if cond == sympy.false:
            return otherwise
        if isinstance(cond, sympy.And):
            first, *rest = cond.args
            return self._lower_condition(first, self._lower_condition(sympy.And(*rest), then, otherwise),
                                         otherwise)
        if isinstance(cond, sympy.Or):
            first, *rest = cond.args
            return self._lower_condition(first, then, self._lower_condition(sympy.Or(*rest), then, otherwise))
        if isinstance(cond, sympy.ITE):
            test, if_true, if_false = cond.args
            return self._lower_condition(test, self._lower_condition(if_true, then, otherwise),
                                         self._lower_condition(if_false, then, otherwise))
        if isinstance(cond, sympy.Not):
            return self._lower_condition(cond.args[0], otherwise, then)
        if isinstance(cond, sympy.core.relational.Relational):
            # g = lhs - rhs as a SymPy Add, so that g shares its terms with the branches (the blend's
            # condition d² <= R² and its value (d² - R²)⁴ then share one d² - R² node)
            g_expr = cond.lhs - cond.rhs
            g = self.lower(g_expr)
            if _cancels(cond.lhs, cond.rhs, g_expr):  # SymPy cancelled terms that may be undefined
                g = t.node("sub", (self.lower(cond.lhs), self.lower(cond.rhs)))  # NaN where they are
            kind = "continuous" if branches and _meets_on_boundary(branches[0], branches[1], g_expr) else None
            if isinstance(cond, sympy.StrictLessThan):
                return t.node("select_lt", (g, then, otherwise), kind)
            if isinstance(cond, sympy.LessThan):
                return t.node("select_le", (g, then, otherwise), kind)
            if isinstance(cond, sympy.StrictGreaterThan):
                return t.node("select_lt", (t.neg(g), then, otherwise), kind)
            if isinstance(cond, sympy.GreaterThan):
                return t.node("select_le", (t.neg(g), then, otherwise), kind)
            gap = t.unary("abs", g)
            if isinstance(cond, sympy.Equality):
                return t.node("select_le", (gap, then, otherwise))
            if isinstance(cond, sympy.Unequality):
                return t.node("select_le", (gap, otherwise, then))
        raise CompileError(f"unsupported Piecewise condition {cond}")


def _cancels(lhs, rhs, difference) -> bool:
    """Whether ``difference`` (SymPy's lhs − rhs) lost a function or power of lhs or rhs (as cbrt(u) −
    cbrt(u) = 0): where that term is undefined the comparison is too, and the difference no longer says so."""
    def terms(e):
        return e.atoms(sympy.Function, sympy.Pow) if isinstance(e, sympy.Basic) else set()
    return not (terms(lhs) | terms(rhs)) <= terms(difference)


def lower(expr: sympy.Expr) -> Tape:
    """Lower ``expr`` to a tape whose single output is F."""
    tape = Tape()
    lowerer = _Lowerer(tape, is_periodic_in_phi(expr))
    tape.outputs = [lowerer.lower(expr)]
    tape = tape.compacted()
    tape.verify()
    return tape
