"""Import paths that moved when the package was laid out by concern (0.3): each old path still imports, for
one release, with a :class:`DeprecationWarning` naming the new one.

An old path is a module of its own whose attributes are read from the new modules (the voxelization
module's ``mesh`` now lives in :mod:`implc.meshing.mesh`), so ``from implc.zarr_store import write_zarr``
and ``import implc.voxel_files`` keep working. Installed by :mod:`implc` on import.
"""

from __future__ import annotations

import importlib
import importlib.abc
import importlib.util
import sys
import types
import warnings

MOVED: dict[str, tuple[str, ...]] = {
    "abi": ("native.abi",),
    "atomic_file": ("common.atomic_file",),
    "big_arrays": ("native.big_arrays",),
    "codegen": ("compiler.llvm",),
    "codegen.contour_cells": ("meshing.contour_native",),
    "codegen.control": ("compiler.llvm.control",),
    "codegen.elementary": ("compiler.llvm.elementary",),
    "codegen.flat_collapse": ("meshing.simplify_native",),
    "codegen.fold": ("engines.compiled.fold_native",),
    "codegen.grouped_rows": ("engines.rows_native",),
    "codegen.interval_rules": ("compiler.llvm.interval_rules",),
    "codegen.kernels": ("engines.compiled.kernels_native",),
    "codegen.leaf_split": ("engines.second_look_native",),
    "codegen.mean_value": ("engines.compiled.mean_value_native",),
    "codegen.normals": ("engines.normals_native",),
    "codegen.octree_index": ("voxelizer.storage.octree_native",),
    "codegen.point": ("compiler.llvm.point",),
    "codegen.pruned_gradient": ("engines.compiled.gradient_native",),
    "codegen.pruned_interval": ("engines.compiled.interval_native",),
    "codegen.pruned_mean_value": ("engines.compiled.pruned_mean_value_native",),
    "codegen.runtime_module": ("engines.rows_native", "voxelizer.storage.octree_native", "view.splat_native",
                               "engines.compiled.evaluator_native", "meshing.contour_native",
                               "meshing.simplify_native"),
    "codegen.splat": ("view.splat_native",),
    "codegen.split": ("native.split",),
    "codegen.subdivision": ("engines.compiled.evaluator_native",),
    "codegen.tape_engine_module": ("engines.tape.engine_native",),
    "codegen.tape_eval": ("engines.tape.interpreter_native",),
    "codegen.tape_points": ("engines.tape.points_native",),
    "codegen.tape_simplify": ("engines.tape.plan_native",),
    "codegen.tape_subdivision": ("engines.tape.evaluator_native",),
    "codegen.tape_tighten": ("engines.tape.tighten_native",),
    "codegen.tighten": ("engines.compiled.tighten_native", "engines.rows_native"),
    "codegen.vector": ("compiler.llvm.vector",),
    "codegen.walk": ("engines.walk_native",),
    "contour": ("meshing.contour", "meshing.grid", "meshing.tables", "meshing.proofs", "meshing.vertices",
                "meshing.features", "meshing.caps"),
    "expr": ("compiler.expr",),
    "gradient": ("compiler.gradient",),
    "ir": ("compiler.ir",),
    "jit": ("native.jit",),
    "kernel_cache": ("native.kernel_cache",),
    "lod_chunks": ("view.lod_chunks",),
    "lower": ("compiler.lower",),
    "mesh_formats": ("meshing.formats",),
    "mesh_payload": ("view.mesh_payload",),
    "mesh_simplify": ("meshing.simplify",),
    "morton": ("engines.morton",),
    "parallel_compile": ("native.parallel_compile",),
    "recipe": ("cluster.recipe",),
    "reference": ("compiler.reference",),
    "regions": ("engines.compiled.plan",),
    "render": ("view.render",),
    "rounding": ("compiler.rounding",),
    "runtime": ("native.runtime", "engines.tape.engine"),
    "scene": ("files.scene",),
    "slices": ("files.slices",),
    "storage": ("voxelizer.storage",),
    "storage.coords": ("voxelizer.storage.coords",),
    "storage.grid": ("voxelizer.storage.dense",),
    "storage.octree": ("voxelizer.storage.octree",),
    "subdivide": ("engines.walk", "engines.compiled.evaluator", "engines.tape.evaluator"),
    "surface": ("engines.surface", "common.threads", "common.bounds"),
    "symbols": ("compiler.symbols",),
    "tape_program": ("engines.tape.program",),
    "triangle_mesh": ("meshing.triangle_mesh",),
    "untrusted": ("common.untrusted",),
    "vdb_file": ("files.vdb",),
    "view_server": ("view.server",),
    "viewer": ("view.page",),
    "viewer_assets": ("view.assets",),
    "vm": ("compiler.vm",),
    "voxel_files": ("files.voxel_files",),
    "voxelization": ("voxelizer.voxelize",),
    "zarr_store": ("files.zarr_store", "files.zarr_writer"),
}
"""Old module (below ``implc.``) -> the modules its names now live in, searched in order."""


def _caller_stacklevel() -> int:
    """The stack level of the first frame outside the import machinery and this module."""
    frame: types.FrameType | None = sys._getframe(1)
    level = 1
    while frame is not None and (frame.f_code.co_filename.startswith("<frozen importlib")
                                 or frame.f_code.co_filename == __file__):
        frame, level = frame.f_back, level + 1
    return level


class _OldPath(types.ModuleType):
    def __getattr__(self, name: str):
        for target in self.__targets__:
            module = importlib.import_module(target)
            if hasattr(module, name):
                return getattr(module, name)
        raise AttributeError(f"module {self.__name__!r} has no attribute {name!r}")

    def __dir__(self):
        return sorted({n for t in self.__targets__ for n in dir(importlib.import_module(t))})


class _Finder(importlib.abc.MetaPathFinder, importlib.abc.Loader):
    def find_spec(self, fullname, path, target=None):
        old = fullname.removeprefix("implc.")
        if fullname.startswith("implc.") and old in MOVED:
            return importlib.util.spec_from_loader(fullname, self)
        return None

    def create_module(self, spec):
        targets = tuple(f"implc.{t}" for t in MOVED[spec.name.removeprefix("implc.")])
        warnings.warn(f"{spec.name} has moved to {' and '.join(targets)}; the old path will be removed in the "
                      "next release", DeprecationWarning, stacklevel=_caller_stacklevel())
        module = _OldPath(spec.name)
        module.__targets__ = targets
        if importlib.util.find_spec(targets[0]).submodule_search_locations is not None:
            module.__path__ = []  # an old package: its old submodules are found by this finder too
        return module

    def exec_module(self, module):
        pass


def forward(package: str, targets: tuple[str, ...], name: str):
    """A name of the 0.2 module that the package ``package`` replaced, read from ``targets`` (its modules now)
    with a DeprecationWarning; for the package's ``__getattr__``."""
    for target in targets:
        module = importlib.import_module(f"{package}.{target}")
        if hasattr(module, name):
            warnings.warn(f"{package}.{name} has moved to {package}.{target}.{name}; the old path will be removed "
                          "in the next release", DeprecationWarning, stacklevel=3)
            value = getattr(module, name)
            setattr(sys.modules[package], name, value)  # warned once
            return value
    raise AttributeError(f"module {package!r} has no attribute {name!r}")


def install() -> None:
    """Put the finder on the import path once (after the regular finders: a new module is never shadowed)."""
    if not any(isinstance(f, _Finder) for f in sys.meta_path):
        sys.meta_path.append(_Finder())
