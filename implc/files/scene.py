"""Scene files: plain Python modules defining ``surface`` (a SymPy expression) and ``bounds``.

A scene is named by its file stem (looked up in the built-in scenes, :data:`SCENES_DIR`) or given as a
path. Optional module-level names: ``depth`` (default voxelization depth) and ``view`` ((azimuth,
elevation)). The built-in scenes are the project's top-level ``scenes/`` folder: a source checkout (or an
editable install) reads its own, next to the package it imported; a wheel carries a copy inside the
package (``implc/scene_files/``, put there by ``setup.py`` at build time).
"""

from __future__ import annotations

import math
import runpy
import sys
from dataclasses import dataclass
from pathlib import Path

import sympy

from ..common.bounds import check_bounds
from ..common.untrusted import regular_file
from ..errors import CompileError, SceneError, shorten
from ..native.abi import MAX_DEPTH


def _scenes_dir() -> Path:
    """The checkout's scenes/ beside this package when it is imported from a checkout, else the copy
    inside the installed package."""
    package = Path(__file__).resolve().parents[1]  # implc/
    checkout = package.parent
    if (checkout / "pyproject.toml").is_file() and (checkout / "scenes").is_dir():
        return checkout / "scenes"
    return package / "scene_files"


SCENES_DIR = _scenes_dir()


@dataclass(frozen=True)
class Scene:
    """A scene: its name, surface (a SymPy expression), bounds, default depth and view, and docstring."""

    name: str
    surface: object
    bounds: tuple
    depth: int = 9
    view: tuple | None = None
    doc: str = ""

    @property
    def title(self) -> str:
        """The first line of the scene's docstring (its name where it has none)."""
        return self.doc.strip().splitlines()[0] if self.doc.strip() else self.name


def available() -> list[str]:
    """The built-in scenes' names."""
    return sorted(p.stem for p in SCENES_DIR.glob("*.py") if not p.stem.startswith("_"))


def load(name_or_path: str) -> Scene:
    """A built-in scene by name (see :func:`available`) or a scene file by its path; :class:`SceneError`
    naming the problem for a missing, broken or incomplete one."""
    path = Path(name_or_path)
    if path.suffix != ".py":
        path = SCENES_DIR / f"{name_or_path}.py"
    if not path.exists():
        raise SceneError(f"no scene {name_or_path!r} (known: {', '.join(available())}; or a path to a .py "
                         "scene file)")
    regular_file(path, SceneError, "scene file")  # a folder, a FIFO or a device: refused before it is run
    folder = str(path.resolve().parent)
    sys.path.insert(0, folder)  # as ``python part.py`` would: the modules beside the scene import
    try:
        namespace = runpy.run_path(str(path))
    except Exception as exc:  # the scene's own error, reported with its file
        raise SceneError(f"scene {path} failed to load: {type(exc).__name__}: {exc}") from exc
    finally:
        if folder in sys.path:
            sys.path.remove(folder)
    if "surface" not in namespace:
        raise SceneError(f"scene {path} defines no 'surface'")
    return Scene(name=path.stem, surface=_checked_surface(path, namespace["surface"]),
                 bounds=_checked_bounds(path, namespace.get("bounds", ((-1, 1), (-1, 1), (-1, 1)))),
                 depth=_checked_depth(path, namespace.get("depth", 9)),
                 view=_checked_view(path, namespace.get("view")), doc=str(namespace.get("__doc__") or ""))


def _checked_surface(path, surface):
    if not isinstance(surface, sympy.Expr):
        raise SceneError(f"scene {path}: 'surface' must be a SymPy expression, got {type(surface).__name__} "
                         f"{shorten(surface, quoted=True)}")
    return surface


def _checked_bounds(path, bounds):
    try:
        return check_bounds(bounds, MAX_DEPTH)
    except CompileError as exc:
        raise SceneError(f"scene {path}: 'bounds': {exc}") from None


def _checked_depth(path, depth):
    if isinstance(depth, bool) or not isinstance(depth, int) or not 1 <= depth <= MAX_DEPTH:
        raise SceneError(f"scene {path}: 'depth' must be an integer from 1 to {MAX_DEPTH}, got "
                         f"{shorten(depth, quoted=True)}")
    return depth


def _checked_view(path, view):
    if view is None:
        return None
    try:
        azimuth, elevation = (float(v) for v in view)
    except (TypeError, ValueError):
        raise SceneError(f"scene {path}: 'view' must be two numbers (azimuth, elevation) in degrees, got "
                         f"{shorten(view, quoted=True)}") from None
    if not (math.isfinite(azimuth) and math.isfinite(elevation)):
        raise SceneError(f"scene {path}: 'view' must be finite, got {shorten(view, quoted=True)}")
    return (azimuth, elevation)
