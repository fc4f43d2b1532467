"""Solids: 3D primitives as SymPy expressions F (F < 0 inside, F > 0 outside), and the paper's blobs.

A primitive called *exact* is F = the signed Euclidean distance to its surface everywhere (‖∇F‖ = 1
wherever F is differentiable); the others say what they are instead (a bound, or another field). Blobs
follow the paper's polynomial blend g(d) = (d² − R²)⁴ / R⁸ for d ≤ R, else 0.
"""

from __future__ import annotations

from collections.abc import Sequence

import sympy

from ..compiler.symbols import x, y, z
from .vectors import Number, Vec, absolute, clamp, length, maximum, minimum, positive, positive_part, unit
from .vectors import vec3 as _vec


def _squared_distance(center):
    cx, cy, cz = _vec(center, "center")
    return (x - cx) ** 2 + (y - cy) ** 2 + (z - cz) ** 2


def _size(v: Number, name: str) -> sympy.Expr:
    """A size as given: a number must be above 0 (an expression, a size that varies over space, is the
    user's to keep positive)."""
    value = sympy.sympify(v)
    return positive(value, name) if value.is_number else value


def sphere(radius: Number = 1, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Signed-distance sphere: ‖p − c‖ − radius.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(sphere(1, (1, 0, 0)).subs({x: 3, y: 0, z: 0})), 6)
    1.0
    """
    return sympy.sqrt(_squared_distance(center)) - _size(radius, "radius")


def box(half_sizes: Vec = (1, 1, 1), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Axis-aligned box as max(abs(pᵢ − cᵢ) − hᵢ) over the axes (exact inside, a lower bound outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(box((1, 1, 1)).subs({x: 0, y: 0, z: 3})), 6)
    2.0
    """
    hx, hy, hz = _vec(half_sizes, "half_sizes")
    cx, cy, cz = _vec(center, "center")
    return maximum(absolute(x - cx) - hx, absolute(y - cy) - hy, absolute(z - cz) - hz)


def torus(major: Number = 1, minor: Number = sympy.Rational(1, 4), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Torus around the z axis: (sqrt(x² + y²) − major)² + z² − minor².

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(torus(1, 0.25).subs({x: 1, y: 0, z: 0})), 6)
    -0.0625
    """
    cx, cy, cz = _vec(center, "center")
    ring = sympy.sqrt((x - cx) ** 2 + (y - cy) ** 2) - major
    return ring**2 + (z - cz) ** 2 - _size(minor, "minor") ** 2


def cylinder(radius: Number = 1, height: Number = 2, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Capped cylinder along z: max(radial distance − radius, abs(z − cz) − height / 2).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(cylinder(1, 2).subs({x: 3, y: 0, z: 0})), 6)
    2.0
    """
    cx, cy, cz = _vec(center, "center")
    return maximum(sympy.sqrt((x - cx) ** 2 + (y - cy) ** 2) - _size(radius, "radius"),
                   absolute(z - cz) - _size(height, "height") / sympy.S(2))


def blend(squared_distance: sympy.Expr, radius: Number) -> sympy.Expr:
    """The paper's blend g(d) = (d² − R²)⁴ / R⁸ for d ≤ R, else 0, written in d² (no square root).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(blend(x**2 + y**2 + z**2, 1).subs({x: 0, y: 0, z: 0})), 6)
    1.0
    """
    r2 = sympy.sympify(radius) ** 2
    return sympy.Piecewise(((squared_distance - r2) ** 4 / r2**4, squared_distance <= r2), (0, True))


def blobs(centers: Sequence[Vec], radius: Number, threshold: Number,
          weights: Sequence[Number] | None = None) -> sympy.Expr:
    """Blended blobs: threshold − Σ wᵢ g(‖p − cᵢ‖), negative inside (where the field exceeds threshold).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(blobs([(0, 0, 0)], 1, 0.5).subs({x: 0, y: 0, z: 0})), 6)
    -0.5
    """
    centers = list(centers)
    if not centers:
        raise ValueError("blobs needs at least one center")
    weights = [1] * len(centers) if weights is None else list(weights)
    if len(weights) != len(centers):
        raise ValueError(f"{len(weights)} weights for {len(centers)} centers")
    field = sympy.Add(*[sympy.sympify(w) * blend(_squared_distance(c), radius) for c, w in zip(centers, weights)])
    return sympy.sympify(threshold) - field




def box_exact(half_sizes: Vec = (1, 1, 1), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Axis-aligned box, exact: the length of the outward overshoot q = abs(p − c) − h beyond the faces, or the
    largest (negative) component inside.

    >>> from implc.compiler.symbols import x, y, z
    >>> f = box_exact((1, 1, 1))
    >>> float(f.subs({x: 2, y: 2, z: 0})), float(f.subs({x: 0, y: 0, z: 0}))
    (1.4142135623730951, -1.0)
    """
    hx, hy, hz = _vec(half_sizes, "half_sizes")
    cx, cy, cz = _vec(center, "center")
    q = (absolute(x - cx) - hx, absolute(y - cy) - hy, absolute(z - cz) - hz)
    return length(*map(positive_part, q)) + minimum(maximum(*q), 0)


def rounded_box(half_sizes: Vec = (1, 1, 1), radius: Number = sympy.Rational(1, 10),
                center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Box with its edges and corners rounded by ``radius`` (within the half sizes), exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> float(rounded_box((1, 1, 1), 0.25).subs({x: 2, y: 0, z: 0}))
    1.0
    """
    r = positive(radius, "radius")
    h = _vec(half_sizes, "half_sizes")
    if any(not (hi > r) for hi in h):
        raise ValueError(f"radius {radius} must be below every half size {tuple(half_sizes)}")
    return box_exact(tuple(hi - r for hi in h), center) - r


def torus_exact(major: Number = 1, minor: Number = sympy.Rational(1, 4), center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Torus around the z axis, exact: the distance to its core circle minus ``minor``.

    >>> from implc.compiler.symbols import x, y, z
    >>> float(torus_exact(1, 0.25).subs({x: 1, y: 0, z: 1}))
    0.75
    """
    cx, cy, cz = _vec(center, "center")
    return length(length(x - cx, y - cy) - major, z - cz) - positive(minor, "minor")


def capsule(a: Vec, b: Vec, radius: Number) -> sympy.Expr:
    """The points within ``radius`` of the segment from ``a`` to ``b``, exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> float(capsule((0, 0, -1), (0, 0, 1), 0.5).subs({x: 0, y: 0, z: 3}))
    1.5
    """
    ax, ay, az = _vec(a, "a")
    bx, by, bz = _vec(b, "b")
    d = (bx - ax, by - ay, bz - az)
    dd = sum(c**2 for c in d)
    if dd == 0:
        return sphere(radius, (ax, ay, az))
    t = clamp(((x - ax) * d[0] + (y - ay) * d[1] + (z - az) * d[2]) / dd, 0, 1)
    return length(x - ax - t * d[0], y - ay - t * d[1], z - az - t * d[2]) - positive(radius, "radius")


def capped_cylinder(radius: Number = 1, height: Number = 2, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Cylinder along z with flat caps, exact (:func:`cylinder` is the same solid with a bound outside its
    rims).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(capped_cylinder(1, 2).subs({x: 0, y: 0, z: 3})), 6)
    2.0
    """
    cx, cy, cz = _vec(center, "center")
    w = (length(x - cx, y - cy) - positive(radius, "radius"), absolute(z - cz) - positive(height, "height") / 2)
    return minimum(maximum(*w), 0) + length(*map(positive_part, w))


def cone(radius: Number = 1, height: Number = 2, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Cone along z, its base of ``radius`` at z = cz − height/2 and its apex at z = cz + height/2: the
    largest of the base plane's and the slanted side's signed distances (exact inside; a bound outside, near
    the rim and beyond the apex).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(cone(1, 2).subs({x: 0, y: 0, z: -1.5})), 6)
    0.5
    """
    cx, cy, cz = _vec(center, "center")
    r, h = positive(radius, "radius"), positive(height, "height")
    slant = sympy.sqrt(r**2 + h**2)
    side = (h * length(x - cx, y - cy) + r * (z - cz) - r * h / 2) / slant
    return maximum(side, cz - h / 2 - z)


def ellipsoid(radii: Vec, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Ellipsoid with semi-axes ``radii``: k₀(k₀ − 1)/k₁ with k₀ = abs(p/r) and k₁ = abs(p/r²) (zero on the surface
    and of the right sign, close to the distance near it; not exact).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(ellipsoid((2, 1, 1)).subs({x: 2, y: 0, z: 0})), 6)
    0.0
    """
    rx, ry, rz = (positive(v, "radii") for v in _vec(radii, "radii"))
    cx, cy, cz = _vec(center, "center")
    k0 = length((x - cx) / rx, (y - cy) / ry, (z - cz) / rz)
    k1 = length((x - cx) / rx**2, (y - cy) / ry**2, (z - cz) / rz**2)
    return k0 * (k0 - 1) / k1


def half_space(normal: Vec = (0, 0, 1), offset: Number = 0) -> sympy.Expr:
    """The points p with n̂·p < ``offset`` (n̂ the unit ``normal``), exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(half_space((0, 0, 1), 1).subs({x: 0, y: 0, z: 3})), 6)
    2.0
    """
    nx, ny, nz = unit(normal, "normal")
    return nx * x + ny * y + nz * z - sympy.sympify(offset)


def slab(normal: Vec = (0, 0, 1), thickness: Number = 1, offset: Number = 0) -> sympy.Expr:
    """The points within ``thickness``/2 of the plane n̂·p = ``offset``, exact.

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(slab((1, 0, 0), 2).subs({x: 3, y: 0, z: 0})), 6)
    2.0
    """
    return absolute(half_space(normal, offset)) - positive(thickness, "thickness") / 2


def _planes(normals, distance) -> sympy.Expr:
    return maximum(*[half_space(n, distance) for n in normals])


def pyramid(base: Number = 1, height: Number = 1, center: Vec = (0, 0, 0)) -> sympy.Expr:
    """Square pyramid along z: its base 2·``base`` wide at z = cz, its apex ``height`` above; the largest of
    its faces' signed distances (exact inside, a bound outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(pyramid(1, 1).subs({x: 0, y: 0, z: 0.5})), 6)
    -0.353553
    """
    b, h = positive(base, "base"), positive(height, "height")
    cx, cy, cz = _vec(center, "center")
    slant = sympy.sqrt(h**2 + b**2)
    faces = [(s * across * h + b * (z - cz) - b * h) / slant for across in (x - cx, y - cy) for s in (1, -1)]
    return maximum(*faces, cz - z)


def tetrahedron(size: Number = 1) -> sympy.Expr:
    """Regular tetrahedron centred at the origin, its faces ``size`` from it (exact inside, a bound outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(tetrahedron(1).subs({x: 0, y: 0, z: 0})), 6)
    -1.0
    """
    return _planes([(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)], positive(size, "size"))


def octahedron(size: Number = 1) -> sympy.Expr:
    """Regular octahedron centred at the origin, its faces ``size`` from it (exact inside, a bound outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(octahedron(1).subs({x: 0, y: 0, z: 0})), 6)
    -1.0
    """
    return _planes([(a, b, c) for a in (1, -1) for b in (1, -1) for c in (1, -1)], positive(size, "size"))


_PHI = (1 + sympy.sqrt(5)) / 2


def dodecahedron(size: Number = 1) -> sympy.Expr:
    """Regular dodecahedron centred at the origin, its faces ``size`` from it (exact inside, a bound
    outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(dodecahedron(1).subs({x: 0, y: 0, z: 0})), 6)
    -1.0
    """
    normals = [v for a in (1, -1) for b in (1, -1) for v in ((0, a, b * _PHI), (a, b * _PHI, 0), (b * _PHI, 0, a))]
    return _planes(normals, positive(size, "size"))


def icosahedron(size: Number = 1) -> sympy.Expr:
    """Regular icosahedron centred at the origin, its faces ``size`` from it (exact inside, a bound outside).

    >>> from implc.compiler.symbols import x, y, z
    >>> round(float(icosahedron(1).subs({x: 0, y: 0, z: 0})), 6)
    -1.0
    """
    normals = [(a, b, c) for a in (1, -1) for b in (1, -1) for c in (1, -1)]
    normals += [v for a in (1, -1) for b in (1, -1) for v in ((0, a / _PHI, b * _PHI), (a / _PHI, b * _PHI, 0),
                                                                (b * _PHI, 0, a / _PHI))]
    return _planes(normals, positive(size, "size"))
