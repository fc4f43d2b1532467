"""implc: a symbolic surface compiler. SymPy surface in, sound native interval kernels and voxels out."""

from . import shapes
from .errors import CompileError
from .surface import Surface, compile
from .symbols import phi, r, theta, x, y, z
from .voxelize import Voxels, voxelize

__all__ = [
           "CompileError",
           "Surface",
           "Voxels",
           "compile",
           "phi",
           "r",
           "shapes",
           "theta",
           "voxelize",
           "x",
           "y",
           "z",
]
__version__ = "0.1.0"
