"""Exports: .npz round-trips exactly, .ply reads back with an independent reader, .npy is the occupancy."""

import numpy as np
import pytest
from plyfile import PlyData

import implc
from implc import shapes
from implc.files import voxel_files


@pytest.fixture(scope="module")
def voxels():
    return implc.voxelize(implc.compile(shapes.torus(0.6, 0.25), bounds=((-1, 1), (-1, 1), (-0.5, 0.5))), 6)


def test_npz_round_trip_is_exact(voxels, tmp_path):
    voxel_files.save(voxels, tmp_path / "v.npz")
    back = voxel_files.load_npz(tmp_path / "v.npz")
    np.testing.assert_array_equal(back.coords, voxels.coords)
    np.testing.assert_array_equal(back.normals, voxels.normals)
    assert back.depth == voxels.depth and back.bounds == voxels.bounds
    assert back.coords.dtype == np.uint32 and back.normals.dtype == np.float32
    np.testing.assert_array_equal(back.octree.traverse()[0], voxels.coords)


def test_ply_reads_back_with_plyfile(voxels, tmp_path):
    voxel_files.save(voxels, tmp_path / "v.ply")
    ply = PlyData.read(str(tmp_path / "v.ply"))
    vertex = ply["vertex"]
    assert ply.text is False and vertex.count == len(voxels)
    xyz = np.column_stack([vertex["x"], vertex["y"], vertex["z"]])
    nrm = np.column_stack([vertex["nx"], vertex["ny"], vertex["nz"]])
    np.testing.assert_allclose(xyz, voxels.centers(), rtol=1e-6, atol=1e-7)
    np.testing.assert_array_equal(nrm, voxels.normals)


def test_dense_npy_is_the_occupancy(voxels, tmp_path):
    voxel_files.save(voxels, tmp_path / "v.npy")
    np.testing.assert_array_equal(np.load(tmp_path / "v.npy"), voxels.to_dense())


def test_bad_files_are_named(tmp_path):
    (tmp_path / "other.npz").write_bytes(b"PK\x03\x04 nonsense")
    with pytest.raises(voxel_files.VoxelFileError, match="cannot read"):
        voxel_files.load_npz(tmp_path / "other.npz")
    np.savez(tmp_path / "foreign.npz", a=np.zeros(3))
    with pytest.raises(voxel_files.VoxelFileError, match="not an implc voxel file"):
        voxel_files.load_npz(tmp_path / "foreign.npz")
    with pytest.raises(ValueError, match="unknown output format"):
        voxel_files.save(None, tmp_path / "v.obj")
