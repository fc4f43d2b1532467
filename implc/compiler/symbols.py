"""The six coordinate symbols a surface may use, and their conventions.

Cartesian ``x, y, z``; spherical (ISO 80000-2) ``r = sqrt(x²+y²+z²)``, ``theta`` the polar angle from +z
in [0, π] and ``phi = atan2(y, x)`` in (−π, π]. An expression may mix both kinds freely.
"""

import sympy

x, y, z = sympy.symbols("x y z", real=True)
r = sympy.Symbol("r", nonnegative=True)
theta = sympy.Symbol("theta", real=True)
phi = sympy.Symbol("phi", real=True)

NAMES = ("x", "y", "z", "r", "theta", "phi")


def min_max_as_given(kind, *args):
    """A ``sympy.Min`` or ``sympy.Max`` node of ``args`` in their order, built without SymPy's evaluation
    (which compares every pair of operands) and without its canonical sort (which counts each operand's
    nodes as a tree: exponential in a part whose operands share subexpressions)."""
    node = sympy.Expr.__new__(kind, *args)
    node._argset = frozenset(args)
    return node


def symbols_in(expr) -> set:
    """The symbols of ``expr``, each shared subexpression visited once (SymPy's ``free_symbols`` walks the
    expression as a tree: a part whose operands are shared, as smooth unions share theirs, doubles the walk
    with each one)."""
    found, seen, stack = set(), set(), [expr]
    while stack:
        node = stack.pop()
        if node in seen:
            continue
        seen.add(node)
        if node.is_Symbol:
            found.add(node)
        stack.extend(node.args)
    return found


def replace(expr, mapping: dict, build=None):
    """``expr`` with the subexpressions in ``mapping`` replaced, rebuilt bottom up with an explicit stack
    (no recursion, each shared subexpression once); ``build(func, args)`` makes a changed node (default
    ``func(*args)``, SymPy's evaluation)."""
    done: dict = dict(mapping)
    stack = [expr]
    while stack:
        node = stack[-1]
        if node in done:
            stack.pop()
            continue
        pending = [a for a in node.args if a not in done]
        if pending:
            stack.extend(pending)
            continue
        stack.pop()
        args = [done[a] for a in node.args]
        if all(a is b for a, b in zip(args, node.args)):
            done[node] = node
        else:
            done[node] = build(node.func, args) if build is not None else node.func(*args)
    return done[expr]


def cartesian_mapping(expr) -> dict:
    """What :func:`cartesian_form` replaces in ``expr``: r, theta and phi by their expressions in x, y and
    z, and any other symbol named x, y or z (other assumptions) by ours."""
    rho = sympy.sqrt(x**2 + y**2)
    by_name = {s.name: s for s in symbols_in(expr)}
    subs = {}
    for name, value in (("r", sympy.sqrt(x**2 + y**2 + z**2)), ("theta", sympy.atan2(rho, z)),
                        ("phi", sympy.atan2(y, x))):
        if name in by_name:
            subs[by_name[name]] = value
    for name, sym in (("x", x), ("y", y), ("z", z)):
        if name in by_name and by_name[name] is not sym:
            subs[by_name[name]] = sym
    return subs


def cartesian_form(expr):
    """``expr`` with r, theta and phi replaced by their expressions in x, y and z."""
    subs = cartesian_mapping(expr)
    return replace(expr, subs) if subs else expr
