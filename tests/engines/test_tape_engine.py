"""The tape engine: per-octant simplification of every Min/Max, against compiled kernels and sampling.

Truths: numpy evaluation of the SymPy expression (``sympy.lambdify``, not implc's compiler) at every grid
corner; the compiled (JIT) kernels as a second backend, which share the interval rules and must give the
same voxels; the unpruned engine, which must give exactly the pruned engine's voxels on Min/Max models (with
smooth blends, whose negligible terms pruning replaces by constants, a superset by a few voxels at most);
mpmath at 40 digits for enclosures.
"""

import math

import mpmath
import numpy as np
import pytest
import sympy
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from sympy import Abs, Max, Min, Piecewise, Rational, cos, sin, sqrt

import implc
from implc import CompileError, x, y, z
from implc.compiler.lower import lower
from implc.compiler.vm import parse_vm
from implc.engines import walk as subdivide_module
from implc.engines.second_look_native import OUTSIDE
from implc.engines.surface import Grouping, choose_engine
from implc.engines.tape import program as tape_program
from implc.engines.tape.program import CHOICE_OPS, FIRST_BINARY, FIRST_TERNARY, OPCODES, encode, slot_scratch
from implc.engines.walk import Buffers, buffers

from ..support.models import CSG, ellipsoid, interpret, smooth_blend
from ..support.models import sign_change_cells as vm_sign_change_cells
from ..support.truth import corner_sign_changes


def sampled_sign_changes(expr, bounds, depth):
    """Cells whose corner values, by numpy (lambdify), change sign, touch 0 or are undefined."""
    n = 1 << depth
    axes = [np.linspace(lo, hi, n + 1) for lo, hi in bounds]
    gx, gy, gz = np.meshgrid(*axes, indexing="ij")
    with np.errstate(all="ignore"):
        f = np.broadcast_to(sympy.lambdify((x, y, z), expr, "numpy")(gx, gy, gz), gx.shape)
    return corner_sign_changes(f)


def _primitive(kind, cx, cy, cz, size):
    c = [Rational(v, 10) for v in (cx, cy, cz)]
    s = Rational(size, 10)
    if kind == "sphere":
        return sqrt((x - c[0])**2 + (y - c[1])**2 + (z - c[2])**2) - s
    if kind == "box":
        return Max(Abs(x - c[0]), Abs(y - c[1]), Abs(z - c[2])) - s
    return (x - c[0]) * Rational(cx + 1, 7) + (y - c[1]) - (z - c[2]) * Rational(cy + 2, 9)  # a plane


primitives = st.builds(_primitive, st.sampled_from(["sphere", "box", "plane"]), st.integers(-7, 7),
                       st.integers(-7, 7), st.integers(-7, 7), st.integers(1, 6))
def _select(a, b, c):
    """Piecewise((a, c < 0), (b, True)): c's sign picks a branch (continuous or not: both are sound)."""
    return Piecewise((a, c < 0), (b, True))


csg = st.recursive(primitives, lambda inner: st.one_of(
    st.builds(Min, inner, inner), st.builds(Max, inner, inner), st.builds(lambda a: -a, inner),
    st.builds(_select, inner, inner, primitives)), max_leaves=8)


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(csg)
def test_random_csg_voxels_agree_across_engines_and_pruning(expr):
    """The natural mode: the same voxels and normals from both engines (the same interval rules), pruned or
    not. The default (each engine's own second look): pruned equals unpruned, a subset of the natural
    voxels, and neither misses a cell sampling finds."""
    bounds = ((-1, 1),) * 3
    tape_surface = implc.compile(expr, bounds, engine="tape")
    jit_surface = implc.compile(expr, bounds, engine="jit")
    pruned = implc.voxelize(tape_surface, 6, storage="coords", **implc.NATURAL)
    unpruned = implc.voxelize(tape_surface, 6, storage="coords", prune=False, **implc.NATURAL)
    compiled = implc.voxelize(jit_surface, 6, storage="coords", **implc.NATURAL)
    np.testing.assert_array_equal(pruned.coords, unpruned.coords)
    np.testing.assert_array_equal(pruned.coords, compiled.coords)
    # normals: the same dual numbers over a shorter program (bit for bit), and the compiled gradient
    np.testing.assert_array_equal(pruned.normals, unpruned.normals)
    np.testing.assert_allclose(pruned.normals, compiled.normals, atol=2e-7)  # float32 rounding of each
    expected = sampled_sign_changes(expr, bounds, 6)
    natural = pruned.to_dense()
    for name, v in (("tape", implc.voxelize(tape_surface, 6, storage="coords")),
                    ("jit", implc.voxelize(jit_surface, 6, storage="coords"))):
        got = v.to_dense()
        missed = np.argwhere(expected & ~got)
        assert len(missed) == 0, f"{expr} ({name}): {len(missed)} missed cells, e.g. {missed[:5].tolist()}"
        assert not (got & ~natural).any()
        if name == "tape":
            unpruned = implc.voxelize(tape_surface, 6, storage="coords", prune=False)
            np.testing.assert_array_equal(v.coords, unpruned.coords)
            np.testing.assert_array_equal(v.normals, unpruned.normals)


def nested_scene():
    """Two far-apart CSG objects, each a nest of Min/Max: below most octants one of them is decided away."""
    left = Max(sqrt((x + Rational(1, 2))**2 + y**2 + z**2) - Rational(3, 10),
               -Min(Abs(x + Rational(1, 2)) - Rational(1, 10), Abs(y) - Rational(1, 10)))
    right = Min(Max(Abs(x - Rational(1, 2)), Abs(y), Abs(z)) - Rational(1, 4),
                sqrt((x - Rational(1, 2))**2 + (y - Rational(3, 10))**2 + z**2) - Rational(1, 5))
    return Min(left, right)


def test_pruning_shortens_the_program_below_decided_octants():
    s = implc.compile(nested_scene(), engine="tape")
    assert s.engine == "tape" and s.program.choices >= 6
    v = implc.voxelize(s, 7)
    full = len(s.program)
    live = v.stats.mean_live_ops
    assert v.stats.program_length == full
    assert live[0] == full  # the root runs everything
    assert live[6] < full / 2, live  # near the surface, one object and few of its branches are left
    unpruned = implc.voxelize(s, 7, prune=False)
    assert unpruned.stats.mean_live_ops[6] == full
    np.testing.assert_array_equal(v.coords, unpruned.coords)
    assert unpruned.stats.interval_evaluations == v.stats.interval_evaluations


def test_a_task_resumes_when_its_output_is_full():
    s = implc.compile(nested_scene(), engine="tape")
    expected = implc.voxelize(s, 7, workers=2)
    with buffers(Buffers(output_chunk=16)):
        chunked = implc.voxelize(s, 7, workers=2)
    np.testing.assert_array_equal(chunked.coords, expected.coords)
    np.testing.assert_array_equal(chunked.normals, expected.normals)
    assert chunked.stats.kept_per_level == expected.stats.kept_per_level


def test_a_task_whose_buffers_grow_keeps_its_second_look(monkeypatch):
    """The engine writes each voxel's flag, and its second look's mark, during the walk: a task whose
    buffers grow in the middle of it keeps them (fresh buffers hold the drop mark here, as recycled memory
    may), so its voxels are those of a task that never grew, none of them dropped unproven."""
    s = implc.compile(smooth_blend(), engine="tape")
    expected = implc.voxelize(s, 7, storage="coords", workers=1)

    def stale(shape, dtype):
        array = np.empty(shape, dtype)
        array.view(np.uint8)[...] = OUTSIDE
        return array
    monkeypatch.setattr(subdivide_module.big_arrays, "empty", stale)
    with buffers(Buffers(output_chunk=16, task_reserve=0)):  # every task starts with 16 rows and grows
        grown = implc.voxelize(s, 7, storage="coords", workers=1)
    np.testing.assert_array_equal(grown.coords, expected.coords)
    assert grown.stats.tightened == expected.stats.tightened


def test_worker_counts_agree():
    s = implc.compile(nested_scene(), engine="tape")
    one, three = implc.voxelize(s, 7, workers=1), implc.voxelize(s, 7, workers=3)
    np.testing.assert_array_equal(one.coords, three.coords)
    np.testing.assert_array_equal(one.normals, three.normals)
    assert one.stats.live_ops_per_level == three.stats.live_ops_per_level


def test_normals_are_unit_and_follow_the_gradient():
    """Against differences of F by numpy (lambdify), at centres where F is smooth (its forward and
    backward differences agree: a centre on a Min/Max crease may take either side's gradient)."""
    expr = nested_scene()
    s = implc.compile(expr, engine="tape")
    v = implc.voxelize(s, 6, storage="coords")
    centres = v.centers()
    f = sympy.lambdify((x, y, z), expr, "numpy")
    step = 1e-6
    forward = np.stack([(f(*(centres + step * e).T) - f(*centres.T)) / step for e in np.eye(3)], axis=1)
    backward = np.stack([(f(*centres.T) - f(*(centres - step * e).T)) / step for e in np.eye(3)], axis=1)
    np.testing.assert_allclose(np.linalg.norm(v.normals, axis=1), 1, atol=1e-6)
    smooth = (np.abs(forward - backward).max(axis=1) < 1e-4) & (np.linalg.norm(forward, axis=1) > 1e-3)
    assert smooth.mean() > 0.5
    unit = forward[smooth] / np.linalg.norm(forward[smooth], axis=1, keepdims=True)
    np.testing.assert_allclose(v.normals[smooth], unit, atol=1e-4)


def test_leaf_refinement_on_the_engine_equals_the_compiled_kernels():
    """refine_leaves keeps a leaf only if one of its eighths may meet F: on the engine (no compiled code),
    the same voxels as the compiled kernels', fewer than without it, and none missed."""
    def t(v):
        return v**4 - 5 * v**2
    expr = Min(t(3 * x) + t(3 * y) + t(3 * z) + Rational(59, 5), Max(x, y) + 2)
    tape = implc.compile(expr, engine="tape")
    refined = implc.voxelize(tape, 6, refine_leaves=True, storage="coords")
    compiled = implc.voxelize(implc.compile(expr, engine="jit"), 6, refine_leaves=True, storage="coords")
    np.testing.assert_array_equal(refined.coords, compiled.coords)
    plain = implc.voxelize(tape, 6, storage="coords", **implc.NATURAL)
    assert len(refined) < 0.8 * len(plain)
    assert tape._native is None, "the engine refined without compiling the surface"
    expected = sampled_sign_changes(expr, tape.bounds, 6)
    assert not (expected & ~refined.to_dense()).any()


def test_the_default_second_look_runs_on_the_engine_too():
    """The default tests again the leaves the linear model at their centre misses (flags from the engine's
    own normals, the test by the engine itself, below each leaf): fewer voxels than the natural mode, a
    subset of them, none missed, the same for every worker count, and nothing compiled for the surface."""
    expr = Max(sin(6 * x) * cos(6 * y) + sin(6 * y) * cos(6 * z) + sin(6 * z) * cos(6 * x),
               sqrt(x**2 + y**2 + z**2) - Rational(9, 10)) + sympy.exp(-8 * x**2) / 4
    s = implc.compile(expr, engine="tape")
    natural = implc.voxelize(s, 7, storage="coords", **implc.NATURAL).to_dense()
    default = implc.voxelize(s, 7, storage="coords", workers=2)
    got = default.to_dense()
    expected = sampled_sign_changes(expr, s.bounds, 7)
    assert not (expected & ~got).any()
    assert not (got & ~natural).any()
    assert got.sum() <= 1.10 * expected.sum() < natural.sum()  # measured: 1.02 and 1.19 at 256³
    assert default.stats.tightened[1] > 0
    np.testing.assert_array_equal(default.coords, implc.voxelize(s, 7, storage="coords", workers=3).coords)
    assert s._native is None and s._bound_native is None, "the engine compiled nothing for the surface"


BOX_GRADIENT_CASES = {  # together every opcode (checked below)
    "csg": Min(sqrt(x**2 + y**2 + z**2) - Rational(1, 2), Max(Abs(x) - Rational(1, 3), -y)),
    "smooth": sympy.exp(x * y) / (2 + cos(z)) - sympy.log(3 + sin(x + y)) + (y - x)**3 - (z + x)**4,
    "selects": Piecewise((x**2 - y, z < x), (y - z, True)) + Piecewise((z, x <= y), (-x, True)),
    # a smooth union (a nonnegative sum of exponentials) plus an exponential term: both watched sums
    "blend": -sympy.log(sympy.exp(-3 * (x**2 + y**2 - z)) + sympy.exp(3 * (x - y))) / 3 + sympy.exp(z - x),
    # a .vm tape keeps its sub instructions; its truth is the same function written in SymPy
    # (with a division by a negative constant and a product with one that is not a double: div_const, mul_const)
    "vm": parse_vm("_0 var-x\n_1 var-y\n_2 var-z\n_3 const 0.25\n_4 sub _0 _1\n_5 mul _4 _2\n_6 sub _5 _3\n"
                   "_7 square _0\n_8 sub _7 _2\n_9 min _6 _8\n_a const -3\n_b div _9 _a\n_c const -0.7\n"
                   "_d mul _c _b\n"),
}
BOX_GRADIENT_TRUTHS = {"vm": Min((x - y) * z - Rational(1, 4), x**2 - z) / -3 * Rational(-7, 10)}


def box_gradient(surface, lo, hi):
    """The engine's enclosures of F and its partials over each box: (n, 8) rows."""
    n = len(lo)
    out, slots = np.empty((n, 8)), slot_scratch(surface.program.slot_count)  # held for the call
    surface.tape_engine.box_gradient(surface.program.header.ctypes.data, slots.ctypes.data, lo.ctypes.data,
                                     hi.ctypes.data, out.ctypes.data, n)
    return out


def _grouped_enclosures(s, lo, hi):
    """Surface.gradient_enclosures with the boxes in two groups (x < 0, x >= 0), each group's box the half
    of [-1, 1]³ it covers: on the engine, each group's program simplified over its half."""
    groups = (lo[:, 0] >= 0).astype(np.int64)
    halves = np.array([[-1, -1, -1, 0, 1, 1], [0, -1, -1, 1, 1, 1]], float)
    return s.gradient_enclosures(lo, hi, groups, lambda labels: (halves[labels, :3], halves[labels, 3:]))


DIRECTIONS = np.array([[0.6, -1.0, 0.3], [1.0, 1.0, 1.0], [0.0, -0.25, 2.0]])
"""Directions for the derivatives along them (one a row): none an axis, one a body diagonal."""


@pytest.mark.parametrize("way", ["engine", "engine grouped", "compiled", "engine directions"])
def test_box_gradients_enclose_the_partials_at_forty_digits(way):
    """The interval-gradient interpreter (the second look's monotonicity test; the mesher's proof of regular
    cells, grouped or compiled, and along the diagonals) against mpmath at 40 digits: at random points of
    random boxes, F and each partial, or each derivative along :data:`DIRECTIONS` (mpmath's own
    differentiation of the SymPy expression, never implc's), lie in the enclosures wherever those are
    defined and finite; most are."""
    mpmath.mp.dps = 40
    rng = np.random.default_rng(7)
    seen = set()
    names = {code: name for name, code in OPCODES.items()}
    for label, expr in BOX_GRADIENT_CASES.items():
        s = implc.compile(expr, engine="jit" if way == "compiled" else "tape")
        if s.program is not None:
            seen |= {names[int(code)] for code in s.program.opcodes}
        f = sympy.lambdify((x, y, z), BOX_GRADIENT_TRUTHS.get(label, expr), "mpmath")
        centres = rng.uniform(-0.9, 0.9, (64, 3))
        half = rng.choice([0.3, 0.05, 0.004], (64, 1)) * rng.uniform(0.2, 1.0, (64, 3))
        half = np.minimum(half, 1 - np.abs(centres))  # within [-1, 1]³, the groups' boxes
        if way == "engine grouped":
            half[:, 0] = np.minimum(half[:, 0], np.abs(centres[:, 0]))  # within its half
        lo, hi = np.ascontiguousarray(centres - half), np.ascontiguousarray(centres + half)
        out = {"engine": box_gradient, "engine grouped": _grouped_enclosures,
               "compiled": lambda s, lo, hi: s.gradient_enclosures(lo, hi),
               "engine directions": lambda s, lo, hi: s.gradient_enclosures(lo, hi, directions=DIRECTIONS),
               }[way](s, lo, hi)
        finite = 0
        for box in range(64):
            usable = [np.isfinite(out[box, 2 + 2 * a: 4 + 2 * a]).all() for a in range(3)]
            finite += all(usable)
            for t in rng.uniform(0, 1, (4, 3)):
                p = [mpmath.mpf(float(v)) for v in lo[box] + t * (hi[box] - lo[box])]
                value = f(*p)
                assert out[box, 0] <= value <= out[box, 1], (label, box, p, value, out[box, :2])
                for a in range(3):
                    if usable[a] and way == "engine directions":
                        along = [mpmath.mpf(float(v)) for v in DIRECTIONS[a]]
                        partial = mpmath.diff(lambda t: f(*[p[k] + t * along[k] for k in range(3)]), 0)
                    elif usable[a]:
                        partial = mpmath.diff(lambda v: f(*[v if k == a else p[k] for k in range(3)]), p[a])
                    if usable[a]:
                        assert out[box, 2 + 2 * a] <= partial <= out[box, 3 + 2 * a], (label, box, a, partial,
                                                                                       out[box])
        assert finite >= 32, f"{label}: only {finite} of 64 boxes have finite partials"
    assert way == "compiled" or seen == set(OPCODES)


def test_derivatives_along_directions_prove_a_crease_the_partials_cannot():
    """At a crease of max(x - 0.1, y - 0.2) every partial's enclosure over a box across it straddles 0
    (its hull holds both sides' partials, 0 and 1), while the derivative along (1, 1, 0) is 1 on both
    sides; the axes as directions give the partials, bit for bit; the compiled kernels and a malformed
    array are refused with a clear message."""
    s = implc.compile(sympy.Max(x - 0.1, y - 0.2), engine="tape")
    lo, hi = np.array([[0.05, 0.15, 0.0]]), np.array([[0.15, 0.25, 0.1]])
    partials = s.gradient_enclosures(lo, hi)
    assert partials[0, 2] <= 0 <= partials[0, 3] and partials[0, 4] <= 0 <= partials[0, 5]
    along = s.gradient_enclosures(lo, hi, directions=[[1, 1, 0], [1, -1, 0], [0, 0, 1]])
    assert 0 < along[0, 2] <= 1 <= along[0, 3] < 2 and along[0, 4] <= 0 <= along[0, 5]
    assert np.array_equal(along[:, :2], partials[:, :2])
    assert np.array_equal(s.gradient_enclosures(lo, hi, directions=np.eye(3)), partials)
    with pytest.raises(ValueError, match="tape engine"):
        implc.compile(sympy.Max(x - 0.1, y - 0.2), engine="jit").gradient_enclosures(lo, hi, directions=np.eye(3))
    with pytest.raises(ValueError, match=r"\(3, 3\)"):
        s.gradient_enclosures(lo, hi, directions=np.eye(2))






def test_the_engine_looks_below_the_leaves_of_a_smooth_blend():
    """The default's second look on the engine splits the flagged leaves it cannot prove whole: on a
    smooth blend it drops most extra voxels (measured: 1.25 -> 1.01 voxels per sign-change cell at
    128³), misses nothing, keeps a subset of the natural voxels, and gives the same voxels pruned or not and
    for every worker count."""
    expr = smooth_blend()
    s = implc.compile(expr, engine="tape")
    expected = sampled_sign_changes(expr, s.bounds, 7)
    natural = implc.voxelize(s, 7, storage="coords", **implc.NATURAL).to_dense()
    default = implc.voxelize(s, 7, storage="coords", workers=1)
    got = default.to_dense()
    assert not (expected & ~got).any()
    assert not (got & ~natural).any()
    assert got.sum() <= 1.05 * expected.sum() and natural.sum() > 1.2 * expected.sum()
    tested, dropped = default.stats.tightened
    assert natural.sum() - got.sum() == dropped <= tested
    other = implc.voxelize(s, 7, storage="coords", workers=2)
    np.testing.assert_array_equal(default.coords, other.coords)
    np.testing.assert_array_equal(default.normals, other.normals)
    # unpruned, no term is replaced by a constant: never a voxel more, at most a handful fewer, all of them
    # next to a sampled sign change (the replaced terms widen the pruned run's enclosures a little)
    near = expected.copy()
    for axis in range(3):
        for shift in (-1, 1):
            near |= np.roll(expected, shift, axis)
    for pruned, options in ((got, {}), (natural, implc.NATURAL)):
        unpruned = implc.voxelize(s, 7, storage="coords", workers=3, prune=False, **options).to_dense()
        extra = pruned & ~unpruned
        assert not (unpruned & ~pruned).any() and extra.sum() <= 0.01 * pruned.sum()
        assert not (extra & ~near).any()


def test_the_second_look_proves_with_negligible_terms_replaced():
    """The second look runs the program whose negligible terms read constants (its proofs hold for the
    family of functions the constants give, docs/soundness.md): on a blend of four ellipsoids far apart, the
    programs two levels above the leaves are shorter than their parents' (terms replaced), and every leaf the
    look drops has F of one strict sign at 5³ points spread over its cell, numpy's F (lambdify), so none
    of them meets the surface, and no sign-change cell is missed."""
    expr = _smooth_unions(11, [ellipsoid((-5, -5, -4), (3, 2, 2), 1), ellipsoid((5, -4, 5), (2, 3, 2), -1),
                               ellipsoid((-4, 5, 5), (2, 2, 3), Rational(1, 2)), ellipsoid((4, 5, -5), (3, 2, 2), 2)])
    bounds, depth = ((-1, 1),) * 3, 7
    s = implc.compile(expr, bounds, engine="tape")
    default = implc.voxelize(s, depth, storage="coords", workers=1)
    natural = implc.voxelize(s, depth, storage="coords", workers=1, **implc.NATURAL)
    live = natural.stats.mean_live_ops
    assert live[depth - 2] < 0.8 * live[depth - 3], live  # terms replaced two levels above the leaves
    got = default.to_dense()
    assert not (sampled_sign_changes(expr, bounds, depth) & ~got).any()
    dropped = np.argwhere(natural.to_dense() & ~got)
    assert len(dropped) > 1000 and len(dropped) == default.stats.tightened[1]
    h = 2.0 / (1 << depth)
    t = np.linspace(0.0, 1.0, 5)
    offsets = np.stack(np.meshgrid(t, t, t, indexing="ij"), -1).reshape(-1, 3)
    points = -1.0 + (dropped[:, None, :] + offsets[None]) * h
    with np.errstate(all="ignore"):
        f = sympy.lambdify((x, y, z), expr, "numpy")(points[..., 0], points[..., 1], points[..., 2])
    one_sign = (f > 0).all(axis=1) | (f < 0).all(axis=1)
    assert one_sign.all(), dropped[~one_sign][:5]


def _smooth_union(a, b, k):
    return -sympy.log(sympy.exp(-k * a) + sympy.exp(-k * b)) / k


def _smooth_unions(k, parts):
    blend = parts[0]
    for part in parts[1:]:  # one k throughout: SymPy turns exp(-k·log(S)/k') into S**(k/k'), which the engine lacks
        blend = _smooth_union(blend, part, k)
    return blend


smooth_blends = st.builds(_smooth_unions, st.sampled_from([4, 11, 30]), st.lists(primitives, min_size=2, max_size=4))


@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(smooth_blends)
def test_random_smooth_blends_miss_no_cell_with_negligible_terms_replaced(expr):
    """Log-sum-exp unions of random primitives on the engine, whose pruning replaces negligible terms by
    constants: no cell that sampling finds is missed in either mode, the pruned run keeps every voxel of
    the unpruned one (its enclosures are only wider), the default within the natural voxels and within 1%
    of the unpruned default's count (the second look drops what the wider enclosures kept; at 64³, where
    the terms' enclosures are widest, the natural mode keeps up to a few per cent more)."""
    bounds = ((-1, 1),) * 3
    s = implc.compile(expr, bounds, engine="tape")
    expected = sampled_sign_changes(expr, bounds, 6)
    voxels = {}
    for mode, options in (("natural", implc.NATURAL), ("default", {})):
        pruned = implc.voxelize(s, 6, storage="coords", **options).to_dense()
        unpruned = implc.voxelize(s, 6, storage="coords", prune=False, **options).to_dense()
        missed = np.argwhere(expected & ~pruned)
        assert len(missed) == 0, f"{expr} ({mode}): {len(missed)} missed cells, e.g. {missed[:5].tolist()}"
        assert not (unpruned & ~pruned).any()
        voxels[mode] = pruned, unpruned
    (natural, _), (default, unpruned_default) = voxels["natural"], voxels["default"]
    assert not (default & ~natural).any()
    assert default.sum() <= 1.01 * unpruned_default.sum()


def far_blobs():
    """Two balls 1.2 apart joined by a log-sum-exp smooth union: near one, the other's term is negligible."""
    def ball(cx):
        return sqrt((x - cx)**2 + y**2 + z**2) - Rational(3, 10)
    return -sympy.log(sympy.exp(-11 * ball(Rational(-6, 10))) + sympy.exp(-11 * ball(Rational(6, 10)))) / 11


def test_a_sum_of_an_exponential_is_marked_and_has_its_constants():
    """A sum's third word marks the operands an exponential gives (the slot's last writer, slots being
    shared), exactly where its opcode is a watched sum's, and such a program's first constants are
    [0, 2^-e], each e of TINY_EXPONENTS in order."""
    for expr, marked in ((far_blobs(), True), (smooth_blend(), True), (nested_scene(), False)):
        program = implc.compile(expr, engine="tape").program
        writer = {}
        marks = 0
        for code, (_, out, a, b, c) in zip(program.opcodes, program.instructions):
            if code in (OPCODES["add"], OPCODES["add_nonneg"], OPCODES["add_watched"], OPCODES["add_nonneg_watched"]):
                assert c == (writer.get(a) == OPCODES["exp"]) | (writer.get(b) == OPCODES["exp"]) << 1
                assert (c != 0) == (code in (OPCODES["add_watched"], OPCODES["add_nonneg_watched"]))
                marks += c != 0
            elif FIRST_BINARY <= code < FIRST_TERNARY:
                assert c == 0
            writer[out] = code
        assert (marks > 0) == marked
        n = len(tape_program.TINY_EXPONENTS) if marked else 0
        assert list(program.constant_slots[:n]) == list(range(n))
        assert [(lo, math.frexp(hi)) for _, lo, hi in program.constants[:n]] == [
            (0.0, (0.5, 1 - e)) for e in tape_program.TINY_EXPONENTS[:n]]


def test_normals_never_come_from_a_program_with_a_term_replaced():
    """The normals are F's gradient by the dual numbers, over a program with no term replaced, whatever
    level the tasks start at: at 16³ with five workers the tasks start one level above the leaves, below
    the octants whose programs replace negligible terms (its normals differed from one worker's by up to
    1.2e-3 when those took that program); the unpruned run's normals are the full program's."""
    s = implc.compile(far_blobs(), engine="tape")
    unpruned = implc.voxelize(s, 4, storage="coords", workers=1, prune=False, **implc.NATURAL)
    for workers in (1, 5):
        v = implc.voxelize(s, 4, storage="coords", workers=workers, **implc.NATURAL)
        assert workers == 1 or v.stats.tasks > 8 ** 2  # tasks below level 2, two above the leaves
        np.testing.assert_array_equal(v.coords, unpruned.coords)
        np.testing.assert_array_equal(v.normals, unpruned.normals)


def test_enclosures_with_negligible_terms_replaced_hold_at_forty_digits():
    """Below a box, a sum reads [0, 2^-e] for an exponential term at most 2^-e over it (and 2^-e at most
    NEGLIGIBLE times the sum's width): the enclosures over boxes inside it, by the program so simplified
    (``implc_tape_grouped``'s mode 3), contain F at 40 digits (mpmath, from the SymPy expression), contain
    the full program's enclosures, and are wider than those in most boxes, by at most 3% on boxes a
    quarter to a half as wide as their group's."""
    mpmath.mp.dps = 40
    expr = far_blobs()
    s = implc.compile(expr, engine="tape")
    f = sympy.lambdify((x, y, z), expr, "mpmath")
    rng = np.random.default_rng(3)
    groups, rows = 48, 8
    side = rng.choice([1 / 8, 1 / 32, 1 / 128], groups)  # the groups' boxes, near either ball's surface
    directions = rng.normal(size=(groups, 3))
    directions /= np.linalg.norm(directions, axis=1)[:, None]
    centres = (np.stack([np.where(rng.uniform(size=groups) < 0.5, -0.6, 0.6), np.zeros(groups), np.zeros(groups)], 1)
               + 0.3 * directions + rng.uniform(-0.5, 0.5, (groups, 3)) * side[:, None])
    group_lo, group_hi = centres - side[:, None] / 2, centres + side[:, None] / 2
    labels = np.repeat(np.arange(groups), rows)
    fraction = rng.uniform(0.25, 0.5, (groups * rows, 1))
    lo = group_lo[labels] + rng.uniform(0, 1, (groups * rows, 3)) * (1 - fraction) * side[labels, None]
    hi = lo + fraction * side[labels, None]
    got = s._grouped(lo, hi, Grouping(labels, lambda chosen: (group_lo[chosen], group_hi[chosen])), 3)[1]
    full_lo, full_hi = s.interval(lo, hi)
    assert (got[:, 0] <= full_lo).all() and (got[:, 1] >= full_hi).all()
    wider = (got[:, 0] < full_lo) | (got[:, 1] > full_hi)
    assert wider.mean() > 0.5
    assert ((got[:, 1] - got[:, 0]) <= 1.03 * (full_hi - full_lo)).all()
    for box in range(0, len(lo), 3):
        for t in rng.uniform(0, 1, (3, 3)):
            value = f(*[mpmath.mpf(float(v)) for v in lo[box] + t * (hi[box] - lo[box])])
            assert got[box, 0] <= value <= got[box, 1], (box, value, got[box])


def test_the_mean_value_form_runs_on_compiled_kernels():
    """The mean-value form needs compiled kernels: a tape surface builds them and misses nothing."""
    expr = nested_scene()
    s = implc.compile(expr, engine="tape")
    expected = sampled_sign_changes(expr, s.bounds, 6)
    got = implc.voxelize(s, 6, storage="coords", mean_value_levels=1).to_dense()
    assert not (expected & ~got).any()
    assert got.sum() <= implc.voxelize(s, 6, storage="coords").to_dense().sum()


def test_the_engine_is_chosen_by_the_tape():
    assert implc.compile(nested_scene()).engine == "tape"  # Min/Max below the top level
    assert implc.compile(Piecewise((x, y < 0), (z, True)) * 2 - 1).engine == "tape"  # a select inside

    def auto(expr, width=8):
        return choose_engine(lower(expr), "auto", width)
    assert auto(Min(x, y, z - 1)) == "jit"  # a top-level chain: the compiled kernels prune it themselves
    assert auto(sympy.sin(x) * y - z) == "jit"
    assert auto(sympy.atan(nested_scene())) == "jit"  # an op the engine lacks
    assert auto(nested_scene(), width=4) == "jit"  # the engine runs eight lanes
    assert auto(sum(((x - Rational(k, 50))**2 * (y - Rational(k, 70)) for k in range(300)), sympy.Integer(0))) == "tape"


def test_each_instruction_names_the_axes_its_value_ignores():
    """An instruction's first word carries, above its opcode, the axes its value does not depend on (whose
    partials the dual numbers and interval gradients make 0): checked by following each program's slots
    from the coordinates' (constants depend on none), apart from the tape's own analysis."""
    seen = 0
    for expr in (nested_scene(), far_blobs(), smooth_blend(),
                 Min(sqrt(x**2 + y**2) - Rational(1, 2), z**2 - x) + sin(z) * cos(y)):
        program = implc.compile(expr, engine="tape").program
        depends = {int(slot): 1 << axis for axis, slot in enumerate(program.variable_slots) if slot >= 0}
        depends |= {int(slot): 0 for slot in program.constant_slots}
        for code, zeros, row in zip(program.opcodes, program.zeros, program.instructions):
            mask = 0
            for operand in _values_read((code, *row[1:])):
                mask |= depends[int(operand)]
            assert zeros == 0b111 & ~mask, (code, row)
            depends[int(row[1])] = mask
            seen += zeros != 0
    assert seen > 0


def _values_read(row):
    code = row[0]
    return list(row[2:3] if code < FIRST_BINARY else row[2:4] if code < FIRST_TERNARY else row[2:5])


def _blob(cx, cy, cz, size, weight):
    """The paper's blend of a blob: (d² − R²)⁴ / R⁸ within R of its centre, exactly 0 beyond, times a weight."""
    r2 = Rational(size, 10) ** 2
    d2 = (x - Rational(cx, 10))**2 + (y - Rational(cy, 10))**2 + (z - Rational(cz, 10))**2
    return Rational(weight, 4) * Piecewise(((d2 - r2)**4 / r2**4, d2 <= r2), (0, True))


blobs = st.lists(st.builds(_blob, st.integers(-7, 7), st.integers(-7, 7), st.integers(-7, 7), st.integers(2, 5),
                           st.integers(1, 8)), min_size=2, max_size=7)
blends = st.one_of(st.builds(lambda terms: Rational(1, 4) - sympy.Add(*terms), blobs),
                   st.builds(lambda terms, other: Min(Rational(1, 4) - sympy.Add(*terms), other), blobs, primitives),
                   st.builds(lambda terms, other: sympy.Add(*terms[1:]) - Rational(3, 2) * terms[0] - other / 8, blobs,
                             primitives))
"""Sums of blends whose terms are exactly 0 away from their blobs (a simplified program drops them: each
term's select decided 0, its scale and its sum's term then the zero constant), alone, in a union, and as
a difference."""


@settings(max_examples=10, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(blends)
def test_random_blends_drop_their_zero_terms_and_agree_pruned_or_not(expr):
    """Where a blend's term is decided 0, what only carried its 0 (its weight, its negation, its sum) reads
    the zero constant or the other operand: the same voxels and normals as the whole program, bit for bit
    (natural and default), F at points grouped by box bit for bit the whole program's, and no cell missed
    against numpy's sampling."""
    bounds = ((-1, 1),) * 3
    surface = implc.compile(expr, bounds, engine="tape")
    assert surface.program.zero >= 0
    for options in (implc.NATURAL, {}):
        pruned = implc.voxelize(surface, 6, storage="coords", **options)
        unpruned = implc.voxelize(surface, 6, storage="coords", prune=False, **options)
        np.testing.assert_array_equal(pruned.coords, unpruned.coords)
        np.testing.assert_array_equal(pruned.normals, unpruned.normals)
        missed = np.argwhere(sampled_sign_changes(expr, bounds, 6) & ~pruned.to_dense())
        assert len(missed) == 0, f"{expr}: {len(missed)} missed cells, e.g. {missed[:5].tolist()}"
    points = np.random.default_rng(5).uniform(-1, 1, (2000, 3))
    cell = np.clip(np.floor((points + 1) * 4), 0, 7).astype(np.int64)
    labels = (cell[:, 0] * 8 + cell[:, 1]) * 8 + cell[:, 2]

    def boxes(distinct):
        g = np.stack([distinct // 64, distinct // 8 % 8, distinct % 8], axis=-1)
        return -1 + g / 4, -1 + (g + 1) / 4

    values, gradients = surface.eval_grouped(points, labels, boxes, gradient=True)
    whole_values, whole_gradients = surface.value_and_gradient(points)
    np.testing.assert_array_equal(values, whole_values)
    np.testing.assert_array_equal(gradients, whole_gradients)


def test_a_blend_of_far_blobs_runs_only_the_near_ones():
    """Thirty blobs: below the octants near one blob the program runs that blob's term and little else (the
    other terms' selects decided 0, and with them their weights and sums: 19 instructions of 303 on average
    below the octants of level 5, 76 when each of those terms still cost three)."""
    rng = np.random.default_rng(3)
    terms = [_blob(*rng.integers(-7, 8, 3), 2, 4) for _ in range(30)]
    s = implc.compile(Rational(1, 4) - sympy.Add(*terms), ((-1, 1),) * 3, engine="tape")
    v = implc.voxelize(s, 6, **implc.NATURAL)
    assert v.stats.mean_live_ops[5] < len(s.program) / 8, (v.stats.mean_live_ops, len(s.program))


def test_a_zero_that_meets_a_sign_of_zero_is_left_alone():
    """A simplified program reads +0 where the whole program may compute −0 (−x, or a sum rounded down):
    the same number for a sum, a product or a choice, but not for a divisor, or for sqrt's and log's
    derivatives (±∞). A program where a value computed from one that may simplify to the zero constant
    reaches one of those keeps its zeros' instructions (no zero slot in its header); a blend's terms reach
    only sums."""
    term = Piecewise(((x - Rational(1, 2))**2 - Rational(1, 16), x < Rational(3, 4)), (0, True))
    assert encode(lower(y - term)).zero >= 0
    assert encode(lower(y - 3 * term + Max(term, z))).zero >= 0
    unevaluated = {"evaluate": False}  # SymPy would take each into the Piecewise's branches (1/0: zoo)
    for expr in (y + sympy.Pow(-2 * term, -1, **unevaluated), y - sympy.sqrt(-term, **unevaluated),
                 y + sympy.log(-term, **unevaluated), y - Abs(term, **unevaluated),
                 y + sympy.Mul(x, sympy.Pow(term, -1, **unevaluated), **unevaluated),
                 y + sympy.Pow(sin(-term, **unevaluated), -1, **unevaluated)):  # sin(−0) is −0: carried on
        assert encode(lower(expr)).zero == -1, expr
    assert encode(lower(y + sympy.Pow(2 + cos(-term, **unevaluated), -1, **unevaluated))).zero >= 0  # cos(±0) = 1
    assert encode(lower(y + term / 3)).zero >= 0  # a quotient's numerator: 0 / c is 0


@settings(max_examples=40, deadline=None)
@given(st.one_of(csg, blends))
def test_slots_are_taken_again_only_where_no_simplified_program_reads_them(expr):
    """Slots are shared by values whose lives do not overlap (a program's slots fit the cache), checked by
    following the program with every value in a slot of its own (the encoding before the allocation): each
    instruction reads the values it read there, and a choice's value operands stay in their slots as long
    as the choice's result is read, so that any simplified program, which reads a decided choice's winner
    in its place, reads the winner's value."""
    captured = {}
    allocate = tape_program._allocate

    def spy(rows, fixed, output, aliasing=None):
        captured["before"], captured["fixed"], captured["aliasing"] = list(rows), list(fixed), aliasing
        result = allocate(rows, fixed, output, aliasing)
        captured["after"], captured["rename"] = list(result[0]), result[1]
        return result
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(tape_program, "_allocate", spy)
        program = encode(implc.compile(expr + x * y, engine="tape").tape)
    before, after, fixed = captured["before"], captured["after"], captured["fixed"]
    assert [(code, *r[1:]) for code, r in zip(program.opcodes, program.instructions)] == [tuple(r) for r in after]
    held = {captured["rename"][f]: f for f in fixed}  # each slot's value, named by its slot before
    assert set(held) == set(program.constant_slots) | {v for v in program.variable_slots if v >= 0}
    for old_row, new_row in zip(before, after):
        assert new_row[0] == old_row[0]
        for old, new in zip(_values_read(old_row), _values_read(new_row)):
            assert held.get(new) == old, (old_row, new_row)  # the value the instruction read before
        assert new_row[1] not in program.constant_slots and new_row[1] not in program.variable_slots
        held[new_row[1]] = old_row[1]
    assert held[program.output] == before[-1][1]
    assert program.slot_count == len({r[1] for r in after} | set(held))
    written_at = {row[1]: i for i, row in enumerate(before)}
    choice_codes = {OPCODES[op] for op in CHOICE_OPS}
    aliasing = captured["aliasing"] or [False] * len(before)
    for i, row in enumerate(before):  # a choice's result read later: its value operands still in place
        if row[0] not in choice_codes and not aliasing[i]:  # and a sum's that may become an alias of one
            continue
        values = _values_read(row)[1:] if row[0] >= FIRST_TERNARY and row[0] in choice_codes else _values_read(row)
        last_read = max([j for j in range(i + 1, len(before)) if row[1] in _values_read(before[j])]
                        + ([len(before)] if row[1] == before[-1][1] else []), default=i)
        for value in values:
            if value in written_at:  # constants' and coordinates' slots are never written
                slot = after[written_at[value]][1]
                assert all(after[k][1] != slot for k in range(written_at[value] + 1, min(last_read, len(after)))), row


@pytest.mark.parametrize("kwargs, words", [
    ({"engine": "gpu"}, "engine must be one of auto, jit, tape"),
    ({"engine": "tape", "expr": sympy.atan(x)}, "engine='tape' cannot run atan"),
    ({"engine": "tape", "vector_width": 4}, "vector_width=4 needs engine='jit'"),
])
def test_bad_engine_requests_are_named(kwargs, words):
    expr = kwargs.pop("expr", x - y)
    with pytest.raises(CompileError, match=words):
        implc.compile(expr, **kwargs)


def test_programs_hold_only_the_work():
    """Constants and coordinates have slots of their own but no instructions; the output is the last
    instruction's slot."""
    s = implc.compile(Max(x * 3, Min(y, z**2)) - 1, engine="jit")
    program = encode(s.tape)
    assert set(program.opcodes) <= set(OPCODES.values())
    assert len(program) == 5  # mul, square, min, max, add (3 and -1 are constants)
    fixed = set(program.constant_slots) | set(program.variable_slots)
    assert len(fixed) == 5 and not fixed & set(program.instructions[:, 1])
    assert program.output == program.instructions[-1, 1]
    assert sorted(program.constants[:, 0]) == [-1.0, 3.0]
    assert program.choices == 2
    assert len(encode(implc.compile(x - 0, engine="jit").tape)) == 0  # F = x: no work


def test_a_vm_model_runs_on_the_engine_without_missing_a_cell():
    from implc.compiler.vm import parse_vm
    model = parse_vm(CSG, name="csg")
    s = implc.compile(model)
    assert s.engine == "tape"
    got = implc.voxelize(s, 6, storage="coords").to_dense()
    expected = vm_sign_change_cells(CSG, model.bounds, 6)
    assert expected.sum() > 100 and not (expected & ~got).any()
    pts = np.random.default_rng(3).uniform(-1.2, 1.2, (64, 3))
    np.testing.assert_allclose(s.eval(pts), interpret(CSG, *pts.T), rtol=1e-12, atol=1e-12)


def test_simplification_stamps_start_over_without_changing_anything(monkeypatch):
    """tape_simplify marks what a program needs with a per-call stamp instead of clearing a buffer; when the
    stamps run out they start over (the buffer cleared once): the voxels are the same."""
    from implc.native import abi
    s = implc.compile(nested_scene(), engine="tape")
    expected = implc.voxelize(s, 7, workers=1)
    original = subdivide_module._Worker.__init__

    def near_the_end(self, depth, words, buffers=()):
        original(self, depth, words, buffers)
        assert len(words) == abi.TAPE_EVALUATOR_WORDS  # the tape engine's evaluator
        self.words[abi.TAPE_STAMP] = 0x7FFFFFFF - 5
    monkeypatch.setattr(subdivide_module._Worker, "__init__", near_the_end)
    again = implc.voxelize(s, 7, workers=1)
    np.testing.assert_array_equal(again.coords, expected.coords)
    np.testing.assert_array_equal(again.normals, expected.normals)


@settings(max_examples=15, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(csg, st.integers(0, 2**31 - 1))
def test_points_grouped_by_box_give_f_and_its_gradient(expr, seed):
    """F (alone, or with its gradient) at points grouped by box (each group's program simplified over its
    box): bit for bit the engine's ungrouped dual numbers (the same rules over a shorter program), and against numpy
    evaluation of the SymPy expression (F) and central differences of it (the gradient, away from kinks)."""
    bounds = ((-1, 1),) * 3
    surface = implc.compile(expr, bounds, engine="tape")
    rng = np.random.default_rng(seed)
    m = 4  # groups per axis
    points = rng.uniform(-1, 1, (1000, 3))
    points[:50] = np.round(points[:50] * m / 2) * 2 / m  # some on the groups' faces
    cell = np.clip(np.floor((points + 1) * m / 2), 0, m - 1).astype(np.int64)
    labels = (cell[:, 0] * m + cell[:, 1]) * m + cell[:, 2]

    def boxes(distinct):
        g = np.stack([distinct // (m * m), distinct // m % m, distinct % m], axis=-1)
        return -1 + g * 2 / m, -1 + (g + 1) * 2 / m

    values, none = surface.eval_grouped(points, labels, boxes)
    assert none is None
    whole = surface.eval(points)  # the whole program's dual numbers' value, bit for bit
    np.testing.assert_array_equal(values, whole)
    # one grouping made for several calls (a vertex's root steps): any points in the same boxes, bit for bit
    plan = Grouping(labels, boxes)
    centres = np.mean(boxes(labels), axis=0)
    moved = points + rng.uniform(0, 1, (len(points), 1)) * (centres - points)  # towards the box's centre
    np.testing.assert_array_equal(surface.eval_grouped(moved, plan)[0], surface.eval(moved))
    np.testing.assert_array_equal(surface.eval_grouped(points, plan)[0], whole)
    # a subset of its rows (the edges still open after a root step) grouped without sorting again
    rows = np.flatnonzero(rng.uniform(size=len(points)) < 0.4)
    subset = plan.subset(rows)
    assert subset.rows == len(rows)
    np.testing.assert_array_equal(surface.eval_grouped(moved[rows], subset)[0], surface.eval(moved[rows]))
    f_values, gradients = surface.eval_grouped(points, labels, boxes, gradient=True)
    f = sympy.lambdify((x, y, z), expr, "numpy")

    def sample(p):
        with np.errstate(all="ignore"):
            return np.broadcast_to(f(*p.T), len(p)).astype(float)

    truth = sample(points)
    # the dual numbers of the whole program, bit for bit: F at every point, the gradient off the faces
    # (there, where Min/Max operands tie, each program's choice of one side is a valid generalized gradient)
    whole_values, whole_gradients = surface.value_and_gradient(points)
    np.testing.assert_array_equal(f_values, whole_values)
    np.testing.assert_array_equal(whole, whole_values)  # eval's point rules: the dual numbers' values
    np.testing.assert_array_equal(gradients[50:], whole_gradients[50:])
    defined = np.isfinite(truth)
    defined[:50] = False  # the points rounded onto the groups' faces tie operands and touch selects' jumps
    np.testing.assert_allclose(f_values[defined], truth[defined], rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(values[defined], truth[defined], rtol=1e-12, atol=1e-12)
    # the gradient against central differences of the sampled F, where the one-sided differences agree
    # (no kink within a step: Min/Max/Abs have one where two operands tie)
    eps = 1e-6
    forward, backward = (np.stack([(sample(points + eps * e) - truth) / eps for e in np.eye(3)], axis=1),
                         np.stack([(truth - sample(points - eps * e)) / eps for e in np.eye(3)], axis=1))
    smooth = defined & (np.abs(forward - backward) < 1e-4).all(1)
    assert smooth.sum() > 100
    np.testing.assert_allclose(gradients[smooth], (forward + backward)[smooth] / 2, rtol=1e-6, atol=1e-6)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.integers(0, 40), max_size=300) | st.lists(st.integers(-2**40, 2**40), max_size=60),
       st.integers(0, 2**31 - 1))
def test_rows_grouped_by_box_are_laid_out_in_whole_blocks_of_their_group(labels, seed):
    """``implc_tape_grouped``'s layout (native ``implc_arrange_groups``), checked row by row in Python: the
    groups in increasing label order, each from a multiple of eight, holding its own rows in row order and
    then its last row again up to the block's end; every row's place holds it; a subset of the rows laid
    out the same way over the kept ones, renumbered in order. Labels in a small range, and sparse ones
    (numbered densely first)."""
    labels = np.array(labels, dtype=np.int64)
    boxes_seen = []

    def boxes(chosen):
        boxes_seen.append(chosen.copy())
        return np.stack([chosen, chosen, chosen], 1) * 1.0, np.stack([chosen, chosen, chosen], 1) + 1.0

    def check(plan, labels):
        distinct = sorted(set(labels.tolist()))
        assert boxes_seen[-1].tolist() == distinct
        np.testing.assert_array_equal(plan.lo[:, 0], distinct)
        assert plan.rows == len(labels) and len(plan.starts) == len(distinct) + 1 and plan.starts[0] == 0
        assert plan.padded == plan.starts[-1] == len(plan.taken)
        for g, label in enumerate(distinct):
            begin, end = plan.starts[g], plan.starts[g + 1]
            assert begin % 8 == 0 and end - begin < len(labels) + 8
            rows = [r for r in range(len(labels)) if labels[r] == label]
            placed = plan.taken[begin:end].tolist()
            assert placed[: len(rows)] == rows
            assert placed[len(rows):] == [placed[len(rows) - 1]] * (end - begin - len(rows))
            assert end - begin == (len(rows) + 7) // 8 * 8
        np.testing.assert_array_equal(plan.taken[plan.place], np.arange(len(labels)))

    plan = Grouping(labels, boxes)
    check(plan, labels)
    kept = np.flatnonzero(np.random.default_rng(seed).uniform(size=len(labels)) < 0.5)
    check(plan.subset(kept), labels[kept])
