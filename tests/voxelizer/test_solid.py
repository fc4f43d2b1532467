"""Solids (``voxelize(..., solid=True)``): inside octants against sampling by numpy (lambdify, not implc's
compiler), guaranteed volume bounds against analytic volumes, both engines, files and the CLI."""

import math

import numpy as np
import pytest
import sympy
from sympy import Max, Min, Rational, cos, sin, sqrt

import implc
from implc import phi, r, shapes, theta, x, y, z
from implc.cli.commands import main
from implc.compiler.symbols import cartesian_form
from implc.engines import morton
from implc.engines.walk import Buffers, buffers
from implc.voxelizer import voxelize

from ..support.models import smooth_blend

SPHERE = sqrt(x**2 + y**2 + z**2) - Rational(7, 10)
TORUS = shapes.torus(Rational(3, 5), Rational(1, 4))
BOX = Max(abs(x), abs(y), abs(z)) - Rational(1, 2)
HOLLOW = Max(BOX, -(sqrt(x**2 + y**2 + z**2) - Rational(3, 10)))  # a box minus a ball inside it
SURFACES = {
    "sphere": (SPHERE, 4 / 3 * math.pi * 0.7**3),
    "torus": (TORUS, 2 * math.pi**2 * 0.6 * 0.25**2),
    "box": (BOX, 1.0),
    "box minus ball": (HOLLOW, 1.0 - 4 / 3 * math.pi * 0.3**3),
    "spherical": (r - Rational(3, 5) - Rational(1, 10) * cos(3 * phi) * sin(theta), None),
    "csg on the tape engine": (Min(HOLLOW, sqrt((x - Rational(3, 4))**2 + y**2 + z**2) - Rational(1, 5)), None),
    "smooth blend on the tape engine": (smooth_blend(), None),  # the engine's second look proves leaves inside
}


def inside_mask(voxels) -> np.ndarray:
    """The cells covered by inside octants only."""
    n = 1 << voxels.depth
    grid = np.zeros((n,) * 3, bool)
    for i, j, k, level in voxels.inside:
        size = 1 << (voxels.depth - int(level))
        grid[i * size:(i + 1) * size, j * size:(j + 1) * size, k * size:(k + 1) * size] = True
    return grid


@pytest.mark.parametrize("name", sorted(SURFACES))
def test_inside_and_outside_agree_with_sampling(name):
    expr, _ = SURFACES[name]
    s = implc.compile(expr, engine="tape" if name == "smooth blend on the tape engine" else "auto")
    if name.endswith("on the tape engine"):
        assert s.engine == "tape"
    depth = 6
    v = implc.voxelize(s, depth, solid=True)
    inside, solid = inside_mask(v), v.to_dense(solid=True)
    assert not (inside & v.to_dense()).any(), "an inside octant and a boundary voxel overlap"
    pts = np.random.default_rng(len(name)).uniform(-1, 1, (40000, 3))
    f = sympy.lambdify((x, y, z), cartesian_form(expr), "numpy")(*pts.T)
    cells = np.minimum(((pts + 1) / 2 * (1 << depth)).astype(int), (1 << depth) - 1)
    at = tuple(cells.T)
    assert (f < 0).sum() > 1000 and (f > 0).sum() > 1000
    assert solid[at][f < 0].all(), "a point with F < 0 outside the solid"
    assert not inside[at][f > 0].any(), "a point with F > 0 in an inside octant"
    assert inside.sum() > 0.2 * solid.sum()  # and the inside is mostly classified whole


@pytest.mark.parametrize("name", ["sphere", "torus", "box", "box minus ball"])
def test_volume_bounds_contain_the_exact_volume_and_tighten(name):
    expr, exact = SURFACES[name]
    s = implc.compile(expr)
    widths = []
    for depth in (5, 6, 7):
        lo, hi = implc.voxelize(s, depth, solid=True).volume_bounds()
        assert lo <= exact <= hi, (depth, lo, exact, hi)
        widths.append(hi - lo)
    for coarse, fine in zip(widths, widths[1:]):
        assert 0.35 < fine / coarse < 0.65, widths  # the boundary shell halves in volume per level


def test_solid_changes_no_voxel_and_workers_agree():
    s = implc.compile(TORUS)
    shell = implc.voxelize(s, 7)
    one, three = implc.voxelize(s, 7, solid=True, workers=1), implc.voxelize(s, 7, solid=True, workers=3)
    np.testing.assert_array_equal(shell.coords, one.coords)
    np.testing.assert_array_equal(shell.normals, one.normals)
    np.testing.assert_array_equal(one.inside, three.inside)
    assert shell.inside is None
    with pytest.raises(ValueError, match="solid=True"):
        shell.volume_bounds()


@pytest.mark.parametrize("engine", ["jit", "tape"])
def test_a_task_resumes_when_its_inside_output_is_full(engine):
    s = implc.compile(Max(SPHERE, -(sqrt(x**2 + y**2) - Rational(1, 5))), engine=engine)
    expected = implc.voxelize(s, 7, solid=True, workers=2)
    with buffers(Buffers(output_chunk=16)):
        chunked = implc.voxelize(s, 7, solid=True, workers=2)
    np.testing.assert_array_equal(chunked.inside, expected.inside)
    np.testing.assert_array_equal(chunked.coords, expected.coords)


def test_both_engines_classify_alike():
    a = implc.voxelize(implc.compile(HOLLOW, engine="jit"), 6, solid=True)
    b = implc.voxelize(implc.compile(HOLLOW, engine="tape"), 6, solid=True)
    np.testing.assert_array_equal(a.inside, b.inside)
    assert a.volume_bounds() == b.volume_bounds()


def test_a_solid_saves_loads_and_is_described(tmp_path, capsys):
    out = tmp_path / "torus.npz"
    assert main(["voxelize", "torus", "--depth", "6", "--solid", "-o", str(out)]) == 0
    assert "inside octants, volume in [" in capsys.readouterr().out
    from implc.files import voxel_files
    loaded = voxel_files.load_npz(out)
    direct = implc.voxelize(implc.compile(TORUS), 6, solid=True)
    np.testing.assert_array_equal(loaded.inside, direct.inside)
    assert loaded.volume_bounds() == direct.volume_bounds()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    lo, hi = direct.volume_bounds()
    assert f"volume   [{lo!r}, {hi!r}]" in text and "inside   " in text


@pytest.mark.parametrize("fmt", ["png", "tiff"])
def test_slices_are_the_dense_solid_layer_by_layer(tmp_path, fmt):
    from PIL import Image

    from implc.files.slices import save_slices
    v = implc.voxelize(implc.compile(HOLLOW), 5, solid=True)
    dense = v.to_dense(solid=True)
    folder = save_slices(v, tmp_path / "layers", fmt)
    files = sorted(folder.iterdir())
    assert len(files) == 32 and all(f.suffix == (".png" if fmt == "png" else ".tif") for f in files)
    for layer, path in enumerate(files):
        with Image.open(path) as image:
            assert image.mode == "1" and image.size == (32, 32)
            pixels = np.array(image, dtype=bool)
        np.testing.assert_array_equal(pixels, np.flipud(dense[:, :, layer].T), err_msg=str(path))
    save_slices(implc.voxelize(implc.compile(SPHERE), 5, solid=True), folder, fmt)  # replaces it whole
    assert len(list(folder.iterdir())) == 32
    assert sorted(p.name for p in tmp_path.iterdir()) == ["layers"], "a temporary folder was left"


def test_the_cli_writes_slices_and_names_a_bad_target(tmp_path, capsys):
    assert main(["voxelize", "torus", "--depth", "5", "--solid", "--slices", "png", "--quiet",
                 "-o", str(tmp_path / "torus")]) == 0
    assert len(list((tmp_path / "torus").glob("layer_*.png"))) == 32
    (tmp_path / "file").write_text("x")
    assert main(["voxelize", "torus", "--depth", "5", "--slices", "png", "-o", str(tmp_path / "file")]) == 2
    assert "is a file" in capsys.readouterr().err


def test_zarr_holds_the_dense_solid_and_the_cli_writes_it(tmp_path, capsys):
    import zarr

    from implc.files import voxel_files
    v = implc.voxelize(implc.compile(HOLLOW), 6, solid=True)
    path = voxel_files.save(v, tmp_path / "hollow.zarr")
    group = zarr.open_group(path, mode="r")
    array = group["occupancy"]
    assert array.shape == (64, 64, 64) and array.dtype == bool and array.metadata.zarr_format == 3
    np.testing.assert_array_equal(array[:], v.to_dense(solid=True))
    assert group.attrs["implc"]["depth"] == 6 and group.attrs["implc"]["solid"] is True
    shell = implc.voxelize(implc.compile(HOLLOW), 6)
    voxel_files.save(shell, path)  # replaces the store whole
    np.testing.assert_array_equal(zarr.open_group(path, mode="r")["occupancy"][:], shell.to_dense())
    assert sorted(p.name for p in tmp_path.iterdir()) == ["hollow.zarr"], "a temporary folder was left"
    out = tmp_path / "torus.zarr"
    assert main(["voxelize", "torus", "--depth", "9", "--solid", "--quiet", "-o", str(out)]) == 0
    big = zarr.open_group(out, mode="r")["occupancy"]
    direct = implc.voxelize(implc.compile(TORUS), 9, solid=True)
    layer = np.zeros((512, 512), bool)  # layer i = 200 of the dense solid, from the voxels and octants
    cells = direct.coords[direct.coords[:, 0] == 200]
    layer[cells[:, 1], cells[:, 2]] = True
    for i, j, k, level in direct.inside:
        size = 1 << (9 - int(level))
        if i * size <= 200 < (i + 1) * size:
            layer[j * size:(j + 1) * size, k * size:(k + 1) * size] = True
    np.testing.assert_array_equal(big[200], layer)
    capsys.readouterr()
    assert main(["info", str(out)]) == 0
    text = capsys.readouterr().out
    assert "occupancy bool 512x512x512" in text and "depth 9" in text and "the solid" in text
    (tmp_path / "other.zarr").mkdir()
    assert main(["info", str(tmp_path / "other.zarr")]) == 2
    assert "cannot read" in capsys.readouterr().err


@pytest.mark.parametrize("shard,chunk", [pytest.param(8, 4, marks=pytest.mark.slow),
                                         pytest.param(16, 8, marks=pytest.mark.slow), (64, 32)],
                         ids=["shards below octants", "shards below tasks", "shards above tasks"])  # small: slow
@pytest.mark.parametrize("solid", [True, False], ids=["solid", "shell"])
def test_zarr_written_while_voxelizing_is_the_dense_voxelization(tmp_path, shard, chunk, solid):
    """write_zarr streams each task's voxels and octants into shards as tasks finish: whatever the shard size
    against the tasks' cells (32³ here) and the octants, and for every worker count, the store is the
    in-memory voxelization's dense occupancy, and so are the counts and volume bounds it reports."""
    import zarr

    from implc.files import zarr_store, zarr_writer
    surface = implc.compile(HOLLOW)
    v = implc.voxelize(surface, 7, solid=solid)
    dense = v.to_dense(solid=solid)
    for workers in (1, 2):
        out = tmp_path / f"w{workers}.zarr"
        with zarr_store.sizes(zarr_store.Sizes(shard=shard, chunk=chunk)):
            result = zarr_writer.write_zarr(surface, 7, out, solid=solid, workers=workers)
        array = zarr.open_group(out, mode="r")["occupancy"]
        assert array.shards == (shard,) * 3
        np.testing.assert_array_equal(array[:], dense)
        assert result.voxels == len(v)
        if solid:
            assert (result.inside_octants, result.inside_voxels) == (len(v.inside), v.inside_voxels())
            assert result.volume_bounds() == v.volume_bounds()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["w1.zarr", "w2.zarr"]


def test_a_cross_section_is_the_dense_solid_layer():
    from implc.view.render import cross_section
    v = implc.voxelize(implc.compile(TORUS), 6, solid=True)
    dense = v.to_dense(solid=True)
    for axis, index in ((2, 32), (0, 20), (1, 45)):
        cells = cross_section(v, axis, index)
        got = np.zeros_like(dense)
        got[cells[:, 0], cells[:, 1], cells[:, 2]] = True
        expected = np.zeros_like(dense)
        layer = [slice(None)] * 3
        layer[axis] = index
        expected[tuple(layer)] = dense[tuple(layer)]
        np.testing.assert_array_equal(got, expected)


def test_a_cut_away_shows_the_filled_section_of_a_solid():
    """A ball cut at z = 0 seen from above: the solid's section is one flat disk (one colour at the
    centre), the shell's is the inside of the lower half (shaded)."""
    from implc.view.render import View, render_voxels
    s = implc.compile(SPHERE)
    view = View(0.0, 90.0)
    solid = render_voxels(implc.voxelize(s, 6, solid=True), size=128, view=view, cut=(2, 0.0))
    shell = render_voxels(implc.voxelize(s, 6), size=128, view=view, cut=(2, 0.0))
    centre = (slice(44, 84), slice(44, 84))
    assert len(np.unique(solid[centre].reshape(-1, 3), axis=0)) == 1
    assert len(np.unique(shell[centre].reshape(-1, 3), axis=0)) > 10
    with pytest.raises(ValueError, match="outside the bounds"):
        render_voxels(implc.voxelize(s, 4), size=64, cut=(0, 3.0))


@pytest.mark.parametrize("argv, words", [
    (["--cut", "w=0"], "--cut must be AXIS=VALUE"),
    (["--cut", "z=abc"], "--cut must be a number"),
    (["--cut", "z=5"], "must lie within the bounds"),
    (["--cut", "z=0", "--lod", "3"], "cannot be combined with --lod"),
])
def test_bad_cuts_are_named(tmp_path, capsys, argv, words):
    assert main(["render", "torus", "--depth", "4", "--quiet", "-o", str(tmp_path / "t.png"), *argv]) == 2
    assert words in capsys.readouterr().err


# -- the octree of a solid -------------------------------------------------------------------------
def _cells_of(levels, coords, depth):
    n = 1 << depth
    grid = np.zeros((n,) * 3, bool)
    for (i, j, k), level in zip(coords, levels):
        size = 1 << (depth - int(level))
        grid[i * size:(i + 1) * size, j * size:(j + 1) * size, k * size:(k + 1) * size] = True
    return grid


def test_the_octree_records_the_inside_and_its_levels_know_it():
    """The tree's inside entries cover exactly the inside octants' cells; the boundary traversal is the
    shell's; at each level, inside nodes lie where numpy's F < 0 (sampled inside each) and boundary nodes
    hold boundary voxels."""
    depth = 7
    surface = implc.compile(HOLLOW)
    solid, shell = implc.voxelize(surface, depth, solid=True), implc.voxelize(surface, depth)
    tree = solid.octree
    levels, coords = tree.inside_nodes()
    assert np.array_equal(_cells_of(levels, coords, depth), inside_mask(solid))
    assert set(np.unique(tree.nodes[tree.nodes < 0])) == {-1}
    for level in range(depth + 1):
        assert np.array_equal(tree.traverse(level)[0], shell.octree.traverse(level)[0])
    f = sympy.lambdify((x, y, z), HOLLOW, "numpy")
    rng = np.random.default_rng(3)
    for k in (3, 5):
        cells, normals, inside = tree.level(k, solid=True)
        boundary, _ = tree.level(k)
        assert np.array_equal(cells[~inside], boundary) and np.all(normals[inside] == 0)
        codes = morton.morton_codes(cells).astype(np.float64)
        assert np.all(np.diff(codes) > 0)  # Morton order, distinct
        size = 2.0 / (1 << k)
        points = -1 + (cells[inside][:, None, :] + rng.uniform(0, 1, (len(cells[inside]), 16, 3))) * size
        assert np.all(f(*points.reshape(-1, 3).T) < 0)
        expected = np.zeros((1 << k,) * 3, bool)
        expected[tuple((solid.coords >> (depth - k)).T)] = True
        assert np.array_equal(_cells_of(np.full(len(boundary), k), boundary, k), expected)
        covered = _cells_of(np.full(int(inside.sum()), k), cells[inside], k)
        full = inside_mask(solid).reshape((1 << k, 1 << (depth - k)) * 3).all(axis=(1, 3, 5))
        assert np.array_equal(covered, full & ~expected)


def test_eight_inside_siblings_merge_into_their_parent():
    """Eight inside siblings become their parent, up the levels (64 grandchildren: one octant two levels
    up), in any order; the cells covered stay the same and no node is left counted for them."""
    from implc.voxelizer.voxelize import Voxels
    depth = 5
    fine = np.array([[4 + a, 6 + b, 2 + c, 4] for a in (0, 1) for b in (0, 1) for c in (0, 1)], np.int32)
    grand = np.array([[8 + a, 8 + b, 8 + c, 5] for a in range(4) for b in range(4) for c in range(4)], np.int32)
    lone = np.array([[0, 0, 0, 5]], np.int32)
    rows = np.concatenate([fine, grand, lone])[np.random.default_rng(5).permutation(73)]
    voxels = Voxels(np.array([[31, 31, 31]], np.uint32), np.array([[0, 0, 1]], np.float32), depth, ((-1, 1),) * 3,
                    stats=None, inside=rows)
    tree = voxels.octree
    levels, coords = tree.inside_nodes()
    found = sorted(zip(levels.tolist(), map(tuple, coords.tolist())))
    assert found == [(3, (2, 2, 2)), (3, (2, 3, 1)), (5, (0, 0, 0))]
    assert np.array_equal(_cells_of(levels, coords, depth), _cells_of(rows[:, 3], rows[:, :3], depth))
    for level in range(depth + 1):  # the counts match what a traversal finds
        assert len(tree.traverse(level)[0]) == tree.level_counts[level]


def test_a_tree_grows_while_recording_the_inside():
    """Octants needing more nodes than the tree has room for: the native call stops, the tree grows, and
    the call resumes where it stopped."""
    from implc.voxelizer.voxelize import Voxels
    rows = np.array([[i, j, k, 6] for i in (1, 9, 17, 40) for j in (3, 30) for k in (0, 63)], np.int32)
    voxels = Voxels(np.array([[0, 0, 0]], np.uint32), np.array([[0, 0, 1]], np.float32), 6, ((-1, 1),) * 3,
                    stats=None, inside=rows)
    levels, coords = voxels.octree.inside_nodes()
    assert sorted(map(tuple, coords.tolist())) == sorted(map(tuple, rows[:, :3].tolist()))
    assert np.all(levels == 6)


def test_inside_away_from_the_boundary_creates_its_nodes_and_saves(tmp_path):
    """Inside octants under no boundary node (a hand-built case) get the nodes above them; the tree saves
    and loads with its states."""
    from implc.voxelizer.storage.octree import Octree
    inside = np.array([[15, 15, 15, 4], [3, 3, 2, 2], [0, 1, 0, 4]], np.int32)
    voxels = voxelize.Voxels(np.array([[0, 0, 0], [1, 0, 0]], np.uint32),
                                       np.array([[0, 0, 1]] * 2, np.float32), 4, ((-1, 1),) * 3, stats=None,
                                       inside=inside)
    tree = voxels.octree
    levels, coords = tree.inside_nodes()
    found = sorted(zip(levels.tolist(), map(tuple, coords.tolist())))
    assert found == [(2, (3, 3, 2)), (4, (0, 1, 0)), (4, (15, 15, 15))]
    assert np.array_equal(tree.traverse()[0], voxels.coords)
    tree.save(tmp_path / "t.npz")
    again = Octree.load(tmp_path / "t.npz")
    assert np.array_equal(again.inside_nodes()[1], coords)
    cells, normals, inside = again.level(1, solid=True)
    assert cells.tolist() == [[0, 0, 0], [1, 1, 1]] and inside.tolist() == [False, False]
    cells, normals, inside = again.level(2, solid=True)
    assert [c for c, i in zip(cells.tolist(), inside) if i] == [[3, 3, 2]]
