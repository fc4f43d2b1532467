"""Every example script runs at a small depth and writes what it promises."""

import runpy
from pathlib import Path

import pytest

EXAMPLES = sorted((Path(__file__).parent.parent / "examples").glob("*.py"))


def test_there_are_examples():
    assert len(EXAMPLES) >= 5


@pytest.mark.parametrize("path", EXAMPLES, ids=[p.stem for p in EXAMPLES])
def test_example_runs(path, tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setenv("IMPLC_EXAMPLE_DEPTH", "5")
    lines = path.read_text().splitlines()
    assert 5 <= len([line for line in lines if line.strip()]) <= 20
    runpy.run_path(str(path), run_name="__main__")
    written = [p for p in tmp_path.iterdir() if p.suffix in (".png", ".ply", ".npz")]
    assert written and all(p.stat().st_size > 0 for p in written)
