"""The caps: each face of the bounds contributes the part where the sampled F is negative, as the
tetrahedra's faces there triangulate it, so the mesh is closed where the solid meets the bounds."""

from __future__ import annotations

import numpy as np

from .grid import (
    NO_POINTS,
    Cells,
    Grid,
    Points,
    both_signs,
    face_corner_keys,
    grid_edge_key,
    grid_face_ids,
    never,
    square_edge_key,
)
from .tables import CAP_POLYGONS, FACE_CORNER, FACE_POINT, SQUARE, face_axes, face_shapes, reversed_face


def _face_triangles(grid, cells, axis, side, split4, face_points: Points, inside):
    """The triangles of the cells' faces on (axis, side), counter-clockwise seen from outside the cells:
    yields (rows of cells, the triangle's shape (("c", square corner) or ("f", 0) for the face point,
    three times), its vertices' inside flags (m, 3), the vertices' own keys (m, 3), the keys of its edges
    0-1, 1-2, 2-0 (m, 3)). Faces with ``split4`` are fanned from their face point."""
    local, corner_keys = face_corner_keys(grid, cells, axis, side)
    face_ids = grid_face_ids(grid, cells, axis, side)
    rows = np.arange(len(cells))
    corner_in = inside[:, local]
    for fanned in (False, True):
        sel = rows[split4 == fanned]
        if not len(sel):
            continue
        fp = face_points.find(face_ids[sel]) if fanned else None
        for shape in face_shapes(axis, side, fanned):
            flags, selves, edges = [], [], []
            for kind, k in shape:
                if kind == "c":
                    flags.append(corner_in[sel, k])
                    selves.append(grid_edge_key(corner_keys[sel, k], 0))
                else:
                    flags.append(face_points.inside[fp])
                    selves.append(face_ids[sel] * 8 + FACE_POINT)
            for v in range(3):
                (ka, a), (kb, bb) = shape[v], shape[(v + 1) % 3]
                if ka == "c" and kb == "c":
                    edges.append(square_edge_key(corner_keys[sel], axis, a, bb))
                else:
                    corner = a if ka == "c" else bb
                    edges.append((face_ids[sel] * 4 + corner) * 8 + FACE_CORNER)
            yield sel, shape, np.stack(flags, 1), np.stack(selves, 1), np.stack(edges, 1)


def cap_triangles(grid: Grid, face_points: Points, is_feature, faces=None):
    """The bounds' faces where the sampled F is negative, as triangles of vertex keys ({(axis, side): (T, 3)}),
    and the cells beside them whose face there has both signs (they must be contoured too); ``faces``: only
    those (default: all six); the faces proven outside (:meth:`Grid.find_outside_faces`) are not sampled."""
    caps, seeds = {}, []
    n = grid.n
    u, v = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    for axis in range(3):
        b, c = face_axes(axis)
        for side in (0, 1):
            if (axis, side) in grid.outside_faces or (faces is not None and (axis, side) not in faces):
                continue
            out: list[np.ndarray] = []
            grid_of_cells = np.zeros((n, n, 3), np.int64)
            grid_of_cells[..., axis] = side * (n - 1)
            grid_of_cells[..., b], grid_of_cells[..., c] = u, v
            cells = grid_of_cells.reshape(-1, 3)
            local, corner_keys = face_corner_keys(grid, cells, axis, side)
            keys = grid.face_keys(axis, side)
            values = grid.face_values(axis, side, keys)
            signs = values < 0
            split4 = is_feature(cells)  # squares fanned from a face point, which may be inside where no corner is
            points_inside = face_points.inside[face_points.find(grid_face_ids(grid, cells[split4], axis, side))]
            if not signs.any() and not points_inside.any():
                continue
            grid.remember(keys.reshape(-1), values.reshape(-1))
            inside = np.zeros((len(cells), 8), bool)
            for k, (du, dv) in enumerate(SQUARE):
                inside[:, local[k]] = signs[cells[:, b] + du, cells[:, c] + dv]
            seeds.append(cells[both_signs(inside[:, local])])
            whole = inside[:, local].all(1) & ~split4  # squares inside throughout, with no face point
            blocks, in_block = _cap_blocks(whole.reshape(n, n))
            if blocks:  # the corners the triangles beside the blocks use: the other squares' and the blocks'
                used = np.zeros((n + 1, n + 1), bool)
                emitting = ~in_block & (signs[:-1, :-1] | signs[1:, :-1] | signs[:-1, 1:] | signs[1:, 1:])
                for du, dv in SQUARE:
                    used[du:n + du, dv:n + dv] |= emitting
                for size, lowest in blocks:
                    for du, dv in SQUARE:
                        used[lowest[:, 0] + du * size, lowest[:, 1] + dv * size] = True
                out.extend(_block_fans(blocks, used, keys, reversed_face(axis, side)))
                rest = np.flatnonzero(~in_block.reshape(-1))
                cells, inside, split4 = cells[rest], inside[rest], split4[rest]
            for sel, shape, flags, selves, edges in _face_triangles(grid, cells, axis, side, split4, face_points,
                                                                    inside):
                case = flags[:, 0] | flags[:, 1].astype(np.int64) << 1 | flags[:, 2].astype(np.int64) << 2
                for polygon_case in range(1, 8):
                    pick = case == polygon_case
                    if not pick.any():
                        continue
                    for triple in CAP_POLYGONS[polygon_case]:
                        out.append(np.stack([selves[pick, i] if i == j else edges[pick, i] for i, j in triple], 1))
            caps[axis, side] = np.concatenate(out) if out else np.zeros((0, 3), np.int64)
    return caps, (np.concatenate(seeds) if seeds else np.zeros((0, 3), np.int64))


def close_over_reached_faces(grid: Grid, todo: Cells, start: int):
    """Where the cells from row ``start`` on reach a face of the bounds taken as outside
    (:meth:`Grid.touched`), that face is sampled after all and the cells are closed under its caps' seeds,
    until none is reached: (cells added, the caps made last, or None where no face was reached)."""
    added, caps = 0, None
    while grid.touched(todo.cells[start:]):
        start = len(todo.cells)  # the cells checked so far reach no other face taken as outside
        caps, seeds = cap_triangles(grid, NO_POINTS, never)
        added += todo.close(seeds, start=start)
    return added, caps


def _cap_blocks(whole: np.ndarray) -> tuple[list[tuple[int, np.ndarray]], np.ndarray]:
    """The squares of a face of the bounds (``whole``, (n, n): inside throughout, no face point) merged into
    aligned blocks of 2^k × 2^k squares (k >= 1), largest first, none touching the face's border (there the
    neighbouring face's cap meets this one square by square): [(size, (m, 2) lowest corners)] and which
    squares the blocks cover (n, n)."""
    n = len(whole)
    mergeable = whole.copy()
    mergeable[[0, -1], :] = mergeable[:, [0, -1]] = False
    covered = np.zeros_like(mergeable)
    levels: list[np.ndarray] = [mergeable]
    while len(levels[-1]) >= 2:  # level k: which aligned 2^k blocks are mergeable throughout
        m = levels[-1]
        half = len(m) // 2
        levels.append(np.asarray(m.reshape(half, 2, half, 2).all((1, 3))))
    blocks = []
    for k in range(len(levels) - 1, 0, -1):
        size = 1 << k
        free = ~covered.reshape(n // size, size, n // size, size).any((1, 3))
        take = levels[k] & free
        if take.any():
            blocks.append((size, np.argwhere(take) * size))
            covered |= np.repeat(np.repeat(take, size, 0), size, 1)
    return blocks, covered


def _block_fans(blocks, used: np.ndarray, keys: np.ndarray, flip: bool):
    """Each block of :func:`_cap_blocks` as a fan from its centre corner over its boundary: its corners and
    every corner along its sides that ``used`` marks ((n + 1)², a corner of a square or block beside it),
    so that each side meets the triangles beyond it edge for edge. Counter-clockwise in the face's axes
    (:data:`SQUARE`), reversed where ``flip``; vertices are the corners' own keys (``keys``: the face's
    corner keys, (n + 1)²)."""
    for size, lowest in blocks:
        steps = np.arange(size)
        # the boundary in SQUARE order: along the first axis, up the second, back, down: (4·size, 2) offsets
        ring = np.concatenate([np.stack([steps, 0 * steps], 1), np.stack([size + 0 * steps, steps], 1),
                               np.stack([size - steps, size + 0 * steps], 1), np.stack([0 * steps, size - steps], 1)])
        points = lowest[:, None, :] + ring[None]  # (m, 4·size, 2)
        on = used[points[..., 0], points[..., 1]]
        on[:, ::size] = True  # the block's own corners
        flat = np.flatnonzero(on)  # in order, block by block; each block's first point is its corner
        width = 4 * size
        following = np.append(flat[1:], -1)
        last = following // width != flat // width  # the block's last point: back to its first
        following = np.where(last, flat // width * width, following)
        p, q = points.reshape(-1, 2)[flat], points.reshape(-1, 2)[following]
        centre = (lowest + size // 2)[flat // width]
        centre, p, q = (grid_edge_key(keys[uv[:, 0], uv[:, 1]], 0) for uv in (centre, p, q))
        yield np.stack([centre, q, p] if flip else [centre, p, q], 1)
