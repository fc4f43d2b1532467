"""The subdivision walk is written once over an evaluator (implc.engines.walk_native): a third evaluator, written here
in a few lines of IR for one ball (an Evaluator for the walk's code, a WalkEvaluator for the driver, nothing
else), runs through the same walk and the same Python driver as the compiled kernels and the tape engine,
and gives the voxels, the inside octants and the normals that the exact arithmetic of the ball and the two
engines give."""

from __future__ import annotations

import hashlib

import numpy as np
import pytest
from llvmlite import ir
from sympy import Rational

import implc
from implc import x, y, z
from implc.compiler.llvm.control import I32, I64, Local, const, for_range, load_at, store_at
from implc.engines.morton import morton_codes
from implc.engines.rows_native import ROWS
from implc.engines.walk import Subdivider, WalkEvaluator
from implc.engines.walk_native import Evaluator, Walk, emit_walk
from implc.native import abi
from implc.native.jit import NativeModule

DOUBLE = ir.DoubleType()
RADIUS2 = 0.5  # x² + y² + z² - 1/2: at depth 5 on [-1, 1]³ every corner value is a multiple of 2^-8, exact
DEPTH = 5
BALL_WALK = abi.Entry("implc_ball_walk", abi.WALK_PARAMS, "i64")


class BallEvaluator(Evaluator):
    """F = x² + y² + z² - RADIUS2, its children enclosed one by one, its normals the unit centres, no second
    look: nothing else of implc's."""

    def start(self, walk: Walk, level, cell) -> None:
        pass

    def boxes(self, walk: Walk, level, cell):
        """The enclosures of F over the eight children of ``cell`` at ``level`` (as the walk's geometry
        makes them: origin + i·h, padded outward): (lo, hi) pairs."""
        b, geom = walk.b, walk.geom
        child = b.add(level, const(I64, 1))
        out = []
        for c in range(8):
            f_lo, f_hi = const(DOUBLE, -RADIUS2), const(DOUBLE, -RADIUS2)
            for a in range(3):
                h = load_at(b, geom, b.add(b.mul(child, const(I64, 3)), const(I64, 6 + a)))
                index = b.add(b.shl(cell[a], const(I32, 1)), const(I32, (c >> a) & 1))
                origin, pad = load_at(b, geom, a), load_at(b, geom, 3 + a)
                lo = b.fsub(b.fadd(origin, b.fmul(b.uitofp(index, DOUBLE), h)), pad)
                hi = b.fadd(b.fadd(origin, b.fmul(b.uitofp(b.add(index, const(I32, 1)), DOUBLE), h)), pad)
                lo2, hi2 = b.fmul(lo, lo), b.fmul(hi, hi)
                straddles = b.and_(b.fcmp_ordered("<=", lo, const(DOUBLE, 0.0)),
                                   b.fcmp_ordered(">=", hi, const(DOUBLE, 0.0)))
                smaller = b.select(b.fcmp_ordered("<", lo2, hi2), lo2, hi2)
                f_lo = b.fadd(f_lo, b.select(straddles, const(DOUBLE, 0.0), smaller))
                f_hi = b.fadd(f_hi, b.select(b.fcmp_ordered(">", lo2, hi2), lo2, hi2))
            out.append((f_lo, f_hi))
        return out

    def masks(self, walk: Walk, level, cell):
        b = walk.b
        kept, below = const(I32, 0), const(I32, 0)
        for c, (f_lo, f_hi) in enumerate(self.boxes(walk, level, cell)):
            zero = const(DOUBLE, 0.0)
            meets = b.and_(b.fcmp_ordered("<=", f_lo, zero), b.fcmp_ordered(">=", f_hi, zero))
            kept = b.or_(kept, b.shl(b.zext(meets, I32), const(I32, c)))
            inside = b.fcmp_ordered("<", f_hi, const(DOUBLE, 0.0))
            below = b.or_(below, b.shl(b.zext(inside, I32), const(I32, c)))
        return kept, below

    def enclose(self, walk: Walk, level, cell):
        kept, below = self.masks(walk, level, cell)
        return kept, below, const(I32, 0)

    def refine(self, walk: Walk, level, c, leaf):
        kept, _ = self.masks(walk, walk.b.add(level, const(I64, 1)), leaf)
        return walk.b.icmp_unsigned("!=", kept, const(I32, 0))

    def enter(self, walk: Walk, level, c, decided) -> None:
        pass

    def normals(self, walk: Walk, level, first, count) -> None:
        """∇F = 2·(x, y, z): the unit centre of each voxel (no flags: nothing for a second look)."""
        b = walk.b
        with for_range(b, count) as k:
            row = b.mul(b.add(first, k), const(I64, 3))
            centre = [b.fadd(load_at(b, walk.leaf_geom, a),
                             b.fmul(b.fadd(b.uitofp(load_at(b, walk.out, b.add(row, const(I64, a))), DOUBLE),
                                           const(DOUBLE, 0.5)), load_at(b, walk.leaf_geom, 3 + a))) for a in range(3)]
            norm2 = Local(b, DOUBLE, const(DOUBLE, 0.0))
            for v in centre:
                norm2.set(b.fadd(norm2.get(), b.fmul(v, v)))
            sqrt = b.module.declare_intrinsic("llvm.sqrt", [DOUBLE])
            length = b.call(sqrt, [norm2.get()])
            for a in range(3):
                store_at(b, b.fptrunc(b.fdiv(centre[a], length), ir.FloatType()), walk.out_normals,
                         b.add(row, const(I64, a)))
            with b.if_then(b.icmp_unsigned("!=", walk.out_flags, ir.Constant(walk.out_flags.type, None))):
                store_at(b, ir.Constant(ir.IntType(8), 0), walk.out_flags, b.add(first, k))

    def second_look(self, walk: Walk, level, first, count) -> None:
        pass


@pytest.fixture(scope="module")
def ball_walk():
    module = ir.Module(name="implc_test_ball_walk")
    emit_walk(module, BALL_WALK, BallEvaluator())
    text = str(module)
    native = NativeModule(lambda: text, source_key="implc-test-ball-walk-" + hashlib.sha256(text.encode()).hexdigest())
    return native, native.bind(BALL_WALK)


def exact_cells():
    """The cells at DEPTH whose exact range of F contains 0, and those where it lies below 0 (numpy, exact:
    dyadic coordinates with few bits)."""
    n = 1 << DEPTH
    i = np.arange(n)
    lo, hi = -1 + 2 * i / n, -1 + 2 * (i + 1) / n
    sq_lo = np.where((lo <= 0) & (hi >= 0), 0.0, np.minimum(lo * lo, hi * hi))
    sq_hi = np.maximum(lo * lo, hi * hi)
    f_lo = sq_lo[:, None, None] + sq_lo[None, :, None] + sq_lo[None, None, :] - RADIUS2
    f_hi = sq_hi[:, None, None] + sq_hi[None, :, None] + sq_hi[None, None, :] - RADIUS2
    return (f_lo <= 0) & (f_hi >= 0)


class BallWalk(WalkEvaluator):
    """The driver's side of the ball's evaluator: its walk, and words it does not read."""

    def __init__(self, walk):
        self.walk = walk

    def worker_words(self):
        return np.zeros(1, dtype=np.int64), ()


def voxelize_with(surface, evaluator, refine):
    """Voxels (coords, normals) and inside octants of ``surface`` through the driver, with ``evaluator``
    (None: the surface's own)."""
    sub = Subdivider(surface, DEPTH, 2, surface.runtime, refine_leaves=refine, solid=True, evaluator=evaluator)
    coords, normals = [], []
    sub.run(lambda c, nrm: (coords.append(np.array(c)), normals.append(np.array(nrm))))
    return np.concatenate(coords), np.concatenate(normals), sub.inside


@pytest.mark.parametrize("refine", [False, True])
def test_a_third_evaluator_runs_through_the_one_walk(ball_walk, refine):
    _, walk = ball_walk
    coords, normals, inside = voxelize_with(implc.compile(x**2 + y**2 + z**2 - Rational(1, 2), engine="jit"),
                                            BallWalk(walk), refine)
    # against exact arithmetic: every cell whose exact range contains 0, nothing else (refinement keeps a cell
    # one of whose eighths meets the surface: with exact ranges, every such cell)
    dense = np.zeros((1 << DEPTH,) * 3, bool)
    dense[tuple(coords.T)] = True
    expected = exact_cells()
    assert expected.sum() > 1000
    np.testing.assert_array_equal(dense, expected)
    assert (np.diff(morton_codes(coords).astype(np.int64)) > 0).all()  # in Morton order, as for every evaluator
    centres = -1 + (coords + 0.5) * 2 / (1 << DEPTH)
    np.testing.assert_allclose(normals, centres / np.linalg.norm(centres, axis=1, keepdims=True), atol=1e-6)
    # and the same voxels, normals and inside octants as both engines give through their evaluators
    for engine in ("jit", "tape"):
        surface = implc.compile(x**2 + y**2 + z**2 - Rational(1, 2), engine=engine)
        theirs = voxelize_with(surface, None, refine)
        np.testing.assert_array_equal(coords, theirs[0])
        np.testing.assert_allclose(normals, theirs[1], atol=1e-6)
        np.testing.assert_array_equal(inside, theirs[2])


@pytest.mark.parametrize("solid", [False, True])
def test_drop_marked_keeps_the_unmarked_rows_in_order(solid):
    """``implc_drop_marked`` after a second look: the rows not marked OUTSIDE or INSIDE (coordinates,
    live-term masks, normals) moved down in their order, the flagged and marked counts added to the stats,
    and for a solid the rows marked INSIDE appended to the inside octants with the depth, after those
    already there; against numpy's selection of the same random rows."""
    from implc.engines.second_look_native import INSIDE, OUTSIDE
    from implc.native.runtime import Runtime
    rng = np.random.default_rng(11)
    n = 10_007
    kinds = np.array([0, abi.TIGHTEN_ABOVE, abi.TIGHTEN_BELOW, OUTSIDE, INSIDE], np.int8)
    flags = rng.choice(kinds, n).astype(np.int8)
    coords = rng.integers(0, 1 << 9, (n, 3)).astype(np.int32)
    masks = rng.integers(0, 1 << 62, n).astype(np.int64)
    normals = rng.standard_normal((n, 3)).astype(np.float32)
    before = coords.copy(), masks.copy(), normals.copy()
    inside = np.full((n + 3, abi.INSIDE_WORDS), -1, np.int32)
    inside_count, stats = np.array([3], np.int64), np.array([5, 7], np.int64)
    kept = Runtime.shared().library(ROWS).drop_marked(9, coords.ctypes.data, masks.ctypes.data, normals.ctypes.data,
                                        flags.ctypes.data, n, inside.ctypes.data if solid else None,
                                        inside_count.ctypes.data, stats.ctypes.data)
    keep = (flags != OUTSIDE) & (flags != INSIDE)
    assert kept == keep.sum()
    assert (coords[:kept] == before[0][keep]).all() and (masks[:kept] == before[1][keep]).all()
    assert (normals[:kept] == before[2][keep]).all()
    flagged = np.isin(flags, [abi.TIGHTEN_ABOVE, abi.TIGHTEN_BELOW, OUTSIDE, INSIDE]).sum()
    assert list(stats) == [5 + flagged, 7 + (~keep).sum()]
    below = flags == INSIDE
    if solid:
        assert inside_count[0] == 3 + below.sum()
        assert (inside[3:3 + below.sum(), :3] == before[0][below]).all() and (inside[3:3 + below.sum(), 3] == 9).all()
        assert (inside[:3] == -1).all() and (inside[3 + below.sum():] == -1).all()
    else:
        assert inside_count[0] == 3 and (inside == -1).all()
