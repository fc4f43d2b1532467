"""Proofs that a crossed cell is regular: F's derivative along an axis (or, on the tape engine, a face or
body diagonal) keeps one strict sign wherever F may vanish in the cell, over the cell or over each sub-box
whose enclosure of F contains 0, down to ``proof_levels`` below the grid (:class:`implc.meshing.grid.Effort`)."""

from __future__ import annotations

import numpy as np

from ..engines.surface import Grouping
from .grid import Grid
from .tables import CORNERS

DIAGONALS = np.array([(1, 1, 0), (1, -1, 0), (1, 0, 1), (1, 0, -1), (0, 1, 1), (0, 1, -1),
                      (1, 1, 1), (1, 1, -1), (1, -1, 1), (1, -1, -1)], dtype=np.float64)
"""The directions beyond the axes along which the proof of regular cells seeks a derivative of one sign
(the face and body diagonals of a cell, up to sign): on the tape engine, for the cells the axes leave open."""


def regular(grid: Grid, cells: np.ndarray) -> np.ndarray:
    """Whether some derivative of F keeps one strict sign wherever F may vanish in each cell, so that the
    cell is proven regular (:class:`MeshStats`). First over the cells' parents (2³ cells: what holds over a box
    holds over each box inside it, and the surface's cells share a parent three or four at a time), then
    over the cells of the parents not proven, and below them down to ``grid.effort.proof_levels`` levels
    (:func:`_prove`); on the tape engine the cells still open try F's derivatives along the
    :data:`DIAGONALS` the same way (a crease's cells: :func:`_diagonal_signs`), on a sample of them first
    and on the others where the sample gained ``effort.proof_yield`` (the diagonals pay on creases, not
    around smooth blends)."""
    regular = np.zeros(len(cells), bool)
    if not len(cells):
        return regular
    parent_keys, parent_of = _unique_inverse(grid.cell_key(cells // 2))
    parents = grid.cell_unkey(parent_keys)
    proven = np.asarray(_partial_signs(grid, grid.world(np.minimum(2 * parents, grid.n)),
                                       grid.world(np.minimum(2 * parents + 2, grid.n))).any(1))
    regular = proven[parent_of]
    rest = np.flatnonzero(~regular)
    lo, hi = grid.world(cells[rest]), grid.world(cells[rest] + 1)
    regular[rest] = _prove(grid, lo, hi, np.ones((len(rest), 6), bool), grid.effort.proof_levels).any(1)
    if grid.surface.engine == "tape":
        rest = np.flatnonzero(~regular)
        sample = np.zeros(len(rest), bool)  # a sample first: the diagonals pay on creases, not on smooth blends
        effort = grid.effort
        sample[:: max(1, min(effort.proof_sample, len(rest) // effort.proof_sample_min))] = True
        for rows in (rest[sample], rest[~sample]):
            lo, hi = grid.world(cells[rows]), grid.world(cells[rows] + 1)
            wanted = np.ones((len(rows), 2 * len(DIAGONALS)), bool)
            gained = np.asarray(_prove(grid, lo, hi, wanted, effort.proof_levels, signs_of=_diagonal_signs).any(1))
            regular[rows] = gained
            if len(gained) and gained.mean() < grid.effort.proof_yield:
                break
    return regular


def _prove(grid: Grid, lo, hi, wanted: np.ndarray, levels: int, signs: np.ndarray | None = None,
           sample: bool = True, signs_of=None) -> np.ndarray:
    """Which of the ``wanted`` signs of F's derivatives ((n, 6): rising along x, y, z, then falling; or
    the columns ``signs_of(grid, lo, hi)`` gives, :func:`_partial_signs` by default) are proven over each
    box [lo, hi]: by the box's own enclosures (``signs`` where known), or else by its 8 sub-boxes, down to
    ``levels`` levels. A derivative keeping one sign over every sub-box (but those the surface does not
    meet: :func:`_partial_signs`) keeps it wherever F may vanish in the box they cover; so below a box only
    the signs that every proven sub-box shares are still sought, and a box whose proven sub-boxes share
    none is given up (a crease: one side rises along x, the other along y); and a level pays for the next
    only where it proved at least ``effort.proof_yield`` of the boxes it was given (around creases finer
    boxes prove almost nothing: colonnade's, 0.4%). The first level, where ``sample`` and it is given many
    boxes, is tried on a sample of them first (``effort.proof_sample``)."""
    signs_of = signs_of or _partial_signs
    if signs is None:
        signs = signs_of(grid, lo, hi)
    signs &= wanted
    open_ = np.flatnonzero(~signs.any(1) & wanted.any(1))
    if not levels or not len(open_):
        return signs
    effort = grid.effort
    if sample and len(open_) >= effort.proof_sample_min * effort.proof_sample:
        first = np.zeros(len(open_), bool)
        first[::effort.proof_sample] = True
        if _prove_below(grid, lo, hi, wanted, levels, signs, open_[first], signs_of) < effort.proof_yield:
            return signs
        open_ = open_[~first]
    _prove_below(grid, lo, hi, wanted, levels, signs, open_, signs_of)
    return signs


def _prove_below(grid: Grid, lo, hi, wanted, levels: int, signs: np.ndarray, open_: np.ndarray,
                 signs_of) -> float:
    """:func:`_prove`'s next level for the boxes ``open_``: their signs proven by their sub-boxes, in place;
    returns the share of them proven."""
    sub_lo, sub_hi = _halves(lo[open_], hi[open_])  # (m, 8, 3)
    m = len(open_)
    sub = signs_of(grid, sub_lo.reshape(-1, 3), sub_hi.reshape(-1, 3)).reshape(m, 8, -1) & wanted[open_, None]
    proven = sub.any(2)
    sought = np.where(proven[..., None], sub, True).all(1) & wanted[open_]  # what every proven sub-box shares
    signs[open_] = sub.all(1) & sought
    gained = np.asarray(signs[open_].any(1))
    if levels > 1 and gained.mean() >= grid.effort.proof_yield:
        rows, cols = np.nonzero(~proven & (sought.any(1) & ~gained)[:, None])
        if len(rows):
            sub[rows, cols] = _prove(grid, sub_lo[rows, cols], sub_hi[rows, cols], sought[rows], levels - 1,
                                     sub[rows, cols], sample=False, signs_of=signs_of)
            signs[open_] = sub.all(1) & sought
            gained = np.asarray(signs[open_].any(1))
    return float(gained.mean())


def _unique_inverse(keys: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """np.unique(keys, return_inverse=True) by a stable sort: keys of cells in grid order come in runs, which
    numpy's merge sort takes as they are (twice as fast as the quicksort np.unique uses)."""
    order = np.argsort(keys, kind="stable")
    ordered = keys[order]
    first = np.empty(len(keys), bool)
    first[:1] = True
    np.not_equal(ordered[1:], ordered[:-1], out=first[1:])
    inverse = np.empty(len(keys), np.int64)
    inverse[order] = np.cumsum(first) - 1
    return ordered[first], inverse


def _halves(lo: np.ndarray, hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The 8 sub-boxes of each box [lo, hi] ((m, 8, 3) lower and upper corners), covering it exactly: the
    outer faces are the box's own, and neighbouring sub-boxes share their inner face's coordinate."""
    mid = lo + (hi - lo) / 2
    edges = np.stack([lo, mid, hi], 1)  # (m, 3 edges, 3 axes)
    index = CORNERS  # sub-box c's lower corner: edge (c >> a & 1) along axis a
    axes = np.arange(3)
    return edges[:, index, axes], edges[:, index + 1, axes]


def _partial_signs(grid: Grid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """For each box [lo, hi]: whether F's partial along x, y, z is proven > 0 over the whole box, then
    whether it is proven < 0, (n, 6); all six where F's enclosure over the box excludes 0: the surface does
    not meet the box, so among boxes that cover a cell only those it may meet need a partial's sign (F
    strictly rising along x wherever it may vanish has at most one zero on each line along x: between two
    rising zeros it would have to fall through a third)."""
    if not len(lo):
        return np.zeros((0, 6), bool)
    rising, falling, empty = _signs_along(grid, lo, hi, grid.grouping((lo + hi) / 2))
    return np.concatenate([rising, falling], 1) | empty[:, None]


def _diagonal_signs(grid: Grid, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """:func:`_partial_signs` for F's derivatives along the :data:`DIAGONALS` (the tape engine's, three at a
    time, each with its own hull at a kink): (n, 2·10), rising along each, then falling; all where F's
    enclosure over the box excludes 0. F rising along a direction d wherever it may vanish in a cell has
    at most one zero on each line along d there, so the surface in the cell is a graph over the plane
    across d: across a crease of Min/Max CSG the two sides' partials along an axis may differ in sign
    (every axis's hull straddles 0) while both rise along a diagonal."""
    count = len(DIAGONALS)
    if not len(lo):
        return np.zeros((0, 2 * count), bool)
    grouping = grid.grouping((lo + hi) / 2)
    rising, falling = [], []
    for first in range(0, count, 3):
        three = DIAGONALS[[min(first + k, count - 1) for k in range(3)]]
        up, down, empty = _signs_along(grid, lo, hi, grouping, three)
        rising.append(up[:, : count - first])
        falling.append(down[:, : count - first])
    return np.concatenate(rising + falling, 1) | empty[:, None]


def _signs_along(grid: Grid, lo, hi, grouping: Grouping | None, directions=None):
    """Over each box [lo, hi] (the tape engine's program simplified over its group of ``grouping``): whether
    F's derivative along each of three directions (the axes, or the rows of ``directions``) is proven > 0,
    whether it is proven < 0 ((n, 3) each), and whether F's enclosure excludes 0 ((n,))."""
    enclosures = grid.surface.gradient_enclosures(lo, hi, grouping, directions=directions)
    derivatives = enclosures[:, 2:].reshape(-1, 3, 2)
    return derivatives[:, :, 0] > 0, derivatives[:, :, 1] < 0, (enclosures[:, 0] > 0) | (enclosures[:, 1] < 0)
