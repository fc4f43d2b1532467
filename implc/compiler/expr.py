"""Safe parsing of surface formulas typed on the command line (``implc voxelize --expr``).

The text is parsed with Python's ``ast`` module and rebuilt node by node into SymPy; nothing is ever
evaluated. Only numbers, the six coordinate symbols, pi and E, + − × ÷ **, and the functions the
compiler supports are accepted; anything else is refused with a message naming it.
"""

from __future__ import annotations

import ast
import operator

import sympy

from ..errors import ExprError, shorten
from .rounding import POWI_MAX
from .symbols import phi, r, theta, x, y, z

NAMES = {"x": x, "y": y, "z": z, "r": r, "theta": theta, "phi": phi, "pi": sympy.pi, "E": sympy.E, "e": sympy.E}
FUNCTIONS = {
    "sin": sympy.sin, "cos": sympy.cos, "tan": sympy.tan, "asin": sympy.asin, "acos": sympy.acos,
    "atan": sympy.atan, "atan2": sympy.atan2, "sinh": sympy.sinh, "cosh": sympy.cosh, "tanh": sympy.tanh,
    "exp": sympy.exp, "log": sympy.log, "sqrt": sympy.sqrt, "cbrt": sympy.cbrt, "abs": sympy.Abs,
    "Abs": sympy.Abs, "min": sympy.Min, "Min": sympy.Min, "max": sympy.Max, "Max": sympy.Max,
}
BINARY = {ast.Add: operator.add, ast.Sub: operator.sub, ast.Mult: operator.mul, ast.Div: operator.truediv,
          ast.Pow: operator.pow}
MAX_LENGTH = 10_000
MAX_NUMERIC_EXPONENT = 64
"""The largest exponent of a number raised to a number (2**64**64 would take the machine's memory)."""
MAX_ARGUMENT_BITS = 1 << 16
"""A function of a number beyond 2^MAX_ARGUMENT_BITS in magnitude is refused: SymPy evaluates a function
of a number as it builds it, and mpmath's exp, cosh or sin of such a number ran for minutes (cosh(exp(1e8)
* 1e308): its argument reduction works to as many bits as the number's exponent); every such value is
far beyond a double anyway."""


def parse(text: str) -> sympy.Expr:
    if len(text) > MAX_LENGTH:
        raise ExprError(f"expression longer than {MAX_LENGTH} characters")
    if not text.strip():
        raise ExprError("the expression is empty")
    try:
        tree = ast.parse(text.strip(), mode="eval")
        return _build(tree.body)
    except SyntaxError as exc:
        raise ExprError(f"cannot parse {shorten(text, quoted=True)}: {exc.msg}") from None
    except (RecursionError, MemoryError):
        raise ExprError("the expression is nested too deeply") from None
    except OverflowError:  # SymPy evaluates as it builds (cosh of cosh of ... asks mpmath whether it is zero)
        raise ExprError(f"a number in {shorten(text, quoted=True)} is too large for SymPy to build") from None
    except ZeroDivisionError:  # a number divided by a number that is zero only once evaluated
        raise ExprError(f"division by zero in {shorten(text, quoted=True)}") from None



def _build(node) -> sympy.Expr:
    if isinstance(node, ast.Constant) and type(node.value) in (int, float):
        return sympy.Integer(node.value) if isinstance(node.value, int) else sympy.Float(repr(node.value))
    if isinstance(node, ast.Name):
        if node.id in NAMES:
            return NAMES[node.id]
        raise ExprError(f"unknown name {node.id!r} (use x, y, z, r, theta, phi, pi, E)")
    if isinstance(node, ast.BinOp) and type(node.op) in BINARY:
        left, right = _build(node.left), _build(node.right)
        if isinstance(node.op, ast.Pow) and right.is_number:
            if right.is_extended_real is not True:  # (-1)**pi: the comparison below would raise TypeError
                raise ExprError(f"exponent {shorten(right)} is not a real number (surfaces are real)")
            limit = MAX_NUMERIC_EXPONENT if left.is_number else POWI_MAX
            if not abs(right) <= limit:
                raise ExprError(f"exponent {shorten(right)} is too large (at most {limit}"
                                f"{' for a number' if left.is_number else ''})")
        if isinstance(node.op, ast.Div) and right.is_zero:  # 0.0 too (a Float is not == the Integer 0)
            raise ExprError(f"division by zero in {shorten(ast.unparse(node), quoted=True)}")
        return _sympy(node, BINARY[type(node.op)], left, right)
    if isinstance(node, ast.BinOp) and isinstance(node.op, ast.BitXor):
        raise ExprError("'^' is not a power: write x**2")
    if isinstance(node, ast.UnaryOp) and isinstance(node.op, (ast.USub, ast.UAdd)):
        value = _build(node.operand)
        return -value if isinstance(node.op, ast.USub) else value
    if isinstance(node, ast.Call):
        if not isinstance(node.func, ast.Name) or node.func.id not in FUNCTIONS:
            name = node.func.id if isinstance(node.func, ast.Name) else ast.unparse(node.func)
            raise ExprError(f"function {name!r} is not allowed (allowed: {', '.join(sorted(FUNCTIONS))})")
        if node.keywords:
            raise ExprError(f"keyword arguments are not allowed in {node.func.id}()")
        if not node.args:
            raise ExprError(f"{node.func.id}() needs an argument")
        args = [_build(a) for a in node.args]
        if any(_huge(a) for a in args):
            raise ExprError(f"a number in {shorten(ast.unparse(node), quoted=True)} is too large (beyond "
                            f"2^{MAX_ARGUMENT_BITS}) for a function of it to be built")
        return _sympy(node, FUNCTIONS[node.func.id], *args)
    raise ExprError(f"{type(node).__name__} is not allowed: only numbers, x y z r theta phi, + - * / ** and "
                    f"functions ({ast.unparse(node)!r})")


def _sympy(node, operation, *args) -> sympy.Expr:
    """``operation(*args)`` (SymPy builds and evaluates as it goes): its own failures named in one line
    (asin(cos(10 / (pi / 1e300))) made SymPy's cache fail with an AttributeError)."""
    try:
        return operation(*args)
    except (OverflowError, ZeroDivisionError, RecursionError, MemoryError):
        raise  # parse() names them
    except Exception as exc:  # noqa: BLE001 - SymPy's own failure on this formula
        if isinstance(node, ast.Call) and isinstance(exc, (TypeError, ValueError)):  # atan2 of one argument
            raise ExprError(f"bad call {ast.unparse(node)}: {exc}") from None
        raise ExprError(f"SymPy cannot build {shorten(ast.unparse(node), quoted=True)} ({type(exc).__name__})") \
            from None


def _huge(value) -> bool:
    """Whether ``value`` is a number beyond 2^MAX_ARGUMENT_BITS in magnitude (a Float's exponent, an exact
    number's bit length)."""
    if isinstance(value, sympy.Float):
        _, mantissa, exponent, bits = value._mpf_
        return bool(mantissa) and exponent + bits > MAX_ARGUMENT_BITS
    if isinstance(value, sympy.Rational):
        return abs(value.p).bit_length() - value.q.bit_length() > MAX_ARGUMENT_BITS
    return False
