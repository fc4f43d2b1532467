"""implc: a symbolic surface compiler. SymPy surface in, sound native interval kernels and voxels out.

The public names are imported on first use (PEP 562), so that ``import implc`` and the ``implc`` command
start without loading SymPy, NumPy and LLVM until they are needed.
"""

from importlib import import_module

_EXPORTS = {
    "CompileError": "errors", "Surface": "surface", "compile": "surface", "Voxels": "voxelization",
    "voxelize": "voxelization", "x": "symbols", "y": "symbols", "z": "symbols", "r": "symbols", "theta": "symbols",
    "phi": "symbols", "load_vm": "vm", "mesh": "voxelization", "Mesh": "triangle_mesh", "NATURAL": "voxelization",
    "TIGHTEST": "voxelization",
}

__all__ = ["NATURAL", "TIGHTEST", "CompileError", "Mesh", "Surface", "Voxels", "compile", "load_vm", "mesh", "phi",
           "r", "shapes", "theta", "voxelize", "x", "y", "z"]
__version__ = "0.2.0"
"""The one place the version is set: the build reads it (pyproject.toml), and so does ``implc --version``."""


def __getattr__(name: str):
    if name in _EXPORTS:
        value = getattr(import_module(f".{_EXPORTS[name]}", __name__), name)
    else:
        try:  # a submodule: implc.shapes, implc.abi, ...
            value = import_module(f".{name}", __name__)
        except ModuleNotFoundError:
            raise AttributeError(f"module 'implc' has no attribute {name!r}") from None
    globals()[name] = value
    return value


def __dir__():
    return sorted(set(globals()) | set(__all__))
