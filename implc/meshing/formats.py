"""Mesh files written with numpy: binary STL, binary PLY, OBJ, 3MF and glTF binary (:meth:`implc.Mesh.save`).

Why not trimesh: its writers took several times as long (OBJ and 3MF most, longer than making the mesh),
and importing it costs more than some writes (``implc bench --sections mesh`` times both).
Here the rows are laid out in fixed-width records, a chunk of :data:`ROWS` at a time (memory for a
chunk, not for the mesh), and written as they are.

- **STL** (binary): an 80-byte header, the count, then per triangle its unit normal (from its corners:
  outward, as the faces wind counter-clockwise seen from outside; 0 for a degenerate one), its three
  corners and a zero attribute, all float32 as the format has them.
- **PLY** (binary little-endian): vertices as doubles (every bit of ``Mesh.vertices``), their analytic
  normals as floats, faces as a list of three int32.
- **OBJ** (text): ``v`` and ``vn`` lines (nine significant digits: finer than float32, within 10⁻⁸ of
  each value relatively), faces ``f a//a b//b c//c`` (1-based, the vertex's own normal). A normal that is
  not finite is written 0 0 0.
- **3MF**: the core specification's package (content types, the relationship to the model, the model:
  one object, its vertices with the OBJ's numbers and its triangles, one build item; unit millimetre),
  deflated at zlib's level 1 (level 6 took several times as long for a few percent less).
- **GLB** (glTF 2.0 binary): one mesh of one triangle primitive, float32 positions (with their bounds, as
  the format asks) and unit normals (a normal that is not finite is written +z), uint32 indices.
"""

from __future__ import annotations

import json
import zipfile
from typing import BinaryIO

import numpy as np

ROWS = 1 << 18
"""Vertices or faces laid out at a time."""

DIGITS = 9
"""Significant digits of the numbers in an OBJ file."""

_STL_RECORD = np.dtype([("normal", "<f4", 3), ("corners", "<f4", (3, 3)), ("attribute", "<u2")])
_PLY_VERTEX = np.dtype([("position", "<f8", 3), ("normal", "<f4", 3)])
_PLY_FACE = np.dtype([("count", "u1"), ("corners", "<i4", 3)])


def write_stl(f: BinaryIO, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A binary STL of the triangles ``faces`` (rows of ``vertices``) to the open file ``f``."""
    f.write(b"binary STL written by implc".ljust(80))  # never starting with "solid" (ASCII STL's mark)
    f.write(np.array(len(faces), "<u4").tobytes())
    for start in range(0, len(faces), ROWS):
        corners = np.take(vertices, faces[start:start + ROWS], axis=0)  # (n, 3, 3)
        normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
        length = np.sqrt(np.einsum("ij,ij->i", normal, normal))
        with np.errstate(invalid="ignore", divide="ignore"):
            normal /= length[:, None]
        normal[~(length > 0)] = 0.0
        records = np.zeros(len(corners), _STL_RECORD)
        records["normal"], records["corners"] = normal, corners
        f.write(records.tobytes())


def write_ply(f: BinaryIO, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None) -> None:
    """A binary little-endian PLY of the mesh (vertex normals where given) to the open file ``f``."""
    if len(vertices) >= 2**31:
        raise ValueError(f"{len(vertices)} vertices: more than PLY's int32 indices can name")
    lines = ["ply", "format binary_little_endian 1.0", "comment written by implc",
             f"element vertex {len(vertices)}", "property double x", "property double y", "property double z"]
    if normals is not None:
        lines += ["property float nx", "property float ny", "property float nz"]
    lines += [f"element face {len(faces)}", "property list uchar int vertex_indices", "end_header"]
    f.write(("\n".join(lines) + "\n").encode("ascii"))
    for start in range(0, len(vertices), ROWS):
        part = vertices[start:start + ROWS]
        if normals is None:
            f.write(np.ascontiguousarray(part, dtype="<f8").tobytes())
            continue
        records = np.empty(len(part), _PLY_VERTEX)
        records["position"], records["normal"] = part, normals[start:start + ROWS]
        f.write(records.tobytes())
    for start in range(0, len(faces), ROWS):
        part = faces[start:start + ROWS]
        records = np.empty(len(part), _PLY_FACE)
        records["count"], records["corners"] = 3, part
        f.write(records.tobytes())


def write_obj(f: BinaryIO, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None) -> None:
    """An OBJ of the mesh (``vn`` lines and ``a//a`` corners where normals are given) to the open file
    ``f`` (opened in binary mode: the text is ASCII)."""
    f.write(b"# written by implc\n")
    for start in range(0, len(vertices), ROWS):
        f.write(_lines(b"v", _decimals(vertices[start:start + ROWS])))
    if normals is not None:
        for start in range(0, len(normals), ROWS):
            part = np.where(np.isfinite(normals[start:start + ROWS]), normals[start:start + ROWS], 0.0)
            f.write(_lines(b"vn", _decimals(part)))
    width = len(str(len(vertices)))
    for start in range(0, len(faces), ROWS):
        index = _integers(faces[start:start + ROWS] + 1, width, fill="\0")  # (n, 3, width): NULs, then digits
        if normals is not None:  # "a//a": the vertex's own normal
            slashes = np.full((*index.shape[:2], 2), ord("/"), np.uint8)
            index = np.concatenate([index, slashes, index], axis=2)
        f.write(_lines(b"f", index, padded=True))  # the padding taken out: "f 1//1 22//22 333//333"


_CONTENT_TYPES = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Types xmlns="http://schemas.openxmlformats.org/package/2006/content-types">'
    '<Default Extension="rels" ContentType="application/vnd.openxmlformats-package.relationships+xml"/>'
    '<Default Extension="model" ContentType="application/vnd.ms-package.3dmanufacturing-3dmodel+xml"/>'
    "</Types>\n")
_RELATIONSHIPS = (
    '<?xml version="1.0" encoding="UTF-8"?>\n'
    '<Relationships xmlns="http://schemas.openxmlformats.org/package/2006/relationships">'
    '<Relationship Target="/3D/3dmodel.model" Id="rel0" '
    'Type="http://schemas.microsoft.com/3dmanufacturing/2013/01/3dmodel"/></Relationships>\n')
_MODEL_START = (
    b'<?xml version="1.0" encoding="UTF-8"?>\n'
    b'<model unit="millimeter" xml:lang="en-US" xmlns="http://schemas.microsoft.com/3dmanufacturing/core/2015/02">'
    b'<metadata name="Application">implc</metadata>'
    b'<resources><object id="1" type="model"><mesh><vertices>\n')
_MODEL_END = b'</triangles></mesh></object></resources><build><item objectid="1"/></build></model>\n'


def write_3mf(f: BinaryIO, vertices: np.ndarray, faces: np.ndarray) -> None:
    """A 3MF package of the mesh to the open file ``f``."""
    with zipfile.ZipFile(f, "w", zipfile.ZIP_DEFLATED, compresslevel=1) as package:
        package.writestr("[Content_Types].xml", _CONTENT_TYPES)
        package.writestr("_rels/.rels", _RELATIONSHIPS)
        with package.open("3D/3dmodel.model", "w", force_zip64=True) as model:
            model.write(_MODEL_START)
            for start in range(0, len(vertices), ROWS):
                numbers = _decimals(vertices[start:start + ROWS])
                numbers[numbers == ord(" ")] = 0  # a positive number's sign: nothing in XML
                model.write(_records([b'<vertex x="', numbers[:, 0], b'" y="', numbers[:, 1], b'" z="',
                                      numbers[:, 2], b'"/>\n']))
            model.write(b"</vertices><triangles>\n")
            width = len(str(max(len(vertices) - 1, 0)))
            for start in range(0, len(faces), ROWS):
                index = _integers(faces[start:start + ROWS], width, fill="\0")
                model.write(_records([b'<triangle v1="', index[:, 0], b'" v2="', index[:, 1], b'" v3="',
                                      index[:, 2], b'"/>\n']))
            model.write(_MODEL_END)


def write_glb(f: BinaryIO, vertices: np.ndarray, faces: np.ndarray, normals: np.ndarray | None) -> None:
    """A glTF 2.0 binary of the mesh to the open file ``f``."""
    if len(vertices) >= 2**32:
        raise ValueError(f"{len(vertices)} vertices: more than glTF's uint32 indices can name")
    positions = vertices.astype("<f4")
    # the buffer: positions, normals (where given), indices; a view and an accessor each
    sizes = [positions.nbytes] + ([positions.nbytes] if normals is not None else []) + [12 * len(faces)]
    offsets = np.concatenate([[0], np.cumsum(sizes)]).tolist()
    bounds = ({"min": positions.min(axis=0).tolist(), "max": positions.max(axis=0).tolist()} if len(vertices)
              else {"min": [0.0] * 3, "max": [0.0] * 3})
    accessors = [{"componentType": 5126, "count": len(vertices), "type": "VEC3", **bounds}]
    if normals is not None:
        accessors.append({"componentType": 5126, "count": len(vertices), "type": "VEC3"})
    accessors.append({"componentType": 5125, "count": 3 * len(faces), "type": "SCALAR"})
    last = len(accessors) - 1
    attributes = {"POSITION": 0, **({"NORMAL": 1} if normals is not None else {})}
    document = {
        "asset": {"version": "2.0", "generator": "implc"}, "scene": 0, "scenes": [{"nodes": [0]}],
        "nodes": [{"mesh": 0}],
        "meshes": [{"primitives": [{"attributes": attributes, "indices": last, "mode": 4}]}],
        "buffers": [{"byteLength": offsets[-1]}],
        "bufferViews": [{"buffer": 0, "byteOffset": offsets[k], "byteLength": sizes[k],
                         "target": 34963 if k == last else 34962} for k in range(len(sizes))],
        "accessors": [{"bufferView": k, **accessor} for k, accessor in enumerate(accessors)],
    }
    text = json.dumps(document, separators=(",", ":")).encode("ascii")
    text += b" " * (-len(text) % 4)
    binary = offsets[-1] + (-offsets[-1] % 4)
    f.write(np.array([0x46546C67, 2, 12 + 8 + len(text) + 8 + binary], "<u4").tobytes())
    f.write(np.array([len(text), 0x4E4F534A], "<u4").tobytes() + text)
    f.write(np.array([binary, 0x004E4942], "<u4").tobytes())
    f.write(positions.tobytes())
    if normals is not None:
        for start in range(0, len(normals), ROWS):
            part = normals[start:start + ROWS]
            usable = np.isfinite(part).all(axis=1)
            part = np.where(usable[:, None], part, [0.0, 0.0, 1.0]).astype("<f4")
            f.write(part.tobytes())
    for start in range(0, len(faces), ROWS):
        f.write(faces[start:start + ROWS].astype("<u4").tobytes())
    f.write(b"\0" * (binary - offsets[-1]))


def _records(parts: list) -> bytes:
    """Rows of text from ``parts``: byte strings, the same in every row, and (n, w) arrays of ASCII codes,
    side by side; NUL bytes (padding) taken out."""
    n = next(len(part) for part in parts if isinstance(part, np.ndarray))
    widths = [len(part) if isinstance(part, bytes) else part.shape[1] for part in parts]
    rows = np.empty((n, sum(widths)), np.uint8)
    at = 0
    for part, width in zip(parts, widths):  # each part into its columns (np.concatenate was slower)
        rows[:, at:at + width] = np.frombuffer(part, np.uint8) if isinstance(part, bytes) else part
        at += width
    text = rows.reshape(-1)
    return text[text != 0].tobytes()


def _lines(tag: bytes, fields: np.ndarray, padded: bool = False) -> bytes:
    """Lines of ``tag`` followed by each row's fields ((n, k, w) ASCII codes), one space before each;
    ``padded``: the fields' NUL padding taken out. (:func:`_records` for fields of one width: laid out in
    one copy, faster on OBJ's lines.)"""
    n, k, w = fields.shape
    out = np.empty((n, len(tag) + k * (w + 1) + 1), np.uint8)
    out[:, : len(tag)] = np.frombuffer(tag, np.uint8)
    body = out[:, len(tag): -1].reshape(n, k, w + 1)
    body[:, :, 0] = ord(" ")
    body[:, :, 1:] = fields
    out[:, -1] = ord("\n")
    text = out.reshape(-1)
    return (text[text != 0] if padded else text).tobytes()


def _integers(values: np.ndarray, width: int, fill: str = " ") -> np.ndarray:
    """Non-negative integers (below 10^15) as ASCII, right-aligned in ``width`` characters (``fill``
    before them; "0" for leading zeros): (..., width)."""
    return np.moveaxis(_integer_columns(values, width, fill), 0, -1)


def _integer_columns(values: np.ndarray, width: int, fill: str = " ") -> np.ndarray:
    """:func:`_integers` column by column: (width, ...), each column contiguous (built fast, moved once).
    The digits come from doubles, which divide in vectors: floor(q / 10) is exact for an integer q below
    10^15 (the quotient's fractional part, a tenth or more, is far wider than its rounding)."""
    if np.any(np.asarray(values) >= 10**15):
        raise ValueError("an integer of 16 digits or more")
    whole = np.asarray(values, dtype=np.float64)
    out = np.empty((width, *whole.shape), np.uint8)
    for k in range(width):  # column width - 1 - k holds the digit of 10^k
        above = np.floor(whole / 10.0)
        digit = (whole - 10.0 * above).astype(np.uint8) + np.uint8(ord("0"))
        blank = k > 0 and fill != "0"  # no leading zeros: fill before the number
        out[width - 1 - k] = np.where(whole > 0, digit, np.uint8(ord(fill))) if blank else digit
        whole = above
    return out


def _decimals(values: np.ndarray) -> np.ndarray:
    """Finite doubles as ASCII in scientific notation with :data:`DIGITS` significant digits, each in 16
    characters (``-1.23456789e+000``; a positive number starts with a space): (..., 16)."""
    values = np.asarray(values, dtype=np.float64)
    magnitude = np.abs(values)
    zero = magnitude == 0
    with np.errstate(divide="ignore"):
        exponent = np.floor(np.log10(np.where(zero, 1.0, magnitude))).astype(np.int64)
    # the mantissa's digits as one integer: |v| x 10^(DIGITS - 1 - exponent), rounded
    mantissa = _scaled(magnitude, DIGITS - 1 - exponent)
    low, high = 10 ** (DIGITS - 1), 10**DIGITS
    for wrong, step in ((mantissa >= high, 1), ((mantissa < low) & ~zero, -1)):
        # log10 rounded the wrong way, or the rounding carried: one digit too many (too few)
        rows = np.flatnonzero(wrong)
        if len(rows):
            exponent.flat[rows] += step
            mantissa.flat[rows] = _scaled(magnitude.flat[rows], DIGITS - 1 - exponent.flat[rows])
    mantissa = np.minimum(np.where(zero, 0, mantissa), high - 1)
    columns = np.empty((16, *values.shape), np.uint8)
    columns[0] = np.where(np.signbit(values) & ~zero, np.uint8(ord("-")), np.uint8(ord(" ")))
    digits = _integer_columns(mantissa, DIGITS, fill="0")
    columns[1] = digits[0]
    columns[2] = ord(".")
    columns[3: 2 + DIGITS] = digits[1:]
    columns[2 + DIGITS] = ord("e")
    columns[3 + DIGITS] = np.where(exponent < 0, np.uint8(ord("-")), np.uint8(ord("+")))
    columns[4 + DIGITS:] = _integer_columns(np.abs(exponent), 3, fill="0")
    return np.moveaxis(columns, 0, -1)


def _scaled(magnitude: np.ndarray, power: np.ndarray) -> np.ndarray:
    """round(magnitude x 10^power) as int64, the power applied in two halves (each a double of the table)."""
    first = power // 2
    with np.errstate(over="ignore", under="ignore"):
        scaled = magnitude * _TENS[first + _TENS_ZERO] * _TENS[power - first + _TENS_ZERO]
    return np.rint(scaled).astype(np.int64)


_TENS_ZERO = 200
_TENS = 10.0 ** np.arange(-_TENS_ZERO, _TENS_ZERO + 1, dtype=np.float64)
"""10^k for k in [-200, 200] as doubles (the nearest), indexed by k + _TENS_ZERO: a half of any power the
numbers need (doubles reach 10^±308, the mantissa's scaling at most 10^332)."""


def written_coordinates(suffix: str, vertices: np.ndarray) -> np.ndarray:
    """The coordinates a reader gets back from a file of ``suffix``: float32 in STL and GLB, the nine
    written digits in OBJ and 3MF, the doubles themselves in PLY."""
    vertices = np.asarray(vertices, dtype=np.float64)
    if suffix in (".stl", ".glb"):
        with np.errstate(over="ignore"):
            return vertices.astype(np.float32).astype(np.float64)
    if suffix in (".obj", ".3mf") and np.isfinite(vertices).all():
        text = np.ascontiguousarray(_decimals(vertices)).view(f"S{16}").reshape(vertices.shape)
        return text.astype(np.float64)
    return vertices


def precision_problem(suffix: str, vertices: np.ndarray, faces: np.ndarray) -> str | None:
    """Why the mesh, rounded to the format's precision (:func:`written_coordinates`), would not keep its
    promises, or None: a coordinate beyond the format's range, distinct vertices that become one (a reader
    that merges them gets a pinched or non-manifold mesh), a triangle that degenerates or turns over
    (folds, which may intersect their neighbours). Each is checked exactly on the rounded coordinates; a
    mesh that passes has the same topology in the file, its triangles each facing as before."""
    written = written_coordinates(suffix, vertices)
    if written is vertices or np.array_equal(written, vertices):
        return None
    where = {".stl": "float32", ".glb": "float32"}.get(suffix, "nine significant digits")
    if not np.isfinite(written).all():
        return f"a coordinate is beyond the range of {where}, the format's precision: write .ply (doubles)"
    used = np.zeros(len(vertices), bool)
    used[faces.ravel()] = True
    w, v = written[used], np.asarray(vertices, np.float64)[used]
    order = np.lexsort(w.T[::-1])  # equal written rows side by side: one of them differs before rounding
    w, v = w[order], v[order]
    if ((w[1:] == w[:-1]).all(1) & (v[1:] != v[:-1]).any(1)).any():
        return (f"in {where}, the format's precision, distinct vertices would become one (the bounds are far "
                "from the origin for their cells, or tiny): write .ply (doubles)")
    a, b, c = (written[faces[:, k]] for k in range(3))
    normal = np.cross(b - a, c - a)
    oa, ob, oc = (np.asarray(vertices, np.float64)[faces[:, k]] for k in range(3))
    before = np.cross(ob - oa, oc - oa)
    turned = np.einsum("ij,ij->i", normal, before) <= 0
    if turned.any():
        return (f"in {where}, the format's precision, {int(turned.sum())} triangles would degenerate or turn "
                "over: write .ply (doubles)")
    return None
