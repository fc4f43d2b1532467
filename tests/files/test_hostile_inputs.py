"""Hostile inputs: forged, damaged and special files given to every reader, astronomic numbers, empty
option values. Each must end in one line and exit status 2 from the CLI (or a clear exception from the
API) within a few seconds, or in a correct result; nothing may hang, read without end, allocate what the
file merely claims, or print the file's control characters to the terminal.

The fuzz tests mutate small valid files (truncations, byte flips, forged header fields) with hypothesis
and hand them to the reader in-process: each run must give a valid result or the reader's own error."""

from __future__ import annotations

import io
import os
import struct
import subprocess
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import implc
from implc import shapes
from implc.cli.commands import main
from implc.common.untrusted import decimal, printable
from implc.compiler.vm import VmError, parse_vm
from implc.files import voxel_files
from implc.files.vdb import describe_vdb
from implc.meshing.triangle_mesh import MeshFileError
from implc.meshing.triangle_mesh import load as load_mesh

ROOT = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def solid():
    surface = implc.compile(shapes.sphere(0.7, (0, 0, 0)))
    return implc.voxelize(surface, 4, solid=True)


def one_line_error(capsys, argv) -> str:
    """Runs the CLI; asserts exit status 2 and exactly one line on stderr; returns it."""
    assert main([str(a) for a in argv]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and err.startswith("implc: error: "), err
    assert "\x1b" not in err
    return err


def run_cli(argv, timeout=30):
    """The CLI in a subprocess (where a hang is a timeout, not a stuck test run)."""
    return subprocess.run([sys.executable, "-m", "implc", *map(str, argv)], capture_output=True, text=True,
                          timeout=timeout, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)))


# -- numbers -----------------------------------------------------------------------------------------
@pytest.mark.parametrize("formula", ["y - exp(exp(exp(9)))", "y - exp(-exp(exp(9)))", "y + exp(exp(exp(exp(3))))",
                                     "y - sinh(sinh(sinh(sinh(9))))", "x - exp(exp(exp(exp(10))))"])
def test_astronomic_constants_compile_at_once(formula):
    """A constant far beyond the doubles' range is an infinite bound on its side (no exact power of two
    with 10^3500 digits is built): the subprocess ends within its timeout."""
    out = run_cli(["voxelize", "--expr", formula, "--depth", "3", "-o", "/dev/null/x.npz"], timeout=60)
    assert out.returncode == 2 and out.stderr.count("\n") == 1  # the output's folder does not exist, said last
    assert "does not exist" in out.stderr


def test_a_constant_too_large_to_evaluate_is_built_from_its_parts():
    """sinh(sinh(sinh(sinh(9)))) is beyond SymPy's certified evaluation: the lowering builds it as sinh of
    an evaluated constant, whose enclosure is [largest double, inf]; F = y - that is negative everywhere."""
    from sympy import sinh
    surface = implc.compile(implc.y - sinh(sinh(sinh(sinh(9)))))
    lo, hi = surface.interval(np.full((1, 3), -1.0), np.full((1, 3), 1.0))
    assert hi[0] < 0 or not np.isfinite(hi[0])
    assert surface.eval(np.zeros((1, 3)))[0] < 0


def test_astronomic_constant_bounds():
    from sympy import exp

    from implc.compiler.lower import number_bounds
    nearest, lo, hi = number_bounds(exp(exp(exp(9))))
    assert lo == sys.float_info.max and hi == float("inf")
    nearest, lo, hi = number_bounds(exp(-exp(exp(9))))  # within the evaluation's own error of 1e-300
    assert lo <= 0.0 < hi <= 1e-299


@pytest.mark.parametrize("text, lo, hi", [("1e999999999", sys.float_info.max, float("inf")),
                                          ("-1e999999999", -float("inf"), -sys.float_info.max),
                                          ("1e-999999999", 0.0, 5e-324), ("0.1", 0.09999999999999999, 0.1)])
def test_vm_constants_of_any_exponent(text, lo, hi):
    model = parse_vm(f"x var-x\nc const {text}\nout sub x c\n")
    attr = [attr for op, _, attr in model.tape.nodes if op == "const"][0]
    assert (attr[1], attr[2]) == (lo, hi)


def test_decimal_is_exact_and_bounded():
    from fractions import Fraction
    assert decimal("-1.25e-2") == Fraction(-1, 80) and decimal(".5") == Fraction(1, 2) and decimal("7.") == 7
    for bad in ("", "1e", "e5", "1.2.3", "0x10", "nan", "inf", "1" * 1001):
        with pytest.raises(ValueError):
            decimal(bad)


def test_vm_header_scale_out_of_range(tmp_path):
    with pytest.raises(VmError, match="--scale"):
        parse_vm("# --scale 1e-320\nx var-x\nout neg x\n")
    with pytest.raises(VmError, match="--scale"):
        parse_vm("# --scale 0\nx var-x\nout neg x\n")


# -- special files -----------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".vm", ".npz", ".ply", ".vdb", ".stl", ".npy"])
def test_special_files_are_refused(tmp_path, capsys, suffix):
    fifo = tmp_path / f"fifo{suffix}"
    os.mkfifo(fifo)
    assert "FIFO" in one_line_error(capsys, ["info", fifo])
    zero = tmp_path / f"zero{suffix}"
    zero.symlink_to("/dev/zero")
    assert "device" in one_line_error(capsys, ["info", zero])
    folder = tmp_path / f"folder{suffix}"
    folder.mkdir()
    assert "folder" in one_line_error(capsys, ["info", folder])


def test_a_fifo_scene_does_not_block(tmp_path):
    fifo = tmp_path / "m.vm"
    os.mkfifo(fifo)
    out = run_cli(["voxelize", fifo, "--depth", "3", "-o", tmp_path / "v.npz"])
    assert out.returncode == 2 and "FIFO" in out.stderr


# -- forged voxel files ------------------------------------------------------------------------------
def forged_npz(path, solid, **changes):
    arrays = dict(implc_voxels=1, coords=solid.coords, normals=solid.normals, depth=solid.depth,
                  bounds=np.asarray(solid.bounds, dtype=np.float64), inside=solid.inside)
    arrays.update(changes)
    np.savez(path, **arrays)
    return path


def test_forged_inside_octants(tmp_path, solid, capsys):
    inside = solid.inside.astype(np.uint64)
    wrapped = inside.copy()
    wrapped[0, 0] = np.uint64(2**63)  # wraps to a negative int64, then past a range check done after a cast
    assert "outside the grid" in one_line_error(capsys, ["info", forged_npz(tmp_path / "a.npz", solid,
                                                                            inside=wrapped)])
    repeated = np.repeat(solid.inside[:1], 1000, axis=0)
    assert "overlap" in one_line_error(capsys, ["info", forged_npz(tmp_path / "b.npz", solid, inside=repeated)])
    parent = solid.inside[:1].copy()
    parent[0, :3] //= 2
    parent[0, 3] -= 1  # its parent octant: holds it
    overlapping = np.concatenate([solid.inside, parent])
    assert "overlap" in one_line_error(capsys, ["info", forged_npz(tmp_path / "c.npz", solid, inside=overlapping)])
    whole = np.array([[0, 0, 0, 1]], np.int32)  # an octant of the grid holding boundary voxels
    assert "boundary voxels" in one_line_error(capsys, ["info", forged_npz(tmp_path / "d.npz", solid,
                                                                           inside=whole)])


@pytest.mark.parametrize("bounds", [[[-1e308, 1e308]] * 3, [[0, 1e-320]] * 3, [[0, np.inf]] * 3])
def test_bounds_without_a_usable_cell_size(tmp_path, solid, capsys, bounds):
    err = one_line_error(capsys, ["info", forged_npz(tmp_path / "v.npz", solid, bounds=np.array(bounds, float))])
    assert "bounds" in err


def test_npz_member_that_is_not_an_array(tmp_path, solid, capsys):
    path = forged_npz(tmp_path / "v.npz", solid)
    with zipfile.ZipFile(path, "a") as z:
        z.writestr("coords", b"not an array")  # np.load gives bytes for a member without .npy
    with zipfile.ZipFile(path) as z:
        names = [n for n in z.namelist() if n != "coords.npy"]
        members = {n: z.read(n) for n in names}
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    assert "not an array" in one_line_error(capsys, ["info", path])


def test_npz_member_whose_header_does_not_parse(tmp_path, solid, capsys):
    """A .npy header with a bracket left open: numpy's header parser raises tokenize's TokenError (not a
    ValueError); the fuzzing of the .npz reader found it."""
    path = forged_npz(tmp_path / "v.npz", solid)
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    members["bounds.npy"] = members["bounds.npy"].replace(b"'shape': (3, 2)", b"'shape': ((3, 2", 1)
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    with pytest.raises(voxel_files.VoxelFileError, match="damaged"):
        voxel_files.load_npz(path)
    assert "damaged" in one_line_error(capsys, ["info", path])


def test_zip_bomb_is_refused_before_it_inflates(tmp_path, solid, capsys):
    path = tmp_path / "bomb.npz"
    buffer = io.BytesIO()
    # 96 MiB of zeros deflate to about 100 KiB: past the 64 MiB that any member may take and 200× its stored
    # size (voxel_files.MAX_RATIO); 768 MiB took 6 s of the suite to deflate and tested nothing more
    np.save(buffer, np.zeros((96 << 20,), np.uint8))
    with zipfile.ZipFile(path, "w", zipfile.ZIP_DEFLATED) as z:
        version = io.BytesIO()
        np.save(version, np.asarray(1))
        z.writestr("implc_voxels.npy", version.getvalue())
        z.writestr("coords.npy", buffer.getvalue())
    assert path.stat().st_size < 4 << 20
    assert "zip bomb" in one_line_error(capsys, ["info", path])


def test_npz_member_claiming_more_than_it_holds(tmp_path, solid, capsys):
    path = forged_npz(tmp_path / "v.npz", solid)
    with zipfile.ZipFile(path) as z:
        members = {n: z.read(n) for n in z.namelist()}
    header = members["coords.npy"]
    shape = f"({len(solid)}, 3)".encode()
    members["coords.npy"] = header.replace(shape, b"(100000000000000, 3)".ljust(len(shape)) if len(shape) > 20
                                           else b"(10000000000000, 3)", 1)
    with zipfile.ZipFile(path, "w") as z:
        for n, data in members.items():
            z.writestr(n, data)
    err = one_line_error(capsys, ["info", path])
    assert str(path) in err and "Unable to allocate" not in err


def test_malformed_npy_header(tmp_path, capsys):
    path = tmp_path / "g.npy"
    path.write_bytes(b"\x93NUMPY\x01\x00\x10\x00{'descr': ..., }\n" + b"\0" * 64)
    assert ".npy" in one_line_error(capsys, ["info", path])


@pytest.mark.parametrize("count", ["1000000000000000000000", "-5", "12abc", "3"])
def test_forged_ply_counts(tmp_path, solid, capsys, count):
    voxel_files.save(solid, tmp_path / "v.ply")
    data = (tmp_path / "v.ply").read_bytes()
    head, body = data.split(b"end_header\n", 1)
    head = head.replace(f"element vertex {len(solid)}".encode(), f"element vertex {count}".encode())
    (tmp_path / "f.ply").write_bytes(head + b"end_header\n" + body)
    assert "PLY" in one_line_error(capsys, ["info", tmp_path / "f.ply"])
    (tmp_path / "t.ply").write_bytes(data[: len(data) - 5])  # truncated body
    assert "PLY" in one_line_error(capsys, ["info", tmp_path / "t.ply"])


def test_forged_mesh_ply_counts(tmp_path):
    path = tmp_path / "m.ply"
    path.write_bytes(b"ply\nformat binary_little_endian 1.0\nelement vertex 1000000000000000000\nproperty float x\n"
                     b"property float y\nproperty float z\nelement face 1\nproperty list uchar int vertex_indices\n"
                     b"end_header\n" + b"\0" * 100)
    with pytest.raises(MeshFileError, match="damaged PLY"):
        load_mesh(path)


def test_a_mesh_file_with_one_coordinate_per_vertex_is_refused(tmp_path, capsys):
    """A damaged OBJ whose vertex lines lost two numbers (the fuzzing below found it) is no mesh in three
    dimensions."""
    path = tmp_path / "m.obj"
    path.write_text("v 1\nv 2\nv 3\nf 1 2 3\n")
    with pytest.raises(MeshFileError, match="without three coordinates"):
        load_mesh(path)
    assert "without three coordinates" in one_line_error(capsys, ["info", path])


def _vdb(tmp_path, solid) -> bytes:
    voxel_files.save(solid, tmp_path / "v.vdb")
    return (tmp_path / "v.vdb").read_bytes()


def test_forged_vdb_grid_count_and_offsets(tmp_path, solid, capsys):
    data = bytearray(_vdb(tmp_path, solid))
    text = describe_vdb(tmp_path / "v.vdb")
    assert any("occupancy" in line for line in text)
    # the grid count follows the file metadata: find it as the int32 before the first grid's name
    name = data.index(b"occupancy")
    count_at = name - 4 - 4
    assert struct.unpack_from("<i", data, count_at)[0] == 2
    struct.pack_into("<i", data, count_at, 2**31 - 1)
    (tmp_path / "count.vdb").write_bytes(bytes(data))
    assert "grid count" in one_line_error(capsys, ["info", tmp_path / "count.vdb"])
    data = bytearray(_vdb(tmp_path, solid))
    offsets_at = name + len(b"occupancy") + 4 + len(b"Tree_float_5_4_3") + 4  # after name, type, parent ""
    struct.pack_into("<q", data, offsets_at + 16, count_at)  # the end offset points back at the count
    (tmp_path / "back.vdb").write_bytes(bytes(data))
    assert "offsets" in one_line_error(capsys, ["info", tmp_path / "back.vdb"])


@pytest.mark.parametrize("type_name, size", [("int64", 3), ("int32", 7), ("vec3i", 4), ("bool", 0), ("double", 2)])
def test_vdb_metadata_of_the_wrong_length(tmp_path, capsys, type_name, size):
    from implc.files.vdb import MAGIC
    meta = struct.pack("<I", 1) + struct.pack("<I", 3) + b"bad" + struct.pack("<I", len(type_name))
    meta += type_name.encode() + struct.pack("<I", size) + b"\1" * size
    data = struct.pack("<qIII?", MAGIC, 224, 10, 0, True) + b"0" * 36 + meta + struct.pack("<i", 0)
    (tmp_path / "m.vdb").write_bytes(data)
    assert "has" in one_line_error(capsys, ["info", tmp_path / "m.vdb"])


def test_escape_sequences_are_not_printed(tmp_path, capsys):
    from implc.files.vdb import MAGIC
    creator = b"\x1b[2J\x1b[31mforged\nline"
    meta = struct.pack("<I", 1) + struct.pack("<I", 7) + b"creator" + struct.pack("<I", 6) + b"string"
    meta += struct.pack("<I", len(creator)) + creator
    data = struct.pack("<qIII?", MAGIC, 224, 10, 0, True) + b"0" * 36 + meta + struct.pack("<i", 0)
    (tmp_path / "e.vdb").write_bytes(data)
    assert main(["info", str(tmp_path / "e.vdb")]) == 0
    out = capsys.readouterr().out
    assert "\x1b" not in out and out.count("\n") == 1 and "\\x1b[2J" in out
    assert printable("a\x1bb\u202ec\\") == "a\\x1bb\\u202ec\\\\"


def test_zarr_attributes_are_checked(tmp_path, capsys):
    import zarr
    surface = implc.compile(shapes.sphere(0.7, (0, 0, 0)))
    from implc.files.zarr_writer import write_zarr
    write_zarr(surface, 4, tmp_path / "v.zarr")
    group = zarr.open_group(str(tmp_path / "v.zarr"), mode="r+")
    written = dict(group.attrs["implc"])
    for about in ({"depth": 7, "bounds": [[-1, 1]] * 3, "solid": True}, {"depth": 4, "bounds": "[-1, 1]",
                                                                          "solid": True},
                  {"depth": None, "bounds": [[-1, 1]] * 3, "solid": True},
                  {"depth": 4, "bounds": [[-1, 1]] * 3, "solid": "yes"},
                  {"manifest": dict(written["manifest"], voxels="many")},
                  {"manifest": dict(written["manifest"], bricks=-1)}):
        group.attrs["implc"] = dict(written, **about)
        assert "damaged implc Zarr store" in one_line_error(capsys, ["info", tmp_path / "v.zarr"])


# -- fuzzing each reader -----------------------------------------------------------------------------
FUZZ = settings(max_examples=40, deadline=5000, suppress_health_check=[HealthCheck.function_scoped_fixture,
                                                                         HealthCheck.too_slow])


def mutations():
    """(truncate at, [(offset, byte)]) as fractions of the file, so one strategy serves every file."""
    return st.tuples(st.one_of(st.none(), st.floats(0, 1)),
                     st.lists(st.tuples(st.floats(0, 1, exclude_max=True), st.integers(0, 255)), max_size=6))


def mutated(data: bytes, mutation) -> bytes:
    cut, flips = mutation
    out = bytearray(data if cut is None else data[: int(cut * len(data))])
    for where, byte in flips:
        if out:
            out[int(where * len(out))] = byte
    return bytes(out)


@pytest.fixture(scope="module")
def samples(tmp_path_factory, solid):
    folder = tmp_path_factory.mktemp("samples")
    files = {}
    for suffix in (".npz", ".ply", ".npy", ".vdb"):
        voxel_files.save(solid, folder / f"v{suffix}")
        files[suffix] = (folder / f"v{suffix}").read_bytes()
    mesh = implc.mesh(implc.compile(shapes.sphere(0.7, (0, 0, 0))), 3)
    for suffix in (".ply", ".stl", ".obj", ".glb", ".3mf"):
        mesh.save(folder / f"m{suffix}")
        files["mesh" + suffix] = (folder / f"m{suffix}").read_bytes()
    return files


@pytest.mark.parametrize("kind", [".npz", ".ply", ".npy", ".vdb"])
@FUZZ
@given(mutation=mutations())
def test_fuzz_voxel_readers(tmp_path, samples, kind, mutation):
    path = tmp_path / f"f{kind}"
    path.write_bytes(mutated(samples[kind], mutation))
    try:
        lines = voxel_files.describe(path)
        assert all("\x1b" not in line for line in lines)
        if kind == ".npz":
            voxel_files.load_npz(path)
    except voxel_files.VoxelFileError:
        pass


@pytest.mark.parametrize("kind", ["mesh.ply", "mesh.stl", "mesh.obj", "mesh.glb", "mesh.3mf"])
@FUZZ
@given(mutation=mutations())
def test_fuzz_mesh_reader(tmp_path, samples, kind, mutation):
    path = tmp_path / f"f.{kind.split('.')[1]}"
    path.write_bytes(mutated(samples[kind], mutation))
    try:
        mesh = load_mesh(path)
        assert mesh.vertices.ndim == 2 and mesh.faces.ndim == 2
    except MeshFileError:
        pass


ATOMS = ["x", "y", "z", "r", "theta", "phi", "pi", "E", "0", "1", "2", "0.5", "-0.0", "(-1)", "1e-320", "1e20",
         "1e300", "1e308", "pi/2"]
CALLS = ["sin", "cos", "tan", "asin", "acos", "atan", "sinh", "cosh", "tanh", "exp", "log", "sqrt", "cbrt", "abs"]


def formulas():
    """Random formulas in --expr's language: numbers at the edges of the doubles, every function."""
    leaves = st.sampled_from(ATOMS)

    def extend(inner):
        return st.one_of(st.tuples(inner, st.sampled_from(["+", "-", "*", "/", "**"]), inner).map(
                             lambda t: f"({t[0]} {t[1]} {t[2]})"),
                         st.tuples(st.sampled_from(CALLS), inner).map(lambda t: f"{t[0]}({t[1]})"),
                         st.tuples(st.sampled_from(["atan2", "min", "max"]), inner, inner).map(
                             lambda t: f"{t[0]}({t[1]}, {t[2]})"))
    return st.recursive(leaves, extend, max_leaves=12)


@pytest.mark.slow
@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(text=formulas())
def test_fuzz_expr_formulas(text):
    """Every formula parses, compiles and voxelizes, or is refused with ExprError or CompileError (the
    CLI's one line), never another exception (SymPy evaluates numbers as it builds: fuzzing of this kind
    found cosh of a huge number running for minutes, 0.5 / 0.0, SymPy's own AttributeError and a non-real
    exponent; each is a case of test_cli_errors' table now)."""
    from implc.compiler.expr import ExprError, parse
    try:
        implc.voxelize(implc.compile(parse(text)), 3)
    except (ExprError, implc.CompileError):
        pass


VM = ("# --scale 0.8\nx var-x\ny var-y\nz var-z\nc const 0.25\nxx square x\nyy square y\ns add xx yy\n"
      "d sub s c\nout max d z\n")


@FUZZ
@given(mutation=mutations())
def test_fuzz_vm_reader(mutation):
    text = mutated(VM.encode(), mutation).decode("latin-1")
    try:
        model = parse_vm(text)
        implc.compile(model)
    except VmError:
        pass


# -- options, messages, exit status, permissions -------------------------------------------------------
@pytest.mark.parametrize("argv, words", [
    (["view", "torus", "--export", ""], "--export is empty"),
    (["voxelize", "torus", "--bounds", "", "-o", "{d}/v.npz"], "--bounds is empty"),
    (["voxelize", "torus", "-o", ""], "--output is empty"),
    (["render", "torus", "--view", " ", "-o", "{d}/v.png"], "--view is empty"),
    (["render", "torus", "--size", "16384", "-o", "{d}/v.png"], "--size must be an integer from 16 to 8192"),
    (["render", "torus", "--cut", "z=0=0", "-o", "{d}/v.png"], "--cut must be a number"),
    (["view", "torus", "--export", "{d}/file.txt"], "cannot write a static viewer to"),
])
def test_options_are_named_and_empty_values_refused(tmp_path, capsys, argv, words):
    (tmp_path / "file.txt").write_text("x")
    err = one_line_error(capsys, [a.replace("{d}", str(tmp_path)) for a in argv])
    assert words in err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["file.txt"]


def test_render_size_beyond_memory_is_refused_with_the_estimate(tmp_path, capsys, monkeypatch):
    import implc.voxelizer.voxelize
    monkeypatch.setattr(implc.voxelizer.voxelize, "available_memory", lambda: 1 << 30)
    err = one_line_error(capsys, ["render", "torus", "--size", "4096", "-o", tmp_path / "v.png"])
    assert "--size 4096 needs about 1.6 GiB" in err


def test_a_full_disk_names_the_output(tmp_path, capsys, monkeypatch):
    def full(*args, **kwargs):
        raise OSError(28, "No space left on device")
    monkeypatch.setattr(np, "savez", full)
    err = one_line_error(capsys, ["voxelize", "torus", "--depth", "4", "-o", tmp_path / "v.npz", "--quiet"])
    assert f"{tmp_path / 'v.npz'}: No space left on device" in err
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("late", [True, False])
def test_a_signal_after_the_output_is_in_place_is_not_a_failure(tmp_path, capsys, monkeypatch, late):
    """Ctrl-C that arrives once the output replaced the old one: exit 0, the output complete; one that
    arrives before: exit 130 and the old file untouched."""
    import implc.common.atomic_file as atomic_file
    target = tmp_path / "v.npz"
    target.write_bytes(b"old")
    real = atomic_file._put_in_place

    def put_then_interrupt(tmp, path):
        if not late:
            raise KeyboardInterrupt
        real(tmp, path)
        raise KeyboardInterrupt

    monkeypatch.setattr(atomic_file, "_put_in_place", put_then_interrupt)
    status = main(["voxelize", "torus", "--depth", "4", "-o", str(target), "--quiet"])
    err = capsys.readouterr().err
    if late:
        assert status == 0 and "written in full" in err and len(voxel_files.load_npz(target)) > 0
    else:
        assert status == 130 and "interrupted" in err and target.read_bytes() == b"old"
    assert sorted(p.name for p in tmp_path.iterdir()) == ["v.npz"]


def test_outputs_get_the_umask_or_keep_the_old_mode(tmp_path):
    old = os.umask(0o022)
    try:
        assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "v.npz"), "--quiet"]) == 0
        assert (tmp_path / "v.npz").stat().st_mode & 0o777 == 0o644
        os.chmod(tmp_path / "v.npz", 0o640)
        assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "v.npz"), "--quiet"]) == 0
        assert (tmp_path / "v.npz").stat().st_mode & 0o777 == 0o640
        assert main(["voxelize", "torus", "--depth", "4", "-o", str(tmp_path / "v.zarr"), "--quiet"]) == 0
        assert (tmp_path / "v.zarr").stat().st_mode & 0o777 == 0o755
        os.umask(0o077)
        assert main(["mesh", "torus", "--depth", "4", "-o", str(tmp_path / "m.stl"), "--quiet"]) == 0
        assert (tmp_path / "m.stl").stat().st_mode & 0o777 == 0o600
    finally:
        os.umask(old)


@FUZZ
@given(mutation=mutations())
def test_fuzz_zarr_reader(tmp_path_factory, mutation):
    """The store's metadata (zarr.json: shape, chunks, shards, the implc attributes) mutated: implc info
    describes a valid store or says in one line what is wrong."""
    from implc.files.zarr_store import describe_zarr
    from implc.files.zarr_writer import write_zarr
    folder = tmp_path_factory.mktemp("z")
    write_zarr(implc.compile(shapes.sphere(0.7, (0, 0, 0))), 3, folder / "v.zarr", solid=False)
    meta = folder / "v.zarr" / "zarr.json"
    meta.write_bytes(mutated(meta.read_bytes(), mutation))
    try:
        lines = describe_zarr(folder / "v.zarr")
        assert all("\x1b" not in line and "\n" not in line for line in lines)
    except ValueError:
        pass
