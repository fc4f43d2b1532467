"""Mesh files read by implc itself: STL, PLY, OBJ, glTF binary (GLB) and 3MF, as triangles and nothing else.

A mesh file from outside is untrusted input. These readers follow no reference out of the file (an OBJ's
``mtllib`` and textures, a glTF buffer's ``uri``, a 3MF part on another path, a PLY's texture comment are
never opened), read only regular files (:func:`implc.common.untrusted.regular_file`), bound every count,
size, nesting depth and instance fan-out before memory is spent on it (a 3MF member is inflated to at most
:data:`MAX_INFLATED` bytes, whatever its header says), and refuse non-finite coordinates. Each failure is one
:class:`implc.errors.MeshFileError` naming the file.
"""

from __future__ import annotations

import json
import re
import struct
import zipfile
import zlib
from pathlib import Path

import numpy as np

from ..common.untrusted import ply_elements, ply_header, printable, regular_file
from ..errors import MeshFileError

MAX_FILE_BYTES = 1 << 32
"""The largest mesh file read (4 GiB)."""
MAX_INFLATED = 1 << 30
"""The most bytes a 3MF's model part may inflate to: a zip bomb stops there."""
MAX_TRIANGLES = 1 << 28
"""The most triangles a file may expand to, instances included."""
MAX_INSTANCES = 1 << 16
"""The most placements of meshes a GLB scene or a 3MF build may make (nodes and components expanded)."""
MAX_NESTING = 32
"""The deepest nesting of GLB nodes or 3MF components followed."""


def _fail(path, why: str) -> MeshFileError:
    return MeshFileError(f"cannot read {path} as a mesh: {why}")


def _checked(path, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(vertices as (n, 3) float64, faces as (m, 3) int64), or the reason they are not a mesh."""
    vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
    faces = np.asarray(faces, dtype=np.int64).reshape(-1, 3)
    if len(faces) == 0:
        raise MeshFileError(f"{path} holds no triangles")
    if not np.isfinite(vertices).all():
        raise _fail(path, "a coordinate is not a finite number")
    if faces.min() < 0 or faces.max() >= len(vertices):
        raise _fail(path, "a face names a vertex the file does not hold")
    return vertices, faces


def _fan(polygons: list[list[int]]) -> np.ndarray:
    """Triangles fanned from each polygon's first vertex."""
    rows = [(p[0], p[k], p[k + 1]) for p in polygons for k in range(1, len(p) - 1)]
    return np.array(rows, dtype=np.int64).reshape(-1, 3)


# -- STL ---------------------------------------------------------------------------------------------
def read_stl(path, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    if len(data) >= 84:
        (count,) = struct.unpack_from("<I", data, 80)
        if 84 + 50 * count == len(data):  # binary: the count and the length agree
            rows = np.frombuffer(data, dtype=np.dtype([("n", "<f4", 3), ("v", "<f4", (3, 3)), ("a", "<u2")]),
                                 count=count, offset=84)
            return _checked(path, rows["v"].reshape(-1, 3), np.arange(3 * count).reshape(-1, 3))
    head = data[:512].lstrip().lower()
    if not head.startswith(b"solid"):
        raise _fail(path, "neither a binary STL (its triangle count does not match its length) nor an ASCII one")
    numbers = re.findall(rb"vertex\s+(\S+)\s+(\S+)\s+(\S+)", data)
    if len(numbers) % 3:
        raise _fail(path, "an ASCII STL facet without three vertices")
    try:
        vertices = np.array(numbers, dtype=np.float64)
    except ValueError:
        raise _fail(path, "an ASCII STL vertex that is not three numbers") from None
    return _checked(path, vertices, np.arange(len(vertices)).reshape(-1, 3))


# -- PLY ---------------------------------------------------------------------------------------------
_PLY_TYPES = {"char": "i1", "int8": "i1", "uchar": "u1", "uint8": "u1", "short": "i2", "int16": "i2",
              "ushort": "u2", "uint16": "u2", "int": "i4", "int32": "i4", "uint": "u4", "uint32": "u4",
              "float": "f4", "float32": "f4", "double": "f8", "float64": "f8"}


def read_ply(path, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    lines, body = ply_header(path, MeshFileError)
    ply_elements(path, lines, body, MeshFileError)  # counts bounded by the file's length
    fmt = next((line.split()[1] for line in lines if line.startswith("format")), "")
    if fmt not in ("ascii", "binary_little_endian", "binary_big_endian"):
        raise _fail(path, f"a PLY format implc does not read ('{printable(fmt, 30)}')")
    elements: list[tuple[str, int, list[list[str]]]] = []
    for line in lines:
        words = line.split()
        if words[:1] == ["element"]:
            elements.append((words[1], int(words[2]), []))
        elif words[:1] == ["property"] and elements:
            elements[-1][2].append(words[1:])
    if fmt == "ascii":
        tokens = data[body:].split()
        return _ply_ascii(path, elements, tokens)
    order = "<" if fmt == "binary_little_endian" else ">"
    return _ply_binary(path, elements, data, body, order)


def _ply_binary(path, elements, data: bytes, at: int, order: str) -> tuple[np.ndarray, np.ndarray]:
    vertices = faces = None
    for name, count, properties in elements:
        lists = [p for p in properties if p[0] == "list"]
        if not lists:
            dtype = np.dtype([(p[1], order + _PLY_TYPES[p[0]]) for p in properties])
            if at + count * dtype.itemsize > len(data):
                raise _fail(path, f"its {printable(name, 20)} rows run past the end of the file")
            rows = np.frombuffer(data, dtype=dtype, count=count, offset=at)
            at += count * dtype.itemsize
            if name == "vertex":
                try:
                    vertices = np.stack([rows[a].astype(np.float64) for a in "xyz"], axis=1)
                except (KeyError, ValueError):
                    raise _fail(path, "its vertices have no x, y and z") from None
            continue
        if len(properties) != 1 or name != "face":
            raise _fail(path, f"a PLY element '{printable(name, 20)}' with lists that implc does not read")
        _, size_type, index_type, _ = properties[0]
        size_dt, index_dt = np.dtype(order + _PLY_TYPES[size_type]), np.dtype(order + _PLY_TYPES[index_type])
        if count == 0:
            faces = np.empty((0, 3), np.int64)
            continue
        if at + size_dt.itemsize > len(data):
            raise _fail(path, "its faces run past the end of the file")
        k = int(np.frombuffer(data, size_dt, 1, at)[0])
        row = np.dtype([("k", size_dt), ("i", index_dt, (max(k, 1),))])
        if k >= 3 and at + count * row.itemsize <= len(data):
            rows = np.frombuffer(data, dtype=row, count=count, offset=at)
            if (rows["k"] == k).all():  # every face has k vertices: read at once
                at += count * row.itemsize
                faces = _fan_uniform(rows["i"].astype(np.int64))
                continue
        polygons = []  # faces of several sizes: one at a time, each bounded by the file
        for _ in range(count):
            if at + size_dt.itemsize > len(data):
                raise _fail(path, "its faces run past the end of the file")
            k = int(np.frombuffer(data, size_dt, 1, at)[0])
            at += size_dt.itemsize
            if k < 3 or at + k * index_dt.itemsize > len(data):
                raise _fail(path, "a face with fewer than three vertices, or past the end of the file")
            polygons.append(np.frombuffer(data, index_dt, k, at).astype(np.int64).tolist())
            at += k * index_dt.itemsize
        faces = _fan(polygons)
    if vertices is None or faces is None:
        raise MeshFileError(f"{path} holds no triangles")
    return _checked(path, vertices, faces)


def _fan_uniform(polygons: np.ndarray) -> np.ndarray:
    """Triangles fanned from the first vertex of each of these polygons of equal size."""
    k = polygons.shape[1]
    return np.stack([np.repeat(polygons[:, :1], k - 2, axis=1), polygons[:, 1:-1], polygons[:, 2:]], axis=2)


def _ply_ascii(path, elements, tokens: list[bytes]) -> tuple[np.ndarray, np.ndarray]:
    at = 0
    vertices = faces = None
    try:
        for name, count, properties in elements:
            if all(p[0] != "list" for p in properties):
                width = len(properties)
                if at + count * width > len(tokens):
                    raise _fail(path, f"its {printable(name, 20)} rows run past the end of the file")
                rows = np.array(tokens[at:at + count * width], dtype=np.float64).reshape(count, width)
                at += count * width
                if name == "vertex":
                    names = [p[1] for p in properties]
                    vertices = rows[:, [names.index(a) for a in "xyz"]]
                continue
            if len(properties) != 1 or name != "face":
                raise _fail(path, f"a PLY element '{printable(name, 20)}' with lists that implc does not read")
            polygons = []
            for _ in range(count):
                k = int(tokens[at])
                if k < 3 or at + 1 + k > len(tokens):
                    raise _fail(path, "a face with fewer than three vertices, or past the end of the file")
                polygons.append([int(t) for t in tokens[at + 1:at + 1 + k]])
                at += 1 + k
            faces = _fan(polygons)
    except ValueError:
        raise _fail(path, "a PLY value that is not a number") from None
    if vertices is None or faces is None:
        raise MeshFileError(f"{path} holds no triangles")
    return _checked(path, vertices, faces)


# -- OBJ ---------------------------------------------------------------------------------------------
_OBJ_XYZ = re.compile(rb"^[ \t]*v[ \t]+(\S+)[ \t]+(\S+)[ \t]+(\S+)(?:[ \t]+\S+)?[ \t]*\r?$", re.M)
_OBJ_TRIANGLE = re.compile(rb"^[ \t]*f[ \t]+(\d+)[^\s]*[ \t]+(\d+)[^\s]*[ \t]+(\d+)[^\s]*[ \t]*\r?$", re.M)
_OBJ_SLASHES = re.compile(rb"/[^\s]*")


def read_obj(path, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (``v``) and faces (``f``, polygons fanned; indices from 1, negative ones relative to the
    vertices before them); texture coordinates, normals, groups and materials (``mtllib``: never opened)
    are left out."""
    vertex_lines = len(re.findall(rb"^[ \t]*v[ \t]", data, re.M))
    rows = _OBJ_XYZ.findall(data)
    if len(rows) != vertex_lines:
        raise _fail(path, "a vertex line without three coordinates")
    try:
        vertices = np.array(rows, dtype=np.float64).reshape(-1, 3)
    except ValueError:
        raise _fail(path, "a vertex coordinate that is not a number") from None
    face_lines = len(re.findall(rb"^[ \t]*f[ \t]", data, re.M))
    if face_lines == 0:
        raise MeshFileError(f"{path} holds no triangles")
    if face_lines > MAX_TRIANGLES:
        raise _fail(path, f"more than {MAX_TRIANGLES} faces")
    triangles = _OBJ_TRIANGLE.findall(data)
    if len(triangles) == face_lines:  # triangles with positive indices (what most writers write): at once
        faces = np.array(triangles, dtype=np.int64).reshape(-1, 3)
        if (faces == 0).any():
            raise _fail(path, "a vertex index 0 (indices start at 1)")
        return _checked(path, vertices, faces - 1)
    polygons, seen = [], 0  # polygons, relative indices (counting back from the vertices before each face)
    for match in re.finditer(rb"^[ \t]*([vf])[ \t]+([^\r\n]*)", data, re.M):
        if match.group(1) == b"v":
            seen += 1
            continue
        try:
            indices = [int(t) for t in _OBJ_SLASHES.sub(b"", match.group(2)).split()]
        except ValueError:
            raise _fail(path, "a face index that is not a number") from None
        if len(indices) < 3 or 0 in indices:
            raise _fail(path, "a face with fewer than three vertices, or a vertex index 0 (indices start at 1)")
        polygons.append([i - 1 if i > 0 else seen + i for i in indices])
    return _checked(path, vertices, _fan(polygons))


# -- glTF binary -------------------------------------------------------------------------------------
_COMPONENTS = {5121: np.uint8, 5123: np.uint16, 5125: np.uint32, 5126: np.float32}
_WIDTH = {"SCALAR": 1, "VEC3": 3}


def read_glb(path, data: bytes) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of a GLB's default scene (every mesh placed by its nodes' transforms, or every mesh
    once where there is no scene), from the file's own binary chunk: a buffer with a ``uri`` is refused."""
    if len(data) < 20 or data[:4] != b"glTF":
        raise _fail(path, "not a glTF binary (no 'glTF' magic)")
    version, length = struct.unpack_from("<II", data, 4)
    if version != 2 or length != len(data):
        raise _fail(path, "a glTF binary whose header does not match the file (version 2, its length)")
    chunks: dict[int, bytes] = {}
    at = 12
    while at + 8 <= len(data):
        size, kind = struct.unpack_from("<II", data, at)
        if at + 8 + size > len(data):
            raise _fail(path, "a glTF chunk runs past the end of the file")
        chunks.setdefault(kind, data[at + 8:at + 8 + size])
        at += 8 + size + (-size % 4)
    if 0x4E4F534A not in chunks:
        raise _fail(path, "a glTF binary without its JSON chunk")
    try:
        doc = json.loads(chunks[0x4E4F534A].decode("utf-8"))
    except (ValueError, RecursionError):
        raise _fail(path, "its JSON chunk is not JSON") from None
    if not isinstance(doc, dict):
        raise _fail(path, "its JSON chunk is not a glTF document")
    binary = chunks.get(0x004E4942, b"")
    for buffer in doc.get("buffers", []):
        if not isinstance(buffer, dict) or "uri" in buffer:
            raise _fail(path, "a buffer names a file or URI outside the GLB: implc does not follow it")
    return _Gltf(path, doc, binary).triangles()


class _Gltf:
    def __init__(self, path, doc: dict, binary: bytes):
        self.path, self.doc, self.binary = path, doc, binary
        self.triangles_out = 0

    def _list(self, key: str) -> list:
        value = self.doc.get(key, [])
        if not isinstance(value, list):
            raise _fail(self.path, f"its '{key}' is not a list")
        return value

    def _item(self, key: str, index) -> dict:
        items = self._list(key)
        if not isinstance(index, int) or isinstance(index, bool) or not 0 <= index < len(items) \
                or not isinstance(items[index], dict):
            raise _fail(self.path, f"a reference to {key}[{printable(str(index), 20)}], which it does not hold")
        return items[index]

    def accessor(self, index, kind: str) -> np.ndarray:
        acc = self._item("accessors", index)
        view = self._item("bufferViews", acc.get("bufferView"))
        dtype = _COMPONENTS.get(acc.get("componentType", -1))
        width = _WIDTH.get(acc.get("type", ""))
        count = acc.get("count")
        if dtype is None or width is None or not isinstance(count, int) or count < 0 or \
                (kind == "POSITION") != (width == 3) or (kind == "POSITION") != (dtype is np.float32):
            raise _fail(self.path, "an accessor of a type implc does not read as mesh data")
        offsets = [view.get("byteOffset", 0), acc.get("byteOffset", 0), view.get("byteLength")]
        if not all(isinstance(v, int) and v >= 0 for v in offsets) or view.get("buffer", 0) != 0:
            raise _fail(self.path, "a buffer view outside the file's binary chunk")
        start, length = offsets[0] + offsets[1], offsets[2] - offsets[1]
        item = np.dtype(dtype).itemsize * width
        stride = view.get("byteStride", item) or item
        if not isinstance(stride, int) or stride < item:
            raise _fail(self.path, "a buffer view with a stride shorter than its items")
        need = (count - 1) * stride + item if count else 0
        if need > length or offsets[0] + offsets[2] > len(self.binary):
            raise _fail(self.path, "an accessor's count needs more bytes than its buffer view holds")
        if count == 0:
            return np.empty((0, width), dtype)
        rows = np.lib.stride_tricks.as_strided(np.frombuffer(self.binary, np.uint8, need, start),
                                               (count, item), (stride, 1))
        return np.ascontiguousarray(rows).view(np.dtype(dtype).newbyteorder("<")).reshape(count, width)

    def mesh(self, index) -> tuple[np.ndarray, np.ndarray]:
        mesh = self._item("meshes", index)
        parts_v, parts_f, base = [], [], 0
        for primitive in mesh.get("primitives", []):
            if not isinstance(primitive, dict) or primitive.get("mode", 4) != 4:
                raise _fail(self.path, "a primitive that is not triangles")
            attributes = primitive.get("attributes", {})
            if not isinstance(attributes, dict) or "POSITION" not in attributes:
                raise _fail(self.path, "a primitive without positions")
            vertices = self.accessor(attributes["POSITION"], "POSITION").astype(np.float64)
            if "indices" in primitive:
                faces = self.accessor(primitive["indices"], "indices").astype(np.int64).reshape(-1)
            else:
                faces = np.arange(len(vertices), dtype=np.int64)
            if len(faces) % 3:
                raise _fail(self.path, "a triangle list whose length is not a multiple of three")
            parts_v.append(vertices)
            parts_f.append(faces.reshape(-1, 3) + base)
            base += len(vertices)
        if not parts_v:
            return np.empty((0, 3)), np.empty((0, 3), np.int64)
        return np.concatenate(parts_v), np.concatenate(parts_f)

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        placements: list[tuple[int, np.ndarray]] = []
        scenes = self._list("scenes")
        if scenes:
            scene = self._item("scenes", self.doc.get("scene", 0))
            stack = [(node, np.eye(4), 1) for node in scene.get("nodes", [])]
            while stack:
                node_index, parent, depth = stack.pop()
                if depth > MAX_NESTING:
                    raise _fail(self.path, f"nodes nested more than {MAX_NESTING} deep")
                node = self._item("nodes", node_index)
                matrix = parent @ _node_matrix(self.path, node)
                if "mesh" in node:
                    placements.append((node["mesh"], matrix))
                stack.extend((child, matrix, depth + 1) for child in node.get("children", []))
                if len(placements) + len(stack) > MAX_INSTANCES:
                    raise _fail(self.path, f"more than {MAX_INSTANCES} placed meshes")
        else:
            placements = [(k, np.eye(4)) for k in range(len(self._list("meshes")))]
        meshes: dict[int, tuple[np.ndarray, np.ndarray]] = {}
        vertices, faces, base, total = [], [], 0, 0
        for index, matrix in placements:
            if index not in meshes:
                meshes[index] = self.mesh(index)
            v, f = meshes[index]
            if not np.isfinite(v).all():
                raise _fail(self.path, "a coordinate is not a finite number")
            total += len(f)
            if total > MAX_TRIANGLES:
                raise _fail(self.path, f"its scene expands to more than {MAX_TRIANGLES} triangles")
            with np.errstate(all="ignore"):  # a transform that overflows is caught as non-finite below
                vertices.append(v @ matrix[:3, :3].T + matrix[:3, 3])
            faces.append(f + base)
            base += len(v)
        if not faces:
            raise MeshFileError(f"{self.path} holds no triangles")
        return _checked(self.path, np.concatenate(vertices), np.concatenate(faces))


def _node_matrix(path, node: dict) -> np.ndarray:
    try:
        if "matrix" in node:
            matrix = np.array(node["matrix"], dtype=np.float64).reshape(4, 4).T  # column-major
        else:
            t = np.array(node.get("translation", [0, 0, 0]), dtype=np.float64).reshape(3)
            x, y, z, w = np.array(node.get("rotation", [0, 0, 0, 1]), dtype=np.float64).reshape(4)
            s = np.array(node.get("scale", [1, 1, 1]), dtype=np.float64).reshape(3)
            rotation = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
            matrix = np.eye(4)
            matrix[:3, :3] = rotation * s
            matrix[:3, 3] = t
    except (TypeError, ValueError):
        raise _fail(path, "a node transform that is not numbers") from None
    if not np.isfinite(matrix).all():
        raise _fail(path, "a node transform that is not finite")
    return matrix


# -- 3MF ---------------------------------------------------------------------------------------------
_CORE = "{http://schemas.microsoft.com/3dmanufacturing/core/2015/02}"


def read_3mf(path, data: bytes, max_inflated: int = MAX_INFLATED) -> tuple[np.ndarray, np.ndarray]:
    """The triangles of a 3MF's build: each item's object (its mesh, or its components, nested at most
    :data:`MAX_NESTING` deep) placed by the transforms. Only the model part ``3D/3dmodel.model`` is read;
    a component in another part (the production extension's ``path``) is refused, not followed."""
    import io

    from lxml import etree
    try:
        archive = zipfile.ZipFile(io.BytesIO(data))
        info = archive.getinfo("3D/3dmodel.model")
        if info.file_size > max_inflated:
            raise _fail(path, f"its model part inflates to more than {max_inflated} bytes")
        with archive.open(info) as member:
            model = member.read(max_inflated + 1)  # a header that lies about the size stops here too
    except KeyError:
        raise _fail(path, "a 3MF without 3D/3dmodel.model") from None
    except (zipfile.BadZipFile, zipfile.LargeZipFile, OSError, EOFError, NotImplementedError, zlib.error) as exc:
        raise _fail(path, f"a damaged 3MF archive ({printable(str(exc), 80)})") from None
    if len(model) > max_inflated:
        raise _fail(path, f"its model part inflates to more than {max_inflated} bytes")
    # each mesh's vertex and triangle lists are read with one regular expression each, and left out of the
    # tree that lxml builds of the rest (a tree of millions of elements is what made reading slow)
    blocks: list[np.ndarray] = []

    def lifted(match) -> bytes:
        tag, body = match.group(1), match.group(2)
        names = (b"x", b"y", b"z") if tag == b"vertices" else (b"v1", b"v2", b"v3")
        item = b"vertex" if tag == b"vertices" else b"triangle"
        pattern = rb"<" + item + b"".join(rb'\s+' + n + rb'\s*=\s*"([^"]*)"' for n in names) + rb"\s*/>"
        found = re.findall(pattern, body)
        if len(found) != body.count(b"<" + item):
            raise _fail(path, f"a {item.decode()} without its {', '.join(n.decode() for n in names)} (in that order)")
        try:
            blocks.append(np.array(found, dtype=np.float64 if item == b"vertex" else np.int64).reshape(-1, 3))
        except (ValueError, OverflowError):
            raise _fail(path, f"a {item.decode()} that is not numbers") from None
        return b"<" + tag + b' implc-block="' + str(len(blocks) - 1).encode() + b'"/>'

    model = re.sub(rb"<(vertices|triangles)>(.*?)</\1>", lifted, model, flags=re.S)
    parser = etree.XMLParser(resolve_entities=False, no_network=True, load_dtd=False)
    try:
        root = etree.fromstring(model, parser)
    except etree.XMLSyntaxError as exc:
        raise _fail(path, f"its model is not XML ({printable(str(exc), 80)})") from None
    return _Model(path, root, blocks).triangles()


class _Model:
    def __init__(self, path, root, blocks: list[np.ndarray]):
        self.path, self.blocks = path, blocks
        self.objects = {o.get("id"): o for o in root.iter(_CORE + "object")}
        self.build = root.find(_CORE + "build")
        self.meshes: dict[str, tuple[np.ndarray, np.ndarray]] = {}

    def _block(self, mesh, tag: str) -> np.ndarray:
        element = mesh.find(_CORE + tag)
        index = None if element is None else element.get("implc-block")
        if index is None or not index.isdigit() or int(index) >= len(self.blocks):
            raise _fail(self.path, f"a mesh without its {tag}")
        return self.blocks[int(index)]

    def mesh(self, obj) -> tuple[np.ndarray, np.ndarray]:
        key = obj.get("id")
        if key not in self.meshes:
            mesh = obj.find(_CORE + "mesh")
            vertices, faces = self._block(mesh, "vertices"), self._block(mesh, "triangles")
            if not np.isfinite(vertices).all():
                raise _fail(self.path, "a coordinate is not a finite number")
            if len(faces) and (faces.min() < 0 or faces.max() >= len(vertices)):
                raise _fail(self.path, f"object {printable(str(key), 20)}: a triangle names a vertex it does not hold")
            self.meshes[key] = (vertices, faces)
        return self.meshes[key]

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        if self.build is None:
            raise MeshFileError(f"{self.path} holds no triangles")
        stack = [(item.get("objectid"), _transform(self.path, item.get("transform")), 1)
                 for item in self.build.iter(_CORE + "item")]
        vertices, faces, base, total, placed = [], [], 0, 0, 0
        while stack:
            key, matrix, depth = stack.pop()
            placed += 1
            if depth > MAX_NESTING or placed > MAX_INSTANCES:
                raise _fail(self.path, f"components nested more than {MAX_NESTING} deep or placed more than "
                                       f"{MAX_INSTANCES} times")
            obj = self.objects.get(key)
            if obj is None:
                raise _fail(self.path, f"a reference to object {printable(str(key), 20)}, which it does not hold")
            if obj.find(_CORE + "mesh") is not None:
                v, f = self.mesh(obj)
                total += len(f)
                if total > MAX_TRIANGLES:
                    raise _fail(self.path, f"its build expands to more than {MAX_TRIANGLES} triangles")
                with np.errstate(all="ignore"):  # a transform that overflows is caught as non-finite below
                    vertices.append(v @ matrix[:3, :3] + matrix[3, :3])
                faces.append(f + base)
                base += len(v)
            for component in obj.iter(_CORE + "component"):
                if any(name.endswith("}path") for name in component.attrib):
                    raise _fail(self.path, "a component in another part of the package: implc does not follow it")
                stack.append((component.get("objectid"),
                              _transform(self.path, component.get("transform")) @ matrix, depth + 1))
                if len(stack) > MAX_INSTANCES:
                    raise _fail(self.path, f"more than {MAX_INSTANCES} placed objects")
        if not faces:
            raise MeshFileError(f"{self.path} holds no triangles")
        return _checked(self.path, np.concatenate(vertices), np.concatenate(faces))


def _transform(path, text: str | None) -> np.ndarray:
    """A 3MF transform (12 numbers, row vectors: p' = [x y z 1] · M) as a 4×4 matrix."""
    matrix = np.eye(4)
    if text is None:
        return matrix
    try:
        values = np.array(text.split(), dtype=np.float64)
    except ValueError:
        raise _fail(path, "a transform that is not numbers") from None
    if len(values) != 12 or not np.isfinite(values).all():
        raise _fail(path, "a transform that is not twelve finite numbers")
    matrix[:, :3] = values.reshape(4, 3)
    return matrix


READERS = {".stl": read_stl, ".ply": read_ply, ".obj": read_obj, ".glb": read_glb, ".3mf": read_3mf}


def read_mesh(path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (n, 3) float64, faces (m, 3) int64) of a mesh file, by its suffix."""
    path = Path(path)
    reader = READERS.get(path.suffix.lower())
    if reader is None:
        raise MeshFileError(f"cannot read {path} as a mesh: implc reads {', '.join(READERS)}")
    size = regular_file(path, MeshFileError, "mesh file")
    if size > MAX_FILE_BYTES:
        raise _fail(path, f"{size >> 20} MiB, more than the {MAX_FILE_BYTES >> 20} MiB implc reads")
    with open(path, "rb") as f:
        data = f.read(MAX_FILE_BYTES + 1)
    try:
        return reader(path, data)
    except MeshFileError:
        raise
    except (ValueError, TypeError, KeyError, IndexError, OverflowError, struct.error, zlib.error,
            RecursionError) as exc:  # a damaged file can fail in many places: one line all the same
        raise _fail(path, f"damaged ({printable(str(exc), 80) or type(exc).__name__})") from None
