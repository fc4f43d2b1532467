"""Every example script runs at a small depth and writes what it promises."""

import runpy
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from plyfile import PlyData

from implc.files import voxel_files

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
    written = sorted(p for p in tmp_path.iterdir() if p.suffix in (".png", ".ply", ".npz"))
    assert written
    counts = set()
    for out in written:
        if out.suffix == ".png":  # a picture of a surface: a background and shaded points of many tones
            image = np.asarray(Image.open(out).convert("RGB"))
            covered = np.any(image != image[0, 0], axis=2)
            assert 0.02 < covered.mean() < 0.95, out.name
            assert len(np.unique(image[covered].reshape(-1, 3), axis=0)) > 20, f"{out.name}: not shaded"
        elif out.suffix == ".npz":
            voxels = voxel_files.load_npz(out)
            assert voxels.depth == 5 and len(voxels) > 0
            counts.add(len(voxels))
        else:
            counts.add(PlyData.read(str(out))["vertex"].count)
    assert len(counts) <= 1, f"the files disagree on the voxel count: {counts}"
