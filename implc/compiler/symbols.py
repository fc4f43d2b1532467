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


def cartesian_form(expr):
    """``expr`` with r, theta and phi replaced by their expressions in x, y and z."""
    rho = sympy.sqrt(x**2 + y**2)
    by_name = {s.name: s for s in expr.free_symbols}
    subs = {}
    for name, value in (("r", sympy.sqrt(x**2 + y**2 + z**2)), ("theta", sympy.atan2(rho, z)),
                        ("phi", sympy.atan2(y, x))):
        if name in by_name:
            subs[by_name[name]] = value
    for name, sym in (("x", x), ("y", y), ("z", z)):
        if name in by_name and by_name[name] is not sym:
            subs[by_name[name]] = sym
    return expr.xreplace(subs)
