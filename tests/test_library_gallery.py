"""The gallery's pictures of the shapes library (``examples/library/``): every function of
:mod:`implc.shapes` has a tile labelled with its name that calls it, and the script draws every tile."""

import ast
import runpy
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from implc import shapes

SCRIPTS = sorted((Path(__file__).resolve().parent.parent / "examples" / "library").glob("*.py"))
FUNCTIONS = set(shapes.__all__) - {"Number", "Vec"}  # the two types are no shapes


def tiles(path):
    """(label, the names of implc.shapes the tile's expression calls) for each ``tile("label", expr, ...)``
    call of the script, read from its source."""
    found = []
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.Call) and isinstance(node.func, ast.Name) and node.func.id == "tile":
            label, expr = node.args[:2]
            assert isinstance(label, ast.Constant) and isinstance(label.value, str), ast.unparse(node)
            called = {n.func.attr for n in ast.walk(expr) if isinstance(n, ast.Call)
                      and isinstance(n.func, ast.Attribute) and isinstance(n.func.value, ast.Name)
                      and n.func.value.id == "shapes"}
            found.append((label.value, called))
    return found


def test_every_function_of_the_library_has_a_tile_that_calls_it():
    assert SCRIPTS
    shown = [(label.split()[0], called) for path in SCRIPTS for label, called in tiles(path)]
    assert [name for name, called in shown if name not in called] == [], "a tile that does not call its label"
    assert [name for name, _ in shown if name not in FUNCTIONS] == [], "a tile named after no shapes function"
    assert sorted(FUNCTIONS - {name for name, _ in shown}) == [], "functions missing from the gallery"


@pytest.mark.slow  # about 10 s: some 70 surfaces compiled into the test run's empty kernel cache
@pytest.mark.parametrize("path", SCRIPTS, ids=[p.stem for p in SCRIPTS])
def test_the_library_gallery_draws_every_tile(path, tmp_path, monkeypatch):
    """Each tile of each picture shows a solid (as many drawn tiles as tile calls in the script), and each
    picture is shaded (a tile alone may be one tone: a plane, seen orthographically)."""
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("IMPLC_EXAMPLE_DEPTH", "5")
    namespace = runpy.run_path(str(path), run_name="__main__")
    size, columns = namespace["SIZE"], namespace["COLUMNS"]
    pictures = sorted(tmp_path.glob("*.png"))
    assert len(pictures) == 8  # one per group
    drawn = 0
    for picture in pictures:
        image = np.asarray(Image.open(picture).convert("RGB"))
        background = image[0, 0]
        for row in range(image.shape[0] // size):
            for column in range(columns):
                cell = image[row * size:(row + 1) * size, column * size:(column + 1) * size]
                cell = cell[size // 8:]  # below the label
                covered = np.any(cell != background, axis=2)
                if covered.any():
                    assert covered.mean() > 0.01, (picture.name, row, column)
                    drawn += 1
        shown = image[np.any(image != background, axis=2)]
        assert len(np.unique(shown, axis=0)) > 20, f"{picture.name}: not shaded"
    assert drawn == len(tiles(path))
