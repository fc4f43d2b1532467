"""The generic runtime modules: the native routines shared by every surface.

The runtime module: the tape engine's end of the second look (dropping the leaves it marked,
:func:`.tighten.emit_drop_marked`), the octree (:mod:`.octree_index`), splatting (:mod:`.splat`) and the
layout of rows grouped by box (:mod:`.grouped_rows`). The contouring module: the mesher's cells
(:mod:`.contour_cells`). The kernel-walk module: the walk (:mod:`.walk`) over a
surface's compiled kernels (:mod:`.subdivision`, with their normals and second look), which the tape engine
does not use (its module holds the walk over itself). The mesh-simplification module: the collapse of flat regions'
interior vertices (:mod:`.flat_collapse`). :class:`implc.runtime.Runtime` compiles each once per process,
on first use: a cold start that voxelizes a tape-engine model compiles no mesher and no kernel walk.
"""

from __future__ import annotations

from llvmlite import ir

from .contour_cells import (
    emit_bent_cells,
    emit_cell_corners,
    emit_corner_points,
    emit_corner_signs,
    emit_edge_ends,
    emit_edge_roots,
    emit_fan_triangles,
    emit_hash_index,
    emit_kuhn_triangles,
    emit_qef,
)
from .flat_collapse import emit_flat_collapse
from .grouped_rows import emit_arrange_groups
from .octree_index import (
    emit_octree_insert,
    emit_octree_mark_inside,
    emit_octree_subtree_rows,
    emit_octree_traverse,
)
from .splat import emit_splat
from .subdivision import emit_subdivide
from .tighten import emit_drop_marked


def build_kernel_walk() -> ir.Module:
    """The kernel-walk module."""
    module = ir.Module(name="implc_kernel_walk")
    emit_subdivide(module)
    return module


def build_mesh_simplify() -> ir.Module:
    """The mesh-simplification module."""
    module = ir.Module(name="implc_mesh_simplify")
    emit_flat_collapse(module)
    return module


def build_runtime() -> ir.Module:
    """The runtime module."""
    module = ir.Module(name="implc_runtime")
    emit_drop_marked(module)
    emit_octree_insert(module)
    emit_octree_traverse(module)
    emit_octree_mark_inside(module)
    emit_octree_subtree_rows(module)
    emit_splat(module)
    emit_arrange_groups(module)
    return module


def build_contouring() -> ir.Module:
    """The contouring module."""
    module = ir.Module(name="implc_contouring")
    emit_hash_index(module)
    emit_cell_corners(module)
    emit_corner_signs(module)
    emit_kuhn_triangles(module)
    emit_fan_triangles(module)
    emit_qef(module)
    emit_bent_cells(module)
    emit_edge_ends(module)
    emit_edge_roots(module)
    emit_corner_points(module)
    return module
