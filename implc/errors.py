"""The exceptions implc raises on purpose, every one a ``ValueError``: each says in one line what is wrong
with the user's input and where. Each is re-exported by the module that raises it."""


class CompileError(ValueError):
    """The compiler rejected an expression or its bounds; the message names the offending part."""


class VmError(CompileError):
    """A ``.vm`` file that cannot be read: the message names the file, the line and the problem."""


class TravelError(ValueError):
    """A surface that cannot be rebuilt in another process from what it was built from."""


class ClusterError(ValueError):
    """A cluster that cannot be used: distributed missing, a scheduler that cannot be reached, a bad address."""


class StoreError(ValueError):
    """A folder that is not a complete implc Zarr store."""


class ExprError(ValueError):
    """The formula is not in the accepted language."""


class MeshFileError(ValueError):
    """A mesh file that cannot be read or written; the message names the file."""


class SceneError(ValueError):
    """A scene file is missing, broken or lacks ``surface``."""


class VoxelFileError(ValueError):
    """A voxel file is missing, unreadable, damaged or not one of ours."""


def shorten(value, limit: int = 80, *, quoted: bool = False) -> str:
    """How ``value`` appears in an error message: ``str`` (``repr`` if ``quoted``), cut to ``limit``
    characters; a value too large to print (a SymPy integer of more than 4,300 digits) is named by type."""
    try:
        text = repr(value) if quoted else str(value)
    except ValueError:
        return f"<a {type(value).__name__} too large to print>"
    return text if len(text) <= limit else text[: limit - 3] + "..."
