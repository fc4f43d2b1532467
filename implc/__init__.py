"""implc: a symbolic surface compiler. SymPy surface in, sound native interval kernels and voxels out.

The public names are imported on first use (PEP 562), so that ``import implc`` and the ``implc`` command
start without loading SymPy, NumPy and LLVM until they are needed.
"""

from importlib import import_module

from .common import moved

_EXPORTS = {
    "CompileError": "errors", "Surface": "engines.surface", "compile": "engines.surface",
    "Voxels": "voxelizer.voxelize", "voxelize": "voxelizer.voxelize", "NATURAL": "voxelizer.voxelize",
    "TIGHTEST": "voxelizer.voxelize", "mesh": "voxelizer.voxelize", "Mesh": "meshing.triangle_mesh",
    "load_vm": "compiler.vm", "x": "compiler.symbols", "y": "compiler.symbols", "z": "compiler.symbols",
    "r": "compiler.symbols", "theta": "compiler.symbols", "phi": "compiler.symbols",
}

__all__ = ["NATURAL", "TIGHTEST", "CompileError", "Mesh", "Surface", "Voxels", "compile", "load_vm", "mesh", "phi",
           "r", "shapes", "theta", "voxelize", "x", "y", "z"]
__version__ = "0.2.0"
"""The one place the version is set: the build reads it (pyproject.toml), and so does ``implc --version``."""
moved.install()


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    else:
        try:  # a submodule: implc.shapes, implc.native.abi, ...
            value = import_module(f".{name}", __name__)
        except ModuleNotFoundError:
            raise AttributeError(f"module 'implc' has no attribute {name!r}") from None
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
