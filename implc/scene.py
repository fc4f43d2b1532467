"""Scene files: plain Python modules defining ``surface`` (a SymPy expression) and ``bounds``.

A scene is named by its file stem (looked up in the project's ``scenes/`` folder) or given as a path.
Optional module-level names: ``depth`` (default voxelization depth) and ``view`` ((azimuth, elevation)).
"""

from __future__ import annotations

import runpy
from dataclasses import dataclass
from pathlib import Path


def _scenes_dir() -> Path:
    """The project's scenes/ folder (installed as the implc.scenes package)."""
    try:
        from . import scenes as package
        return Path(next(iter(package.__path__)))
    except ImportError:  # running from a source tree that was never installed
        return Path(__file__).resolve().parent.parent / "scenes"


SCENES_DIR = _scenes_dir()


@dataclass(frozen=True)
class Scene:
    name: str
    surface: object
    bounds: tuple
    depth: int = 9
    view: tuple | None = None
    doc: str = ""

    @property
    def title(self) -> str:
        return self.doc.strip().splitlines()[0] if self.doc.strip() else self.name


class SceneError(ValueError):
    """A scene file is missing, broken or lacks ``surface``."""


def available() -> list[str]:
    return sorted(p.stem for p in SCENES_DIR.glob("*.py") if not p.stem.startswith("_"))


def load(name_or_path: str) -> Scene:
    path = Path(name_or_path)
    if path.suffix != ".py":
        path = SCENES_DIR / f"{name_or_path}.py"
    if not path.is_file():
        raise SceneError(f"no scene {name_or_path!r} (known: {', '.join(available())})")
    try:
        namespace = runpy.run_path(str(path))
    except Exception as exc:  # the scene's own error, reported with its file
        raise SceneError(f"scene {path} failed to load: {type(exc).__name__}: {exc}") from exc
    if "surface" not in namespace:
        raise SceneError(f"scene {path} defines no 'surface'")
    return Scene(name=path.stem, surface=namespace["surface"],
                 bounds=namespace.get("bounds", ((-1, 1), (-1, 1), (-1, 1))),
                 depth=int(namespace.get("depth", 9)), view=namespace.get("view"),
                 doc=namespace.get("__doc__") or "")
