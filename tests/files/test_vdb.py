""".vdb export: every file the tests write is read back with the reference library (OpenVDB's own Python
module, ``pyopenvdb``, from Debian's python3-openvdb, run in the system Python that has it) and compared
with the voxelization, with sampling by numpy, and with hand-built trees whose content is known."""

import json
import os
import shutil
import subprocess
import textwrap

import numpy as np
import pytest
import sympy
from sympy import Max, Rational, sqrt

import implc
from implc import x, y, z
from implc.cli.commands import main
from implc.files.scene import load as load_scene
from implc.files.vdb import describe_vdb, save_vdb
from implc.voxelizer.voxelize import Voxels

READ_BACK = textwrap.dedent("""
    import json, sys
    import numpy as np
    import pyopenvdb as vdb
    path, query = sys.argv[1], np.load(sys.argv[2])
    out = {}
    for grid in vdb.readAll(path)[0]:
        depths = {}
        for item in grid.citerOnValues():
            depths[str(item.depth)] = depths.get(str(item.depth), 0) + 1
        acc = grid.getConstAccessor()
        values = [[float(v) for v in np.ravel(acc.getValue(tuple(map(int, c))))] for c in query["cells"]]
        active = [bool(acc.isValueOn(tuple(map(int, c)))) for c in query["cells"]]
        entry = {"active_voxels": int(grid.activeVoxelCount()), "on_values_by_depth": depths,
                 "values": values, "active": active, "class": str(grid.gridClass),
                 "vector_type": str(grid.metadata.get("vector_type", "")),
                 "file_bbox": [list(grid.metadata["file_bbox_min"]), list(grid.metadata["file_bbox_max"])],
                 "active_bbox": [list(c) for c in grid.evalActiveVoxelBoundingBox()],
                 "world": [list(grid.transform.indexToWorld(tuple(map(float, c)))) for c in query["cells"][:8]]}
        n = int(query["dense"])
        if n:
            shape = (n, n, n) if grid.name == "occupancy" else (n, n, n, 3)
            dense = np.zeros(shape, np.float32)
            grid.copyToArray(dense, ijk=(0, 0, 0))
            np.save(sys.argv[2] + "." + grid.name + ".npy", dense)
        out[grid.name] = entry
    print(json.dumps(out))
""")


def _reference_python():
    """A Python that imports the reference library, or None."""
    for candidate in (os.environ.get("IMPLC_OPENVDB_PYTHON"), "/usr/bin/python3", shutil.which("python3")):
        if candidate and os.path.exists(candidate):
            probe = subprocess.run([candidate, "-c", "import pyopenvdb"], capture_output=True)
            if probe.returncode == 0:
                return candidate
    return None


@pytest.fixture(scope="module")
def reference():
    python = _reference_python()
    if python is None:
        pytest.skip("no Python here imports pyopenvdb (Debian: apt-get install python3-openvdb), so the .vdb files "
                    "cannot be read back with the reference library")

    def read_back(path, cells, dense=0):
        query = path.parent / (path.name + ".query.npz")
        np.savez(query, cells=np.asarray(cells, dtype=np.int64).reshape(-1, 3), dense=dense)
        done = subprocess.run([python, "-c", READ_BACK, str(path), str(query)], capture_output=True, text=True)
        assert done.returncode == 0, done.stderr
        result = json.loads(done.stdout)
        for name in result:
            if dense:
                result[name]["dense"] = np.load(str(query) + f".{name}.npy")
        return result
    return read_back


SPHERE = sqrt(x**2 + y**2 + z**2) - Rational(7, 10)
BOX_MINUS_BALL = Max(Max(abs(x), abs(y), abs(z)) - Rational(1, 2), -(sqrt(x**2 + y**2 + z**2) - Rational(3, 10)))


def _lower_tile_count(voxels) -> int:
    """How many 8³ tiles of lower internal nodes the inside octants of edge 8 to 64 make."""
    sizes = np.left_shift(1, voxels.depth - voxels.inside[:, 3].astype(np.int64))
    return int(sum((s // 8) ** 3 for s in sizes if 8 <= s < 128))


@pytest.mark.parametrize("expr,bounds", [(SPHERE, ((-1, 1), (-1, 1.5), (-2, 1))),
                                         (BOX_MINUS_BALL, ((-1, 1),) * 3)], ids=["sphere", "box minus ball"])
def test_solid_reads_back_as_the_voxelization(reference, tmp_path, expr, bounds):
    surface = implc.compile(expr, bounds=bounds)
    depth = 7
    voxels = implc.voxelize(surface, depth, solid=True)
    path = save_vdb(voxels, tmp_path / "solid.vdb")
    got = reference(path, voxels.coords, dense=1 << depth)
    occupancy, normals = got["occupancy"], got["normals"]
    solid, shell = voxels.to_dense(solid=True), voxels.to_dense()
    expected = np.where(shell, 0.5, np.where(solid, 1.0, 0.0))
    assert np.array_equal(occupancy["dense"], expected)
    assert occupancy["active_voxels"] == len(voxels) + voxels.inside_voxels()
    assert occupancy["on_values_by_depth"].get("2", 0) == _lower_tile_count(voxels) > 0  # inside 8³ blocks as tiles
    assert occupancy["class"] == "fog volume"
    assert occupancy["file_bbox"] == occupancy["active_bbox"]  # the metadata's box is the active voxels' box
    assert normals["file_bbox"] == normals["active_bbox"]
    # normals: exactly the voxels' float32 normals, nothing else active
    assert np.array_equal(np.array(normals["values"], dtype=np.float32), voxels.normals)
    assert normals["active_voxels"] == len(voxels) and normals["vector_type"] == "covariant normalize"
    # the transform puts voxel (i, j, k) at the centre of cell (i, j, k)
    assert np.allclose(occupancy["world"], voxels.centers()[:8], rtol=0, atol=1e-12)


def test_solid_holds_every_sampled_inside_point(reference, tmp_path):
    """Against sampling by numpy (lambdify): a point with F < 0 lies in an active voxel of the file, a point
    with F > 0 in an inactive one or a boundary voxel."""
    bounds = ((-1, 1),) * 3
    depth = 6
    voxels = implc.voxelize(implc.compile(BOX_MINUS_BALL, bounds=bounds), depth, solid=True)
    path = save_vdb(voxels, tmp_path / "s.vdb")
    points = np.random.default_rng(7).uniform(-1, 1, (4000, 3))
    f = sympy.lambdify((x, y, z), BOX_MINUS_BALL, "numpy")(*points.T)
    cells = np.clip(((points + 1) / 2 * (1 << depth)).astype(np.int64), 0, (1 << depth) - 1)
    got = reference(path, cells)["occupancy"]
    values, active = np.array(got["values"])[:, 0], np.array(got["active"])
    assert np.all(active[f < 0]) and np.all(values[f < 0] > 0)
    assert np.all((~active[f > 0]) | (values[f > 0] == 0.5))
    assert np.any(f < 0) and np.any(f > 0)


def test_tiles_at_every_level_of_the_tree(reference, tmp_path):
    """A hand-built solid at depth 13 (8192³): an octant of 4096³ (a root tile), one of 2048³ (16³ tiles of
    the upper internal nodes), one of 128³ (one such tile), one of 8³ (a lower tile), one of 2³ (eight leaf
    voxels), next to three boundary voxels."""
    depth = 13
    inside = np.array([[1, 0, 0, 1], [0, 2, 0, 2], [0, 0, 20, 6], [0, 0, 1, 10], [3, 3, 3, 12]], dtype=np.int32)
    coords = np.array([[0, 0, 0], [0, 0, 1], [9, 9, 9]], dtype=np.uint32)
    normals = np.array([[1, 0, 0], [0, 1, 0], [0, 0.6, 0.8]], dtype=np.float32)
    voxels = Voxels(coords, normals, depth, ((-1.0, 1.0),) * 3, stats=None, inside=inside)
    path = save_vdb(voxels, tmp_path / "tiles.vdb")
    probes = [[4096, 0, 0], [8191, 4095, 4095], [0, 4096, 0], [2047, 6143, 2047], [0, 0, 2560], [127, 127, 2687],
              [0, 0, 8], [7, 7, 15], [6, 6, 6], [7, 7, 7], [0, 0, 0], [9, 9, 9], [5, 5, 5], [0, 0, 2688], [8, 8, 8]]
    got = reference(path, probes)
    occupancy = got["occupancy"]
    expected_active = 4096**3 + 2048**3 + 128**3 + 8**3 + 2**3 + 3
    assert occupancy["active_voxels"] == expected_active
    assert occupancy["on_values_by_depth"] == {"0": 1, "1": 16**3 + 1, "2": 1, "3": 8 + 3}
    assert [v[0] for v in occupancy["values"]] == [1.0] * 10 + [0.5, 0.5, 0.0, 0.0, 0.0]
    assert occupancy["active"] == [True] * 12 + [False] * 3
    assert got["normals"]["active_voxels"] == 3
    assert got["normals"]["values"][10:12] == [[1, 0, 0], [0, pytest.approx(0.6), pytest.approx(0.8)]]


def test_a_shell_writes_its_boundary_voxels(reference, tmp_path):
    voxels = implc.voxelize(implc.compile(SPHERE, bounds=((-1, 1),) * 3), 6)
    got = reference(save_vdb(voxels, tmp_path / "shell.vdb"), voxels.coords[:50], dense=64)
    assert np.array_equal(got["occupancy"]["dense"] > 0, voxels.to_dense())
    assert set(np.unique(got["occupancy"]["dense"])) == {0.0, 0.5}
    assert np.array_equal(np.array(got["normals"]["values"], np.float32), voxels.normals[:50])


def test_cli_writes_vdb_and_info_describes_it(reference, tmp_path, capsys):
    out = tmp_path / "torus.vdb"
    assert main(["voxelize", "torus", "--depth", "6", "--solid", "--quiet", "-o", str(out)]) == 0
    scene = load_scene("torus")
    voxels = implc.voxelize(implc.compile(scene.surface, bounds=scene.bounds), 6, solid=True)
    got = reference(out, np.zeros((1, 3)))
    assert got["occupancy"]["active_voxels"] == len(voxels) + voxels.inside_voxels()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "OpenVDB format 224" in text
    assert "occupancy: Tree_float_5_4_3" in text and "normals: Tree_vec3s_5_4_3" in text


def test_describe_refuses_what_is_not_vdb(tmp_path):
    bad = tmp_path / "x.vdb"
    bad.write_bytes(b"not a vdb at all")
    with pytest.raises(ValueError, match="not an OpenVDB file"):
        describe_vdb(bad)
    assert main(["info", str(bad)]) == 2


def test_transform_of_a_non_cubic_box(tmp_path):
    """The written scale-and-translate map, read by describe_vdb: cell sizes and the centre of cell 0."""
    voxels = Voxels(np.zeros((1, 3), np.uint32), np.array([[0, 0, 1]], np.float32), 4,
                    ((-1.0, 1.0), (0.0, 4.0), (2.0, 2.5)), stats=None)
    text = "\n".join(describe_vdb(save_vdb(voxels, tmp_path / "t.vdb")))
    assert "ScaleTranslateMap: voxel size (0.125, 0.25, 0.03125)" in text
    assert f"centred at {(-1 + 0.0625, 0.125, 2 + 0.015625)}" in text
