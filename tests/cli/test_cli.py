"""The implc command: every subcommand works, and every user error is one line on stderr with exit 2."""

import os
from pathlib import Path

import numpy as np
import pytest
from PIL import Image
from plyfile import PlyData

import implc
from implc.cli.commands import main
from implc.files import scene, voxel_files

from ..support.command import run


def test_scenes_lists_every_scene_with_a_line(capsys):
    assert main(["scenes"]) == 0
    lines = capsys.readouterr().out.strip().splitlines()
    names = [line.split()[0] for line in lines]
    for required in ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4", "torus", "tangle_cube",
                     "gyroid_sphere", "heart", "csg_part"):
        assert required in names
    assert len(names) >= 9


def test_voxelize_info_render_round_trip(tmp_path, capsys):
    out = tmp_path / "blobs.npz"
    assert main(["voxelize", "paper_blobs", "--depth", "6", "--workers", "2", "-o", str(out)]) == 0
    summary = capsys.readouterr().out
    assert "voxels at 64³" in summary and "yield" in summary
    voxels = voxel_files.load_npz(out)
    assert voxels.depth == 6 and len(voxels) > 0
    assert main(["info", str(out)]) == 0
    info = capsys.readouterr().out
    assert f"voxels   {len(voxels)}" in info and "64³" in info
    png = tmp_path / "blobs.png"
    assert main(["render", str(out), "-o", str(png), "--size", "128", "--view", "10,60", "--lod", "5"]) == 0
    from PIL import Image
    with Image.open(png) as image:
        assert image.size == (128, 128)


def test_voxelize_expr_and_formats(tmp_path):
    for suffix in (".npz", ".ply", ".npy"):
        out = tmp_path / f"s{suffix}"
        assert main(["voxelize", "--expr", "sin(4*theta)*sin(8*phi) - r", "--depth", "5", "--quiet",
                     "-o", str(out)]) == 0
    voxels = voxel_files.load_npz(tmp_path / "s.npz")
    dense = np.load(tmp_path / "s.npy")
    assert dense.shape == (32, 32, 32) and dense.dtype == bool
    np.testing.assert_array_equal(dense, voxels.to_dense())
    vertex = PlyData.read(str(tmp_path / "s.ply"))["vertex"]
    assert vertex.count == len(voxels) > 0
    np.testing.assert_allclose(np.column_stack([vertex["x"], vertex["y"], vertex["z"]]), voxels.centers(),
                               rtol=1e-6, atol=1e-7)


def test_render_scene_directly_with_perspective(tmp_path):
    png = tmp_path / "t.png"
    assert main(["render", "torus", "--depth", "6", "--quiet", "-o", str(png), "--size", "96", "--perspective",
                 "--color", "0.2,0.5,0.9"]) == 0
    image = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert image.shape == (96, 96, 3)
    covered = np.any(image != image[0, 0], axis=2)
    assert 0.05 < covered.mean() < 0.9  # the torus, not an empty or a filled frame
    lit = image[covered]
    assert np.median(lit[:, 2]) > np.median(lit[:, 0])  # in the colour asked for: blue over red


@pytest.mark.parametrize("formula", [
    "__import__('os').system('echo pwned')",
    "x.__class__",
    "(lambda: 1)()",
    "[x for x in ()]",
    "open('/etc/passwd')",
    "sin(x) if x else y",
    "x ^ 2",
    "exec('1')",
    "sympy.sin(x)",
    "x + w",
    "10**10**10",
    "sin(x, y)",
    "x; y",
])
def test_expr_never_executes_code(formula, tmp_path):
    marker = tmp_path / "pwned"
    status, out, err = run("voxelize", "--expr", formula.replace("pwned", str(marker)), "--depth", "4",
                           "-o", str(tmp_path / "x.npz"))
    assert status == 2
    assert err.startswith("implc: error: --expr:") and len(err.strip().splitlines()) == 1, err
    assert "Traceback" not in err and not marker.exists()
    assert not (tmp_path / "x.npz").exists()


@pytest.mark.skipif(os.geteuid() == 0, reason="running as root: every folder is writable, so no permission "
                                               "error can be provoked")
def test_an_unwritable_output_is_one_line_with_exit_2(tmp_path):
    readonly = tmp_path / "ro"
    readonly.mkdir()
    readonly.chmod(0o500)
    status, _, err = run("voxelize", "torus", "-o", str(readonly / "a.npz"))
    assert status == 2 and err.strip() == f"implc: error: cannot write {readonly / 'a.npz'}: permission denied"


def test_demo_writes_the_three_renders(tmp_path, capsys):
    assert main(["demo", "--depth", "5", "--size", "64", "--out-dir", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    images = {}
    for name in ("paper_blobs", "paper_sin4_sin8", "paper_sin3_sin4"):
        assert name in out
        image = np.asarray(Image.open(tmp_path / f"{name}.png").convert("RGB"))
        assert image.shape == (64, 64, 3)
        covered = np.any(image != image[0, 0], axis=2)
        assert 0.05 < covered.mean() < 0.95, name  # a surface in the frame
        images[name] = covered
    assert not np.array_equal(images["paper_blobs"], images["paper_sin4_sin8"])  # each scene its own picture


def test_console_script_is_declared():
    text = (Path(__file__).resolve().parents[2] / "pyproject.toml").read_text()
    assert 'implc = "implc.cli.commands:console"' in text  # main() for a process that ends when it returns


def test_tightness_option_spells_the_presets_and_changes_the_leaves(tmp_path):
    """--tightness natural / default / tightest are implc.NATURAL, the default and implc.TIGHTEST: the
    natural mode keeps the most voxels, the tightest the fewest, each file the same as the API's."""
    from implc.cli import arguments
    assert arguments.TIGHTNESS == {"natural": implc.NATURAL, "default": {}, "tightest": implc.TIGHTEST}
    counts = {}
    for mode in ("natural", "default", "tightest"):
        out = tmp_path / f"{mode}.npz"
        assert main(["voxelize", "paper_sin3_sin4", "--depth", "6", "--quiet", "--tightness", mode,
                     "-o", str(out)]) == 0
        counts[mode] = len(voxel_files.load_npz(out))
    sc = scene.load("paper_sin3_sin4")
    s = implc.compile(sc.surface, sc.bounds)
    assert counts["natural"] == len(implc.voxelize(s, 6, **implc.NATURAL))
    assert counts["default"] == len(implc.voxelize(s, 6))
    assert counts["natural"] > counts["default"] >= counts["tightest"]


def test_surface_options_given_with_a_file_are_refused_in_one_line(tmp_path, capsys):
    """--expr, --depth, --bounds, --workers (and for a mesh --budget) make no sense for a file shown or
    rendered as saved: one line naming them, exit status 2, for voxel and mesh files alike."""
    ball = implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 0.5)
    voxel_files.save(implc.voxelize(ball, 4), tmp_path / "b.npz")
    implc.mesh(ball, 4).save(tmp_path / "b.stl")
    cases = [(["render", str(tmp_path / "b.npz"), "--depth", "5", "-o", str(tmp_path / "x.png")],
              f"--depth cannot apply to a voxel file ({tmp_path / 'b.npz'}): it is rendered as saved"),
             (["view", str(tmp_path / "b.npz"), "--workers", "2", "--no-browser"],
              f"--workers cannot apply to a voxel file ({tmp_path / 'b.npz'}): it is shown as saved"),
             (["view", str(tmp_path / "b.stl"), "--depth", "3", "--budget", "5000", "--no-browser"],
              f"--depth, --budget cannot apply to a mesh file ({tmp_path / 'b.stl'}): it is shown as saved")]
    for argv, line in cases:
        assert main(argv) == 2
        err = capsys.readouterr().err.strip().splitlines()
        assert err == [f"implc: error: {line}"], err
