"""The generic runtime module: the native routines shared by every surface, in one LLVM module.

Subdivision (:mod:`.subdivision`), normals (:mod:`.normals`), tightening (:mod:`.tighten`), the octree
(:mod:`.octree_index`), splatting (:mod:`.splat`) and the contouring's cells (:mod:`.contour_cells`);
:class:`implc.runtime.Runtime` compiles it once per process.
"""

from __future__ import annotations

from llvmlite import ir

from .contour_cells import (
    emit_bent_cells,
    emit_corner_points,
    emit_edge_ends,
    emit_edge_roots,
    emit_hash_index,
    emit_kuhn_triangles,
)
from .normals import emit_normals
from .octree_index import (
    emit_octree_insert,
    emit_octree_mark_inside,
    emit_octree_subtree_rows,
    emit_octree_traverse,
)
from .splat import emit_splat
from .subdivision import emit_subdivide
from .tighten import emit_tighten


def build_runtime() -> str:
    """The LLVM IR text of the runtime module."""
    module = ir.Module(name="implc_runtime")
    emit_subdivide(module)
    emit_normals(module)
    emit_tighten(module)
    emit_octree_insert(module)
    emit_octree_traverse(module)
    emit_octree_mark_inside(module)
    emit_octree_subtree_rows(module)
    emit_splat(module)
    emit_hash_index(module)
    emit_kuhn_triangles(module)
    emit_bent_cells(module)
    emit_edge_ends(module)
    emit_edge_roots(module)
    emit_corner_points(module)
    return str(module)
