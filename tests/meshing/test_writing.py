"""A written mesh keeps its promises in its format's precision, or the write is refused with the reason:
read back by implc's own reader (and counted by exact edge arithmetic), it is closed and manifold with
every triangle facing as before; an empty mesh is refused; a link's target is written, the link kept."""

import numpy as np
import pytest
import sympy

import implc
from implc import x, y, z
from implc.errors import MeshFileError
from implc.meshing.triangle_mesh import Mesh, load

FORMATS = (".stl", ".obj", ".ply", ".glb", ".3mf")


def merged(mesh: Mesh) -> Mesh:
    """Equal coordinates are one vertex (as a slicer or STL reader merges them)."""
    distinct, inverse = np.unique(mesh.vertices, axis=0, return_inverse=True)
    return Mesh(distinct, inverse.reshape(-1)[mesh.faces])


def faces_as_before(written: Mesh, original: Mesh) -> bool:
    a, b, c = (written.vertices[written.faces[:, k]] for k in range(3))
    oa, ob, oc = (original.vertices[original.faces[:, k]] for k in range(3))
    return bool((np.einsum("ij,ij->i", np.cross(b - a, c - a), np.cross(ob - oa, oc - oa)) > 0).all())


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_mesh_near_the_origin_reads_back_closed_in_every_format(tmp_path, suffix):
    mesh = implc.mesh(implc.compile(x**2 + y**2 + z**2 - 0.5), 5)
    mesh.save(tmp_path / f"m{suffix}")
    back = load(tmp_path / f"m{suffix}")
    report = merged(back).check()
    assert report["open_edges"] == report["overused_edges"] == report["repeated_directed_edges"] == 0
    assert report["degenerate"] == 0 and faces_as_before(back, mesh)


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_mesh_far_from_the_origin_is_refused_where_its_precision_breaks_it(tmp_path, suffix):
    """A ball of radius 1/2 at x = 10^6 meshed at 128³: float32's step there (1/16) is larger than a cell
    (1/64), so in STL and GLB (and in nine digits, OBJ and 3MF) distinct vertices would become one; PLY holds
    doubles and is written. Whatever is written reads back closed, manifold, every triangle as before."""
    far = implc.compile((x - 10**6)**2 + y**2 + z**2 - 0.25, ((10**6 - 1, 10**6 + 1), (-1, 1), (-1, 1)))
    mesh = implc.mesh(far, 7)
    path = tmp_path / f"far{suffix}"
    try:
        mesh.save(path)
    except MeshFileError as error:
        assert suffix != ".ply" and "precision" in str(error) and not path.exists()
        return
    back = load(path)
    report = merged(back).check()
    assert report["open_edges"] == report["overused_edges"] == report["repeated_directed_edges"] == 0
    assert report["degenerate"] == 0 and faces_as_before(back, mesh)


def test_coordinates_beyond_float32_are_refused_in_float32_formats(tmp_path):
    mesh = Mesh(np.array([[0, 0, 0], [1e39, 0, 0], [0, 1e39, 0], [0, 0, 1e39]], float),
                np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]]))
    with pytest.raises(MeshFileError, match="beyond the range of float32"):
        mesh.save(tmp_path / "big.stl")
    mesh.save(tmp_path / "big.ply")
    assert load(tmp_path / "big.ply").volume == pytest.approx(mesh.volume)


def test_an_empty_mesh_is_refused(tmp_path, capsys):
    from implc.cli.commands import main
    empty = implc.mesh(implc.compile(x**2 + y**2 + z**2 + 1), 3)
    with pytest.raises(MeshFileError, match="no triangles"):
        empty.save(tmp_path / "e.stl")
    assert main(["mesh", "--expr", "x**2 + y**2 + z**2 + 1", "--depth", "3", "-o", str(tmp_path / "e.stl")]) == 2
    assert "no triangles" in capsys.readouterr().err and not (tmp_path / "e.stl").exists()


def test_a_link_as_output_keeps_the_link_and_writes_its_target(tmp_path):
    target = tmp_path / "real.stl"
    target.write_bytes(b"old")
    link = tmp_path / "link.stl"
    link.symlink_to(target)
    mesh = implc.mesh(implc.compile(x**2 + y**2 + z**2 - 0.5), 4)
    mesh.save(link)
    assert link.is_symlink() and len(load(target).faces) == len(mesh.faces)


@pytest.mark.parametrize("suffix", FORMATS)
def test_a_mesh_whose_cells_span_few_float32_steps_reads_back_free_of_intersections(tmp_path, suffix):
    """The file keeps the promise of no self-intersection: a box minus a ball, and a gyroid, in bounds a
    quarter wide at 100 meshed at 64³, where a cell spans 512 float32 steps and a dual vertex's margin
    inside its cell two; written, read back (equal coordinates merged) and moved to the origin (exactly: a
    difference of floats within a factor of two of each other), each passes every validator of the mesh
    tests, pymeshlab's self-intersection selection tested pair by pair in exact arithmetic among them."""
    from ..support.meshes import BOX_BALL, assert_closed_manifold

    corner, width = 100, 0.25
    shift = {x: (x - corner) * 8 - 1, y: (y - corner) * 8 - 1, z: (z - corner) * 8 - 1}
    gyroid = sum(sympy.sin(4 * u) * sympy.cos(4 * v) for u, v in ((x, y), (y, z), (z, x)))
    for expr in (BOX_BALL, gyroid):
        surface = implc.compile(expr.subs(shift, simultaneous=True), ((corner, corner + width),) * 3)
        mesh = implc.mesh(surface, 6)
        assert mesh.stats.dual_cells > 0.8 * mesh.stats.crossed_cells
        mesh.save(tmp_path / f"m{suffix}")
        back = merged(load(tmp_path / f"m{suffix}"))
        assert len(back.faces) == len(mesh.faces)
        assert_closed_manifold(Mesh(back.vertices - corner, back.faces))
