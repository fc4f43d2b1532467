"""The documentation's promises: the docstring examples of the public API run and print what they show
(doctest), every public name has a docstring, and every page of the site is reachable from its index."""

import doctest
import importlib
import inspect
from pathlib import Path

import pytest

import implc

ROOT = Path(__file__).resolve().parent.parent
DOCTESTED = [
    "implc.engines.surface",
    "implc.voxelizer.voxelize",
    "implc.compiler.vm",
    "implc.meshing.triangle_mesh",
    "implc.shapes",
    "implc.shapes.sketch",
    "implc.shapes.solids",
    "implc.shapes.csg",
    "implc.shapes.offsets",
    "implc.shapes.transforms",
]
"""Modules whose docstring examples run: compile, Surface.eval/gradient/interval, voxelize, Voxels and its
methods, mesh, load_vm (the issue names these)."""
PUBLIC_MODULES = [
    "implc.engines.surface",
    "implc.voxelizer.voxelize",
    "implc.compiler.vm",
    "implc.meshing.triangle_mesh",
    "implc.shapes",
    "implc.files.voxel_files",
    "implc.files.zarr_store",
    "implc.files.zarr_writer",
    "implc.files.slices",
    "implc.view.render",
    "implc.files.scene",
    "implc.errors",
    "implc.common.untrusted",
    "implc.cluster.tasks",
    "implc.cluster.recipe",
    "implc.shapes.sketch",
    "implc.shapes.solids",
    "implc.shapes.csg",
    "implc.shapes.offsets",
    "implc.shapes.transforms",
    "implc.shapes.deform",
    "implc.shapes.repeat",
    "implc.shapes.lattices",
]


@pytest.mark.parametrize("name", DOCTESTED)
def test_docstring_examples_run(name, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)  # an example that writes a file writes it here
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE, verbose=False)
    assert result.failed == 0, f"{result.failed} of {result.attempted} docstring examples of {name} failed"


def test_the_named_functions_carry_examples():
    named = [implc.compile, implc.voxelize, implc.mesh, implc.load_vm, implc.Voxels, implc.Surface.eval,
             implc.Surface.gradient, implc.Surface.interval]
    assert [f.__qualname__ for f in named if ">>>" not in (f.__doc__ or "")] == []


def _public(module):
    names = getattr(module, "__all__", None) or [n for n in vars(module) if not n.startswith("_")]
    for name in names:
        value = getattr(module, name)
        if (inspect.isfunction(value) or inspect.isclass(value)) and value.__module__ == module.__name__:
            yield name, value
            if inspect.isclass(value):
                for attr, member in vars(value).items():
                    if not attr.startswith("_") and (inspect.isfunction(member) or isinstance(member, property)):
                        yield f"{name}.{attr}", member


@pytest.mark.parametrize("name", PUBLIC_MODULES)
def test_every_public_name_has_a_docstring(name):
    module = importlib.import_module(name)
    assert module.__doc__, f"{name} has no module docstring"
    missing = [qualified for qualified, value in _public(module) if not (value.__doc__ or "").strip()]
    assert missing == [], f"{name}: public names without a docstring: {missing}"


def test_every_package_level_name_is_documented():
    missing = [n for n in implc.__all__ if n not in ("x", "y", "z", "r", "theta", "phi", "NATURAL", "TIGHTEST")
               and not (getattr(implc, n).__doc__ or "").strip()]
    assert missing == []


def test_every_page_is_in_the_table_of_contents():
    docs = ROOT / "docs"
    index = (docs / "index.md").read_text()
    pages = sorted(p.relative_to(docs).with_suffix("").as_posix() for p in docs.rglob("*.md")
                   if "_build" not in p.parts and "gallery" not in p.parts and p.name != "index.md")
    assert [p for p in pages if p not in index] == []


NOTEBOOKS = sorted((ROOT / "examples").glob("*.ipynb"))


def test_notebooks_are_stored_without_outputs():
    import nbformat
    assert len(NOTEBOOKS) >= 2
    for path in NOTEBOOKS:
        nb = nbformat.read(path, as_version=4)
        assert all(not cell.get("outputs") and cell.get("execution_count") is None
                   for cell in nb.cells if cell.cell_type == "code"), f"{path.name} has outputs stored"


@pytest.mark.slow
@pytest.mark.parametrize("path", NOTEBOOKS, ids=[p.stem for p in NOTEBOOKS])
def test_notebooks_run(path, tmp_path):
    """Each notebook runs top to bottom in a fresh kernel, in a temporary folder (its own checks included:
    the part's volume bracketed, its mesh closed)."""
    import nbformat
    from nbclient import NotebookClient
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    errors = [o for cell in nb.cells for o in cell.get("outputs", []) if o.get("output_type") == "error"]
    assert errors == []


ANNOTATED = [m for m in PUBLIC_MODULES if m not in ("implc.errors", "implc.common.untrusted")]
"""The public modules whose functions are annotated (the exceptions module has none; untrusted's helpers
take what the readers hand them)."""


@pytest.mark.parametrize("name", ANNOTATED)
def test_the_public_api_is_annotated(name):
    """Every public function and method of the public modules has annotated parameters and a return type
    (py.typed promises them to an editor; mypy checks them in CI)."""
    module = importlib.import_module(name)
    bare = []
    for qualified, value in _public(module):
        if not inspect.isfunction(value):
            continue
        signature = inspect.signature(value)
        params = [p.name for p in signature.parameters.values()
                  if p.name not in ("self", "cls") and p.annotation is inspect.Parameter.empty]
        if params or signature.return_annotation is inspect.Signature.empty:
            bare.append(f"{qualified}({', '.join(params)})")
    assert bare == []
    assert (ROOT / "implc" / "py.typed").is_file()
