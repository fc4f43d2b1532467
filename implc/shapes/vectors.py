"""Numbers and points as the shape builders take them, the few vector operations they share, and the
builders' Min, Max, Abs and substitution.

SymPy's own Min and Max compare every pair of their arguments when they are built (to drop the ones that
cannot win), and each comparison asks the assumptions system about the difference of two shapes: a part
of a few hundred operations took minutes to build, most of it in those questions, and again each time a
transform rebuilt the tree. The builders never need that pruning (the tape engine prunes per octant, with
proofs), so :func:`minimum`, :func:`maximum` and :func:`absolute` build the node as given, and
:func:`substitute` rebuilds a shape through them.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import sympy

Number = Any
"""A number: int, float or a SymPy number (exact where it is a Rational or an Integer)."""
Vec = Sequence[Any]
"""Three numbers (x, y, z)."""


def vec3(v: Vec, name: str = "point") -> tuple[sympy.Expr, sympy.Expr, sympy.Expr]:
    """``v`` as three SymPy numbers; ValueError naming ``name`` otherwise."""
    values = tuple(sympy.sympify(c) for c in v)
    if len(values) != 3:
        raise ValueError(f"{name} needs three coordinates, got {v!r}")
    return values  # type: ignore[return-value]


def number(v: Number, name: str) -> sympy.Expr:
    """``v`` as a SymPy number; ValueError naming ``name`` where it is not one."""
    value = sympy.sympify(v)
    if not value.is_number:
        raise ValueError(f"{name} must be a number, got {v!r}")
    return value


def positive(v: Number, name: str) -> sympy.Expr:
    """``v`` as a SymPy number above 0."""
    value = number(v, name)
    if not value.is_positive:
        raise ValueError(f"{name} must be above 0, got {v!r}")
    return value


def length(*components: sympy.Expr) -> sympy.Expr:
    """The Euclidean length of a vector given by its components."""
    return sympy.sqrt(sympy.Add(*[c**2 for c in components]))


def _extremum(kind, args) -> sympy.Expr:
    flat: list = []
    for arg in map(sympy.sympify, args):
        flat.extend(arg.args if isinstance(arg, kind) else (arg,))
    unique = list(dict.fromkeys(flat))
    if not unique:
        raise ValueError(f"{kind.__name__} of no shapes")
    if len(unique) == 1:
        return unique[0]
    if all(a.is_number for a in unique):
        return kind(*unique)  # numbers only: SymPy's comparison is cheap and exact
    from ..compiler.symbols import min_max_as_given
    return min_max_as_given(kind, *unique)


def minimum(*args: sympy.Expr) -> sympy.Expr:
    """min of ``args`` as one Min node (nested Mins merged, repeats dropped), built without comparing them."""
    return _extremum(sympy.Min, args)


def maximum(*args: sympy.Expr) -> sympy.Expr:
    """max of ``args`` as one Max node, built like :func:`minimum`."""
    return _extremum(sympy.Max, args)


def absolute(v: sympy.Expr) -> sympy.Expr:
    """abs(v), built without asking for v's sign (a number's is taken)."""
    v = sympy.sympify(v)
    return sympy.Abs(v) if v.is_number else sympy.Abs(v, evaluate=False)


_REBUILD = {sympy.Min: minimum, sympy.Max: maximum, sympy.Abs: absolute}


def _build(func, args):
    if func in _REBUILD:
        return _REBUILD[func](*args)
    if func is sympy.Pow and not args[0].is_number:  # SymPy's Pow asks for the base's sign to simplify: slow
        return sympy.Pow(*args, evaluate=False)
    return func(*args)


def substitute(expr: sympy.Expr, mapping: dict) -> sympy.Expr:
    """``expr`` in Cartesian form with x, y and z replaced as ``mapping`` says, Min, Max and Abs rebuilt
    through :func:`minimum`, :func:`maximum` and :func:`absolute` (each shared subexpression once, no
    recursion: a deep part cannot exhaust Python's stack)."""
    from ..compiler.symbols import cartesian_mapping, replace
    full = {symbol: value.xreplace(mapping) for symbol, value in cartesian_mapping(expr).items()}
    return replace(expr, {**mapping, **full}, build=_build)


def positive_part(v: sympy.Expr) -> sympy.Expr:
    """max(v, 0)."""
    return maximum(v, 0)


def clamp(v: sympy.Expr, lo: Number, hi: Number) -> sympy.Expr:
    """v limited to [lo, hi]."""
    return minimum(maximum(v, lo), hi)


def unit(v: Vec, name: str = "direction") -> tuple[sympy.Expr, sympy.Expr, sympy.Expr]:
    """``v`` scaled to length 1 (exactly, as SymPy numbers)."""
    a, b, c = vec3(v, name)
    n = sympy.sqrt(a**2 + b**2 + c**2)
    if n == 0:
        raise ValueError(f"{name} must not be zero")
    return a / n, b / n, c / n
