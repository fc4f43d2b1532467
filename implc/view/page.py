"""The browser viewer's page: its assets (``implc/view/assets``: our HTML, CSS and WebGL2 script, no
library), the chunks it reads (:mod:`implc.view.lod_chunks`) or the mesh (:mod:`implc.view.mesh_payload`), a static
export of both, and a self-contained embed for notebooks (``Voxels.show()``, ``Mesh.show()``).

The page reads ``meta.json`` and ``chunks/<level>-<i>-<j>-<k>.bin`` (or ``mesh.bin``) relative to itself, so
the same files work behind :mod:`implc.view.server`, from any static file server (:func:`export`), or
inlined in one HTML document (:func:`embed_html`, chunks as base64 up to a size, a mesh whole).
"""

from __future__ import annotations

import base64
import html
import json
import re
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..common.atomic_file import replacing, replacing_folder
from .json_text import finite
from .lod_chunks import LodChunks
from .mesh_payload import MeshPayload

ASSETS = Path(__file__).resolve().parent / "assets"
ASSET_TYPES = {"index.html": "text/html; charset=utf-8", "viewer.js": "text/javascript; charset=utf-8",
               "viewer.css": "text/css; charset=utf-8"}
EMBED_BYTES = 24 << 20
"""How many bytes of chunks a notebook embed carries by default (coarse levels first)."""


def asset(name: str) -> bytes:
    """One of the page's files, as shipped in the package."""
    if name not in ASSET_TYPES:
        raise KeyError(name)
    return (ASSETS / name).read_bytes()


def lod_chunks(voxels, name: str = "", view=None) -> LodChunks:
    """The chunks of a voxelization (a :class:`~implc.voxelizer.voxelize.Voxels` or anything with Morton-ordered
    coords, normals, depth and bounds)."""
    return LodChunks(voxels, name=name, view=view)


def _is_export(folder: Path) -> bool:
    """Whether ``folder`` holds nothing but an exported viewer (one written before outputs were marked)."""
    names = {p.name for p in folder.iterdir()}
    if not names <= {*ASSET_TYPES, "meta.json", "mesh.bin", "chunks"}:
        return False
    chunks = folder / "chunks"
    return not chunks.exists() or all(re.fullmatch(r"\d+-\d+-\d+-\d+\.bin", p.name) for p in chunks.iterdir())


def export(chunks: LodChunks | MeshPayload, folder, *, budget: int = 1_000_000) -> Path:
    """Write a static, self-contained viewer (index.html, its script and style, meta.json and every
    chunk, or mesh.bin) into ``folder``, replacing it whole once complete."""
    folder = Path(folder)
    with replacing_folder(folder, "viewer", _is_export, marked=False) as tmp:
        for name in ASSET_TYPES:
            (tmp / name).write_bytes(asset(name))
        (tmp / "meta.json").write_bytes(chunks.meta_json(budget))
        if isinstance(chunks, MeshPayload):
            (tmp / "mesh.bin").write_bytes(chunks.body())
            return folder
        (tmp / "chunks").mkdir()
        for level, i, j, k in chunks.chunk_ids():
            (tmp / "chunks" / f"{level}-{i}-{j}-{k}.bin").write_bytes(chunks.chunk(level, i, j, k))
    return folder


def embed_html(chunks: LodChunks | MeshPayload, *, max_bytes: int = EMBED_BYTES, budget: int = 1_000_000) -> str:
    """One HTML document holding the viewer and the coarsest chunks up to ``max_bytes`` (the finest
    levels that fit are shown; nothing is fetched), or the whole mesh (refused beyond ``max_bytes``)."""
    data: dict = {"meta": chunks.meta(budget)}
    if isinstance(chunks, MeshPayload):
        if chunks.size > max_bytes:
            raise ValueError(f"this mesh takes {chunks.size / 2**20:.0f} MiB, more than the {max_bytes / 2**20:.0f} "
                             "MiB a notebook view carries: mesh at a smaller depth, or raise max_bytes")
        data["mesh"] = base64.b64encode(chunks.body()).decode("ascii")
    else:
        data["chunks"] = {f"{c[0]}-{c[1]}-{c[2]}-{c[3]}": base64.b64encode(chunks.chunk(*c) or b"").decode("ascii")
                          for c in chunks.chunk_ids(max_bytes)}
    page = asset("index.html").decode()
    style = f"<style>{asset('viewer.css').decode()}</style>"
    embedded = json.dumps(finite(data), allow_nan=False).replace("</", "<" + chr(92) + "/")
    script = (f"<script>window.IMPLC_EMBED = {embedded};</script>"
              f"<script>{asset('viewer.js').decode()}</script>")
    page = page.replace('<link rel="stylesheet" href="viewer.css">', style)
    return page.replace('<script src="viewer.js"></script>', script)


class NotebookView:
    """What ``Voxels.show()`` and ``Mesh.show()`` return: a notebook displays it as the viewer in an iframe
    (its document inlined, so no server and no second process). :meth:`update` redraws it in place, in the
    same output, with a new model: a new surface (voxelized as the first was), new voxels or a new mesh."""

    def __init__(self, chunks: LodChunks | MeshPayload, *, height: int = 480, max_bytes: int = EMBED_BYTES,
                 budget: int = 1_000_000, remake: Callable[[Any], LodChunks | MeshPayload] | None = None):
        """``remake``: what turns the model given to :meth:`update` into chunks (the voxelizer's, from
        ``Voxels.show()``: a surface voxelized at the same depth)."""
        self.height, self.max_bytes, self.budget, self.remake = height, max_bytes, budget, remake
        self.document = embed_html(chunks, max_bytes=max_bytes, budget=budget)
        self._handle: Any = None

    def _repr_html_(self) -> str:
        return (f'<div class="implc-view"><iframe srcdoc="{html.escape(self.document, quote=True)}" '
                f'style="width: 100%; height: {self.height}px; border: 0" '
                f'sandbox="allow-scripts" title="implc viewer"></iframe></div>')

    def _ipython_display_(self):
        """Shown in an output of its own that :meth:`update` can replace."""
        from IPython.display import HTML, display
        self._handle = display(HTML(self._repr_html_()), display_id=True)

    def update(self, model) -> NotebookView:
        """Show ``model`` instead, in the output this view was displayed in: a SymPy expression or a
        compiled surface (for a view of voxels: voxelized at their depth and bounds), voxels or a mesh."""
        if isinstance(model, (LodChunks, MeshPayload)):
            chunks = model
        elif hasattr(model, "faces"):
            chunks = MeshPayload(model)
        elif hasattr(model, "coords"):
            chunks = lod_chunks(model)
        elif self.remake is not None:
            chunks = self.remake(model)
        else:
            raise TypeError(f"a mesh's view shows meshes: got {type(model).__name__}")
        self.document = embed_html(chunks, max_bytes=self.max_bytes, budget=self.budget)
        if self._handle is not None:
            from IPython.display import HTML
            self._handle.update(HTML(self._repr_html_()))
        return self

    def save(self, path) -> Path:
        """Write the self-contained document to ``path`` (an .html any browser opens)."""
        path = Path(path)
        with replacing(path) as tmp:
            tmp.write_text(self.document, encoding="utf-8")
        return path
