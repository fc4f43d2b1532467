"""The octree backend (the paper's Fig. 2 and Fig. 6), index-based and relocatable.

Nodes are rows of an (M, 8) int32 array: entry c of node n is its child in octant c (x bit | y bit << 1 |
z bit << 2), 0 meaning empty (the root, node 0, is nobody's child). Nodes at level depth − 1 hold
``voxel index + 1`` instead: the payload, a normal per voxel, lives in ``normals``. Insertion and
traversal run natively (:mod:`implc.voxelizer.storage.octree_native`).

A solid's tree also records its inside: an entry :data:`INSIDE` (−1) says the child's whole box lies where
F < 0, and nothing is stored below it. So each node is in one of three states, in the entry that points
at it: boundary (a node: it holds boundary voxels), inside (−1) or outside (0). Eight inside siblings
become an inside parent, so an inside entry is the largest octant the voxelization proved inside.
"""

from __future__ import annotations

import threading

import numpy as np

from ...engines.morton import morton_codes
from ...native import abi, big_arrays
from ...native.abi import DEPTH, LEVEL_COUNTS, NODE_COUNT, OCTREE_STATE_WORDS
from ...native.runtime import Runtime
from .octree_native import OCTREE_INDEX

INSIDE = -1
"""A child entry: the child's whole box is inside (F < 0 in all of it); nothing is stored below it."""


class Octree:
    def __init__(self, depth: int, bounds, nodes: np.ndarray, normals: np.ndarray, level_counts: np.ndarray):
        self.depth = depth
        self.bounds = bounds
        self.nodes = nodes
        self.normals = normals
        self.level_counts = level_counts

    def __len__(self) -> int:
        return len(self.normals)

    @property
    def nbytes(self) -> int:
        return self.nodes.nbytes + self.normals.nbytes

    @property
    def bytes_per_voxel(self) -> float:
        return self.nbytes / max(len(self), 1)

    def save(self, path) -> None:
        """Write the octree to an ``.npz`` file (plain arrays: it is index-based, so it relocates)."""
        np.savez(path, nodes=self.nodes, normals=self.normals, level_counts=self.level_counts,
                 depth=self.depth, bounds=np.asarray(self.bounds, dtype=np.float64))

    @classmethod
    def load(cls, path) -> Octree:
        with np.load(path) as data:
            return cls(int(data["depth"]), tuple(map(tuple, data["bounds"].tolist())), data["nodes"],
                       data["normals"], data["level_counts"])

    def traverse(self, level: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The nodes at ``level`` (default: the voxels) in Fig. 6 order (which is Morton order).

        Returns (coords (K, 3) uint32 at that level's resolution, payload (K,) int64): voxel indices into
        ``normals`` at the leaf level, node indices above it.
        """
        level = self.depth if level is None else int(level)
        if not 0 <= level <= self.depth:
            raise ValueError(f"level must be in 0..{self.depth}, got {level}")
        if level == 0:
            return np.zeros((1, 3), np.uint32), np.zeros(1, np.int64)
        count = int(self.level_counts[level])
        coords = np.empty((count, 3), dtype=np.uint32)
        payload = np.empty(count, dtype=np.int64)
        nodes = np.ascontiguousarray(self.nodes, dtype=np.int32)
        index = Runtime.shared().library(OCTREE_INDEX)
        got = index.octree_traverse(nodes.ctypes.data, self.depth, level, coords.ctypes.data,
                                           payload.ctypes.data)
        assert got == count, f"octree traversal found {got} nodes at level {level}, expected {count}"
        return coords, payload

    def level(self, k: int, solid: bool = False):
        """Level of detail: the boundary nodes at depth k and the normalised mean normal of the voxels below
        each. With ``solid``: (coords, normals, inside), the inside nodes at depth k too (normal 0, 0, 0),
        all in Morton order, ``inside`` marking them."""
        coords, payload = self.traverse(k)
        if k == self.depth:
            normals = self.normals[payload]
        else:
            voxels, index = self.traverse(self.depth)
            prefix = voxels >> np.uint32(self.depth - k)
            starts = (np.flatnonzero(np.r_[True, np.any(prefix[1:] != prefix[:-1], axis=1)]) if len(voxels)
                      else np.zeros(0, np.int64))
            sums = np.zeros((len(coords), 3))
            if len(voxels):  # a node with no voxel below (never on a sound voxelization) keeps the default
                at = np.searchsorted(morton_codes(coords), morton_codes(prefix[starts]))
                sums[at] = np.add.reduceat(self.normals[index].astype(np.float64), starts, axis=0)
            lengths = np.linalg.norm(sums, axis=1, keepdims=True)
            normals = np.where(lengths > 0, sums / np.where(lengths > 0, lengths, 1), [0.0, 0.0, 1.0])
            normals = normals.astype(np.float32)
        if not solid:
            return coords, normals
        inside = self.inside_at(k)
        all_coords = np.concatenate([coords, inside])
        order = np.argsort(morton_codes(all_coords), kind="stable")
        all_normals = np.concatenate([normals, np.zeros((len(inside), 3), np.float32)])
        is_inside = np.r_[np.zeros(len(coords), bool), np.ones(len(inside), bool)]
        return all_coords[order], all_normals[order], is_inside[order]

    # -- a solid's inside ------------------------------------------------------------------------
    def add_inside(self, inside: np.ndarray) -> None:
        """Record a solid's inside octants, (n, 4) int rows (i, j, k, level), disjoint from each other and
        from the voxels (natively: a node is created above an octant only where no boundary node holds
        it, and a node whose eight entries are inside becomes an inside entry of its parent)."""
        rows = np.ascontiguousarray(inside, dtype=np.int32)
        state = np.zeros(OCTREE_STATE_WORDS, dtype=np.int64)
        state[NODE_COUNT], state[DEPTH] = len(self.nodes), self.depth
        state[LEVEL_COUNTS: LEVEL_COUNTS + len(self.level_counts)] = self.level_counts
        nodes, done = np.ascontiguousarray(self.nodes, dtype=np.int32), 0
        runtime = Runtime.shared().library(OCTREE_INDEX)
        while True:
            done += runtime.octree_mark_inside(nodes.ctypes.data, len(nodes), state.ctypes.data,
                                               rows[done:].ctypes.data, len(rows) - done)
            if done == len(rows):
                break
            nodes = big_arrays.grown(nodes, 2 * len(nodes) + abi.MAX_DEPTH, len(nodes))  # out of nodes: room, go on
        self.nodes = nodes[:int(state[NODE_COUNT])]
        self.level_counts = state[LEVEL_COUNTS: LEVEL_COUNTS + len(self.level_counts)].copy()

    def inside_nodes(self) -> tuple[np.ndarray, np.ndarray]:
        """The inside entries as (levels (n,) int32, coords (n, 3) uint32 at each one's level), coarsest
        level first, Morton order within a level."""
        levels, coords = [], []
        for level in range(self.depth):
            cells, ids = self.traverse(level)
            node, slot = np.nonzero(self.nodes[ids] == INSIDE)
            if len(node):
                child = (cells[node].astype(np.uint32) << np.uint32(1)) | _slot_bits(slot)
                coords.append(child)
                levels.append(np.full(len(child), level + 1, np.int32))
        if not coords:
            return np.empty(0, np.int32), np.empty((0, 3), np.uint32)
        return np.concatenate(levels), np.concatenate(coords)

    def inside_at(self, k: int) -> np.ndarray:
        """The cells at depth k covered by inside entries, (n, 3) uint32 in Morton order (coarser entries
        expanded to depth k; finer ones lie in boundary nodes at depth k)."""
        levels, coords = self.inside_nodes()
        out = []
        for level in np.unique(levels[levels <= k]):
            cells = coords[levels == level]
            per = 1 << (k - int(level))
            steps = np.stack(np.meshgrid(*(np.arange(per, dtype=np.uint32),) * 3, indexing="ij"), -1).reshape(-1, 3)
            out.append((cells[:, None, :] * np.uint32(per) + steps[None]).reshape(-1, 3))
        cells = np.concatenate(out) if out else np.empty((0, 3), np.uint32)
        return cells[np.argsort(morton_codes(cells), kind="stable")]


def _slots(cells: np.ndarray) -> np.ndarray:
    """Each cell's octant in its parent (x bit | y bit << 1 | z bit << 2)."""
    c = cells.astype(np.int64) & 1
    return c[:, 0] | (c[:, 1] << 1) | (c[:, 2] << 2)


def _slot_bits(slot: np.ndarray) -> np.ndarray:
    """(n, 3) uint32 low bits of the children in octants ``slot``."""
    return np.column_stack([(slot >> a) & 1 for a in range(3)]).astype(np.uint32)


class OctreeBuilder:
    """Storage backend that inserts each Morton-ordered batch natively as it arrives.

    With ``keep_normals=False`` the caller owns the normals array and attaches it as the payload after
    ``finish()`` (the voxelizer does, to avoid a second copy).
    """

    def __init__(self, keep_normals: bool = True):
        self.keep_normals = keep_normals

    def begin(self, depth, bounds):
        self.depth, self.bounds = depth, bounds
        self.runtime = Runtime.shared().library(OCTREE_INDEX)
        self.nodes = np.zeros((1024, 8), dtype=np.int32)
        self.state = np.zeros(OCTREE_STATE_WORDS, dtype=np.int64)
        self.state[NODE_COUNT] = 1  # the root
        self.state[DEPTH] = depth
        self.state[LEVEL_COUNTS] = 1
        self.count = 0
        self._normals = []

    def reserve(self, voxels: int):
        """Size the node array for about ``voxels`` voxels (a surface needs ~1/3 node per voxel)."""
        self._grow_to(int(voxels * 0.4))

    def _grow_to(self, rows: int):
        """Room for ``rows`` nodes; rows past the node count are left uninitialised (the native insertion
        clears each node it creates), so that rows reserved but never used cost nothing."""
        if rows > len(self.nodes):
            self.nodes = big_arrays.grown(self.nodes, rows, int(self.state[NODE_COUNT]))

    def add(self, coords, normals):
        coords = np.ascontiguousarray(coords, dtype=np.uint32)
        done = 0
        while done < len(coords):
            inserted = self.runtime.octree_insert(
                self.nodes.ctypes.data, len(self.nodes), self.state.ctypes.data,
                coords[done:].ctypes.data, len(coords) - done, self.count + done)
            done += inserted
            if done < len(coords):  # out of nodes: grow and go on where it stopped
                self._grow_to(2 * len(self.nodes))
        self.count += len(coords)
        if self.keep_normals:
            self._normals.append(np.asarray(normals, dtype=np.float32))

    def finish(self):
        used = int(self.state[NODE_COUNT])
        normals = np.concatenate(self._normals) if self._normals else np.zeros((0, 3), np.float32)
        counts = self.state[LEVEL_COUNTS: LEVEL_COUNTS + self.depth + 1].copy()
        tree = Octree(self.depth, self.bounds, self.nodes[:used], normals, counts)
        self.nodes = self._normals = None
        return tree


class OctreeAssembly:
    """The octree built from per-task subtrees, in parallel (a :class:`implc.engines.walk.Subdivider`
    placement): each task's voxels get their place in task order (a voxel offset and a row offset, the
    only serial step), then the worker that finished the task writes its normals there and inserts its
    voxels natively into its own rows below the task's node (Fig. 2's insertion, rooted at the task cell),
    while other tasks are placed. The nodes above the tasks are linked at the end. Each voxel's normal is
    written once; no coordinates are stored (the tree holds them). Row indices differ from the serial
    builder's; the tree, its traversals and levels are the same for every worker count.
    """

    def __init__(self, depth: int, bounds, task_level: int, capacity: int):
        self.depth, self.bounds, self.task_level = depth, bounds, task_level
        self.below = depth - task_level  # levels from a task's node to its voxels
        capacity = max(int(capacity), 1024)
        self.normals = big_arrays.empty((capacity, 3), np.float32)
        self.nodes = big_arrays.empty((int(capacity * 0.45) + 1024, 8), np.int32)
        self.nodes[0] = 0  # the root; the rows after it are the tasks'
        self.voxel_count, self.node_count = 0, 1
        self.level_counts = np.zeros(depth + 1, dtype=np.int64)
        self.level_counts[0] = 1
        self.roots: list[tuple[tuple, int]] = []  # (task cell, its node's row) of the tasks with voxels
        self._filling = threading.Condition()
        self._active = 0  # fills in progress: the arrays may only be replaced when there are none
        self.runtime = Runtime.shared().library(OCTREE_INDEX)

    def prepare(self, result, cell) -> None:
        """How many rows the task's subtree needs below its node (from its Morton-ordered voxels: each
        voxel adds a node at every level below the one it shares with the previous voxel)."""
        result.subtree_rows = self.runtime.octree_subtree_rows(result.coords.ctypes.data, result.count, self.below)

    def claim(self, result):
        """Place a task (in task order): its voxel offset and its node's row."""
        if result.count == 0:
            return None
        rows = 1 + result.subtree_rows
        with self._filling:
            if self.voxel_count + result.count > len(self.normals) or self.node_count + rows > len(self.nodes):
                while self._active:  # fills write into the arrays: wait for them before moving them
                    self._filling.wait()
                voxels = max(self.voxel_count + result.count, 2 * len(self.normals))
                self.normals = big_arrays.grown(self.normals, voxels, self.voxel_count)
                self.nodes = big_arrays.grown(self.nodes, max(self.node_count + rows, 2 * len(self.nodes)),
                                              self.node_count)
            ticket = (self.voxel_count, self.node_count, rows)
            self.voxel_count += result.count
            self.node_count += rows
            self._active += 1
        return ticket

    def fill(self, result, cell, ticket) -> None:
        """Write a placed task's normals and subtree (in the worker, in parallel with other tasks)."""
        if ticket is None:
            return
        try:
            first_voxel, row, rows = ticket
            n = result.count
            self.normals[first_voxel:first_voxel + n] = result.normals[:n]
            local = result.coords[:n]
            local -= np.asarray(cell, dtype=np.uint32) << np.uint32(self.below)  # in place: the buffer is the task's
            self.nodes[row] = 0
            state = np.zeros(OCTREE_STATE_WORDS, dtype=np.int64)
            state[NODE_COUNT], state[DEPTH], state[abi.PATH], state[LEVEL_COUNTS] = row + 1, self.below, row, 1
            inserted = self.runtime.octree_insert(self.nodes.ctypes.data, row + rows, state.ctypes.data,
                                                  local.ctypes.data, n, first_voxel)
            if inserted != n or state[NODE_COUNT] != row + rows:
                raise AssertionError(f"a task's subtree took {state[NODE_COUNT] - row} rows for {inserted} of {n} "
                                     f"voxels, {rows} planned")
            counts = state[LEVEL_COUNTS: LEVEL_COUNTS + self.below + 1]
        finally:
            with self._filling:
                self._active -= 1
                self._filling.notify_all()
        with self._filling:
            self.level_counts[self.task_level:] += counts
            self.roots.append((tuple(int(v) for v in cell), row))

    def finish(self) -> Octree:
        """Link the tasks' nodes to the root through the levels between (rows after the tasks')."""
        rows = {(0, (0, 0, 0)): 0}

        def row_of(level, cell):
            key = (level, cell)
            if key not in rows:
                parent = row_of(level - 1, tuple(v >> 1 for v in cell))
                if self.node_count == len(self.nodes):
                    self.nodes = big_arrays.grown(self.nodes, 2 * len(self.nodes), self.node_count)
                rows[key] = self.node_count
                self.nodes[self.node_count] = 0
                self.nodes[parent, _slots(np.array([cell]))[0]] = self.node_count
                self.node_count += 1
                self.level_counts[level] += 1
            return rows[key]

        for cell, row in self.roots:
            parent = row_of(self.task_level - 1, tuple(v >> 1 for v in cell))
            self.nodes[parent, _slots(np.array([cell]))[0]] = row
        return Octree(self.depth, self.bounds, self.nodes[:self.node_count], self.normals[:self.voxel_count],
                      self.level_counts.copy())
