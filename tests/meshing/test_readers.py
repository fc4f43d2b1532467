"""Mesh files from outside: the readers follow no reference out of the file, read only regular files, bound
every count, nesting depth and fan-out before spending memory or time on it, and refuse non-finite
coordinates, each with one line (the command: exit status 2). Files are built here byte by byte, by the
formats' own layouts (not through implc's writers)."""

import io
import json
import os
import struct
import subprocess
import sys
import threading
import time
import zipfile

import numpy as np
import pytest

import implc
from implc.errors import MeshFileError
from implc.meshing.readers import MAX_INSTANCES, MAX_NESTING, read_3mf
from implc.meshing.triangle_mesh import load

TETRA_V = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0), (0.0, 0.0, 1.0)]
TETRA_F = [(0, 2, 1), (0, 1, 3), (0, 3, 2), (1, 2, 3)]  # outward
TETRA_VOLUME = 1 / 6


def glb(doc: dict, binary: bytes = b"") -> bytes:
    """A glTF binary: header, JSON chunk (space-padded), BIN chunk (zero-padded)."""
    text = json.dumps(doc).encode()
    text += b" " * (-len(text) % 4)
    binary += b"\0" * (-len(binary) % 4)
    chunks = struct.pack("<II", len(text), 0x4E4F534A) + text
    if binary:
        chunks += struct.pack("<II", len(binary), 0x004E4942) + binary
    return b"glTF" + struct.pack("<II", 2, 12 + len(chunks)) + chunks


def tetra_glb(nodes=None, scenes=None, positions=None, count=None, extra_buffers=()) -> bytes:
    vertices = np.array(TETRA_V if positions is None else positions, np.float32)
    indices = np.array(TETRA_F, np.uint32).ravel()
    binary = vertices.tobytes() + indices.tobytes()
    doc = {"asset": {"version": "2.0"},
           "buffers": [{"byteLength": len(binary)}, *extra_buffers],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": vertices.nbytes},
                           {"buffer": 0, "byteOffset": vertices.nbytes, "byteLength": indices.nbytes}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": len(vertices) if count is None else count,
                          "type": "VEC3"},
                         {"bufferView": 1, "componentType": 5125, "count": len(indices), "type": "SCALAR"}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0}, "indices": 1}]}],
           "nodes": nodes if nodes is not None else [{"mesh": 0}],
           "scenes": scenes if scenes is not None else [{"nodes": [0]}], "scene": 0}
    return glb(doc, binary)


def three_mf(model: str, compress=zipfile.ZIP_DEFLATED) -> bytes:
    out = io.BytesIO()
    with zipfile.ZipFile(out, "w", compress) as z:
        z.writestr("[Content_Types].xml", '<?xml version="1.0"?><Types/>')
        z.writestr("3D/3dmodel.model", model)
    return out.getvalue()


CORE = "http://schemas.microsoft.com/3dmanufacturing/core/2015/02"


def tetra_model(build='<item objectid="1"/>', vertices=None, extra="") -> str:
    vs = "".join(f'<vertex x="{x}" y="{y}" z="{z}"/>' for x, y, z in (vertices or TETRA_V))
    ts = "".join(f'<triangle v1="{a}" v2="{b}" v3="{c}"/>' for a, b, c in TETRA_F)
    return (f'<?xml version="1.0" encoding="UTF-8"?><model unit="millimeter" xmlns="{CORE}"><resources>'
            f'<object id="1" type="model"><mesh><vertices>{vs}</vertices><triangles>{ts}</triangles></mesh>'
            f'</object>{extra}</resources><build>{build}</build></model>')


def tetra_obj(extra: str = "") -> str:
    return extra + "".join(f"v {x} {y} {z}\n" for x, y, z in TETRA_V) + \
        "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in TETRA_F)


def info(path, capsys) -> tuple[int, str, str]:
    """``implc info`` on ``path``, in this process: (status, stdout, stderr)."""
    from implc.cli.commands import main
    code = main(["info", str(path)])
    captured = capsys.readouterr()
    return code, captured.out, captured.err


# -- what the readers read -------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".obj", ".glb", ".3mf"])
def test_each_format_built_by_hand_reads_as_its_triangles(tmp_path, suffix):
    path = tmp_path / f"t{suffix}"
    path.write_bytes({".obj": tetra_obj().encode(), ".glb": tetra_glb(), ".3mf": three_mf(tetra_model())}[suffix])
    mesh = load(path)
    assert mesh.vertices.tolist() == [list(v) for v in TETRA_V] and mesh.faces.tolist() == [list(f) for f in TETRA_F]
    assert mesh.volume == pytest.approx(TETRA_VOLUME, rel=1e-15)


def test_transforms_place_instances(tmp_path):
    """A GLB node's translation and a 3MF item's transform move the mesh: twice placed, twice the volume,
    and the second copy where the transform puts it."""
    path = tmp_path / "two.glb"
    path.write_bytes(tetra_glb(nodes=[{"mesh": 0}, {"mesh": 0, "translation": [5, 0, 0]}],
                               scenes=[{"nodes": [0, 1]}]))
    mesh = load(path)
    assert mesh.volume == pytest.approx(2 * TETRA_VOLUME) and mesh.vertices[:, 0].max() == 6
    path = tmp_path / "two.3mf"
    items = '<item objectid="1"/><item objectid="1" transform="1 0 0 0 1 0 0 0 1 0 7 0"/>'
    path.write_bytes(three_mf(tetra_model(items)))
    mesh = load(path)
    assert mesh.volume == pytest.approx(2 * TETRA_VOLUME) and mesh.vertices[:, 1].max() == 8


def test_a_ply_with_a_long_header_is_read(tmp_path):
    """A valid PLY whose header has a hundred comment lines is a mesh, not damage."""
    header = ["ply", "format binary_little_endian 1.0", *[f"comment line {k}" for k in range(100)],
              "element vertex 4", "property float x", "property float y", "property float z",
              "element face 4", "property list uchar int vertex_indices", "end_header"]
    body = np.array(TETRA_V, "<f4").tobytes() + b"".join(struct.pack("<B3i", 3, *f) for f in TETRA_F)
    path = tmp_path / "long.ply"
    path.write_bytes(("\n".join(header) + "\n").encode() + body)
    assert load(path).volume == pytest.approx(TETRA_VOLUME)


# -- nothing read out of the file ------------------------------------------------------------------------
def test_a_glb_buffer_naming_a_sibling_file_is_refused_and_the_file_not_read(tmp_path, capsys):
    secret = tmp_path / "secret.txt"
    secret.write_bytes(np.array(TETRA_V, np.float32).tobytes() + np.array(TETRA_F, np.uint32).tobytes())
    doc = json.loads(tetra_glb()[20:20 + struct.unpack_from("<I", tetra_glb(), 12)[0]])
    doc["buffers"] = [{"uri": "secret.txt", "byteLength": secret.stat().st_size}]
    path = tmp_path / "ref.glb"
    path.write_bytes(glb(doc))
    before = os.stat(secret).st_atime_ns
    with pytest.raises(MeshFileError, match="outside the GLB"):
        load(path)
    assert os.stat(secret).st_atime_ns == before
    code, out, err = info(path, capsys)
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "outside the GLB" in err
    export = tmp_path / "site"
    run = subprocess.run([sys.executable, "-m", "implc", "view", str(path), "--export", str(export), "--quiet"],
                         capture_output=True, text=True, timeout=60)
    assert run.returncode == 2 and not export.exists()


@pytest.mark.skipif(not hasattr(os, "mkfifo"), reason="needs FIFOs")
def test_an_obj_whose_material_and_texture_are_fifos_reads_without_opening_them(tmp_path):
    """``mtllib`` and a texture naming FIFOs: opening either would block for ever; the reader opens neither."""
    os.mkfifo(tmp_path / "m.mtl")
    os.mkfifo(tmp_path / "t.png")
    path = tmp_path / "t.obj"
    path.write_text(tetra_obj("mtllib m.mtl\nusemtl x\nvt 0 0\n") + "# map_Kd t.png\n")
    done = []
    reader = threading.Thread(target=lambda: done.append(load(path)), daemon=True)
    reader.start()
    reader.join(10)
    assert done and done[0].volume == pytest.approx(TETRA_VOLUME)


def test_a_3mf_component_in_another_part_is_refused(tmp_path):
    production = "http://schemas.microsoft.com/3dmanufacturing/production/2015/06"
    extra = (f'<object id="2" type="model"><components><component xmlns:p="{production}" '
             'p:path="/3D/other.model" objectid="1"/></components></object>')
    path = tmp_path / "parts.3mf"
    path.write_bytes(three_mf(tetra_model('<item objectid="2"/>', extra=extra)))
    with pytest.raises(MeshFileError, match="another part"):
        load(path)


def test_a_3mf_entity_is_not_expanded(tmp_path):
    """An XML external entity naming a local file is neither read nor expanded."""
    secret = tmp_path / "secret.txt"
    secret.write_text("0.5")
    model = tetra_model().replace('<?xml version="1.0" encoding="UTF-8"?>',
                                  f'<?xml version="1.0"?><!DOCTYPE model [<!ENTITY s SYSTEM "file://{secret}">]>')
    model = model.replace('x="1.0"', 'x="&s;"', 1)
    path = tmp_path / "xxe.3mf"
    path.write_bytes(three_mf(model))
    with pytest.raises(MeshFileError):
        load(path)


# -- counts, depth and fan-out bounded ---------------------------------------------------------------------
def test_a_3mf_zip_bomb_stops_at_the_bound(tmp_path):
    """A model part that inflates past the bound is refused without inflating it whole (the bound is the
    reader's parameter: 1 MiB here against a 64 MiB part of spaces, a few kB on disk)."""
    model = tetra_model().replace("<resources>", "<resources>" + " " * (64 << 20), 1)
    data = three_mf(model)
    assert len(data) < 1 << 20
    t0 = time.process_time()
    with pytest.raises(MeshFileError, match="inflates to more than"):
        read_3mf("bomb.3mf", data, max_inflated=1 << 20)
    assert time.process_time() - t0 < 5


def test_3mf_fan_out_and_nesting_are_bounded(tmp_path):
    """Components that each place the next one twice: 2^40 placements if followed; refused at the bound."""
    objects = "".join(f'<object id="{k + 2}" type="model"><components><component objectid="{k + 1}"/>'
                      f'<component objectid="{k + 1}" transform="1 0 0 0 1 0 0 0 1 1 0 0"/></components></object>'
                      for k in range(40))
    path = tmp_path / "fan.3mf"
    path.write_bytes(three_mf(tetra_model('<item objectid="41"/>', extra=objects)))
    t0 = time.monotonic()
    with pytest.raises(MeshFileError, match=f"{MAX_NESTING} deep|{MAX_INSTANCES}"):
        load(path)
    assert time.monotonic() - t0 < 10
    items = '<item objectid="1"/>' * (MAX_INSTANCES + 1)
    path.write_bytes(three_mf(tetra_model(items)))
    with pytest.raises(MeshFileError, match=str(MAX_INSTANCES)):
        load(path)


def test_glb_nesting_and_instances_are_bounded(tmp_path):
    deep = [{"mesh": 0, "children": [k + 1]} for k in range(MAX_NESTING + 5)] + [{"mesh": 0}]
    path = tmp_path / "deep.glb"
    path.write_bytes(tetra_glb(nodes=deep))
    with pytest.raises(MeshFileError, match="nested"):
        load(path)
    wide = [{"children": list(range(1, 301))}] + [{"children": list(range(301, 601))}] * 300 + [{"mesh": 0}] * 300
    path.write_bytes(tetra_glb(nodes=wide))
    t0 = time.monotonic()
    with pytest.raises(MeshFileError, match="placed meshes"):
        load(path)
    assert time.monotonic() - t0 < 10


def test_a_glb_accessor_count_that_lies_is_refused(tmp_path):
    path = tmp_path / "lie.glb"
    path.write_bytes(tetra_glb(count=10**9))
    with pytest.raises(MeshFileError, match="count needs more bytes"):
        load(path)


def test_ply_list_sizes_and_obj_index_zero_are_refused(tmp_path):
    header = ["ply", "format binary_little_endian 1.0", "element vertex 4", "property float x",
              "property float y", "property float z", "element face 1", "property list uchar int vertex_indices",
              "end_header"]
    path = tmp_path / "big.ply"
    body = np.array(TETRA_V, "<f4").tobytes() + bytes([255]) + b"\0" * 12  # a face of 255 vertices, 3 given
    path.write_bytes(("\n".join(header) + "\n").encode() + body)
    with pytest.raises(MeshFileError):
        load(path)
    path = tmp_path / "zero.obj"
    path.write_text(tetra_obj().replace("f 1 3 2", "f 0 3 2"))
    with pytest.raises(MeshFileError, match="index 0"):
        load(path)


# -- non-finite coordinates ------------------------------------------------------------------------------
@pytest.mark.parametrize("suffix", [".stl", ".obj", ".ply", ".glb", ".3mf", "3mf transform"])
@pytest.mark.parametrize("value", ["nan", "inf"])
def test_non_finite_coordinates_are_refused(tmp_path, capsys, suffix, value):
    v = [(float(value), 0.0, 0.0), *TETRA_V[1:]]
    if suffix == ".stl":
        data = b"\0" * 80 + struct.pack("<I", 4) + b"".join(
            struct.pack("<3f", 0, 0, 0) + np.array([v[i] for i in f], "<f4").tobytes() + b"\0\0" for f in TETRA_F)
    elif suffix == ".obj":
        data = "".join(f"v {x} {y} {z}\n" for x, y, z in v).encode() + b"f 1 2 3\nf 1 2 4\nf 1 3 4\nf 2 3 4\n"
    elif suffix == ".ply":
        header = ["ply", "format binary_little_endian 1.0", "element vertex 4", "property float x",
                  "property float y", "property float z", "element face 4",
                  "property list uchar int vertex_indices", "end_header"]
        data = ("\n".join(header) + "\n").encode() + np.array(v, "<f4").tobytes() + \
            b"".join(struct.pack("<B3i", 3, *f) for f in TETRA_F)
    elif suffix == ".glb":
        data = tetra_glb(positions=v)
    elif suffix == ".3mf":
        data = three_mf(tetra_model(vertices=v))
    else:
        data = three_mf(tetra_model(f'<item objectid="1" transform="1 0 0 0 1 0 0 0 1 {value} 0 0"/>'))
    path = tmp_path / f"bad{suffix.split()[0] if suffix.startswith('.') else '.3mf'}"
    path.write_bytes(data)
    with pytest.raises(MeshFileError, match="finite"):
        load(path)
    code, out, err = info(path, capsys)
    assert code == 2 and len(err.strip().splitlines()) == 1 and "finite" in err


def test_a_fifo_is_not_read(tmp_path):
    if not hasattr(os, "mkfifo"):
        pytest.skip("needs FIFOs")
    os.mkfifo(tmp_path / "f.glb")
    with pytest.raises(MeshFileError, match="FIFO"):
        load(tmp_path / "f.glb")


def test_a_mesh_round_trips_through_every_format_implc_writes(tmp_path):
    mesh = implc.mesh(implc.compile(implc.x**2 + implc.y**2 + implc.z**2 - 0.5), 4)
    for suffix in (".stl", ".ply", ".obj", ".glb", ".3mf"):
        mesh.save(tmp_path / f"m{suffix}")
        back = load(tmp_path / f"m{suffix}")
        assert len(back.faces) == len(mesh.faces)
        assert back.volume == pytest.approx(mesh.volume, rel=1e-5)  # float32 or the decimals written
