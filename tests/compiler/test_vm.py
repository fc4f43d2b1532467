"""Models in the .vm tape format of fidget and MPR: read in one pass into a tape, compiled, and voxelized
without missing a cell where a numpy interpreter of the .vm text (not implc's compiler) sees F change
sign; clear errors for bad files; any depth without recursion."""

import numpy as np
import pytest

import implc
from implc import CompileError
from implc.cli.commands import main
from implc.compiler.vm import VmError, parse_vm
from implc.engines.compiled.plan import plan_regions

from ..support.models import BLEND, CSG, TANGLE, interpret, sign_change_cells


@pytest.mark.parametrize("name, text", [("csg", CSG), ("blend", BLEND), ("tangle", TANGLE)])
def test_no_sign_change_cell_of_the_vm_text_is_missed(name, text):
    model = parse_vm(text, name=name)
    bounds = ((-4.5, 4.5),) * 3 if name == "tangle" else model.bounds
    s = implc.compile(model, bounds)
    depth = 6
    voxels = implc.voxelize(s, depth, storage="coords").to_dense()
    expected = sign_change_cells(text, bounds, depth)
    assert expected.sum() > 100, "the surface must cross the box"
    missed = np.argwhere(expected & ~voxels)
    assert len(missed) == 0, f"{name}: {len(missed)} missed cells, e.g. {missed[:5].tolist()}"
    assert voxels.sum() < voxels.size / 8  # and not everything either (x⁴ − 5x² keeps ~3.5x: issue 14)
    pts = np.random.default_rng(0).uniform(bounds[0][0], bounds[0][1], (200, 3))
    np.testing.assert_allclose(s.eval(pts), interpret(text, *pts.T), rtol=1e-12, atol=1e-12)


def test_the_header_scale_suggests_the_bounds():
    assert parse_vm(CSG).bounds == ((-1.25, 1.25),) * 3
    assert parse_vm(TANGLE).bounds == ((-1.0, 1.0),) * 3
    assert implc.compile(parse_vm(CSG)).bounds == ((-1.25, 1.25),) * 3


def test_constants_are_enclosed_exactly():
    model = parse_vm("x var-x\nc const 0.1\nout sub x c\n")
    const = [attr for op, _, attr in model.tape.nodes if op == "const"][0]
    from fractions import Fraction
    assert Fraction(const[1]) < Fraction("0.1") < Fraction(const[2])


@pytest.mark.parametrize("text, words", [
    ("", "no instructions"),
    ("# only a comment\n", "no instructions"),
    ("x var-x\ny frob x\n", "unknown op 'frob'"),
    ("x var-x\nout add x q\n", "'q' is not defined"),
    ("x var-x\nout add x\n", "add takes 2 arguments, got 1"),
    ("x var-x\nx var-y\n", "defined twice"),
    ("c const abc\n", "'abc' is not a decimal number"),
    ("x\n", "expected 'NAME OP ARG"),
])
def test_bad_files_are_named_with_their_line(text, words):
    with pytest.raises(VmError, match=words):
        parse_vm(text, where="m.vm")
    assert issubclass(VmError, CompileError)


def test_any_depth_loads_without_recursion():
    """A chain of 20,000 min instructions (deeper than Python's recursion limit) loads in one pass, and
    its region plan finds all its leaves."""
    lines = ["x var-x", "y var-y", "acc sub x y"]
    for k in range(20_000):
        lines += [f"c{k} const {k / 1000}", f"d{k} sub x c{k}", f"m{k} min acc d{k}" if k == 0 else
                  f"m{k} min m{k - 1} d{k}"]
    model = parse_vm("\n".join(lines))
    assert model.instructions == 3 + 3 * 20_000
    assert len(plan_regions(model.tape).chain_leaves) > 10_000


def test_cli_takes_a_vm_file(tmp_path, capsys):
    path = tmp_path / "csg.vm"
    path.write_text(CSG)
    out = tmp_path / "csg.npz"
    assert main(["voxelize", str(path), "--depth", "5", "--quiet", "-o", str(out)]) == 0
    from implc.files import voxel_files
    v = voxel_files.load_npz(out)
    assert v.bounds == ((-1.25, 1.25),) * 3 and len(v) > 0
    assert main(["info", str(path)]) == 0
    assert "31 instructions" in capsys.readouterr().out
    (tmp_path / "bad.vm").write_text("x var-x\nout add x q\n")
    assert main(["voxelize", str(tmp_path / "bad.vm"), "-o", str(tmp_path / "b.npz")]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "bad.vm:2: 'q' is not defined" in err
    assert not (tmp_path / "b.npz").exists()


def test_a_model_runs_without_importing_sympy(tmp_path):
    """A .vm model needs no SymPy (its import is about a quarter of a second of a fresh process): the
    CLI and the API load, compile, voxelize and mesh it in a process that never imports it."""
    import os
    import subprocess
    import sys
    path = tmp_path / "csg.vm"
    path.write_text(CSG)
    cli = [["mesh", str(path), "--depth", "4", "--quiet", "-o", str(tmp_path / "m.stl")],
           ["voxelize", str(path), "--depth", "4", "--quiet", "-o", str(tmp_path / "v.npz")]]
    script = ("import sys, implc\nfrom implc.cli.commands import main\n"
              f"m = implc.load_vm({str(path)!r}); s = implc.compile(m)\n"
              "assert len(implc.voxelize(s, 5)) > 0 and len(implc.mesh(s, 5).faces) > 0\n"
              f"assert [main(argv) for argv in {cli!r}] == [0, 0]\n"
              "print(sorted(name for name in sys.modules if name.split('.')[0] == 'sympy'))\n")
    env = {**os.environ, "IMPLC_CACHE_DIR": str(tmp_path / "kernels")}
    run = subprocess.run([sys.executable, "-c", script], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert run.stdout.strip() == "[]"


DISC = "x var-x\ny var-y\nr const 0.6\nx2 square x\ny2 square y\ns add x2 y2\nd sqrt s\nout sub d r\n"


def test_a_model_composes_with_sympy():
    """model(x, y, z) is a SymPy expression that compile inlines: a 2-D model extruded by Max, and a model
    moved and scaled, each against the numpy run of the .vm text."""
    import sympy

    from implc import x, y, z
    disc = parse_vm(DISC, name="disc")
    slab = sympy.Max(disc(x, y, z), sympy.Abs(z) - sympy.Rational(1, 10))
    moved = parse_vm(CSG, name="csg")(2 * x - sympy.Rational(1, 2), y, z + sympy.Rational(1, 5))
    pts = np.random.default_rng(5).uniform(-1, 1, (64, 3))
    slab_truth = np.maximum(interpret(DISC, *pts.T), np.abs(pts[:, 2]) - 0.1)
    moved_truth = interpret(CSG, 2 * pts[:, 0] - 0.5, pts[:, 1], pts[:, 2] + 0.2)
    for expr, truth in ((slab, slab_truth), (moved, moved_truth)):
        np.testing.assert_allclose(implc.compile(expr).eval(pts), truth, rtol=1e-12, atol=1e-12)
    assert "disc_" in str(slab)
    voxels = implc.voxelize(implc.compile(slab), 5, storage="coords").to_dense()
    n = 32
    c = (np.arange(n) + 0.5) / n * 2 - 1
    gx, gy, gz = np.meshgrid(c, c, c, indexing="ij")
    inside = np.maximum(np.hypot(gx, gy) - 0.6, np.abs(gz) - 0.1) < -0.1  # deep inside: no voxel there
    assert voxels.any() and not (voxels & inside).any()
