"""PLY meshes as scans write them: per-vertex colour (bytes or floats, with or without alpha),
polygons of any size, extra vertex and face properties (labels, segments, materials) left alone.

The header is checked against the file before any array is made: a header that claims more vertices
or faces than the file holds, a truncated file, a face that names a vertex the file does not have,
or a coordinate that is not finite, is refused in one line naming the file. Binary files are read
with one ``numpy.frombuffer`` per element where every row has the same size (triangles, quads);
polygons of mixed sizes are read row by row.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

import numpy as np

__all__ = ["PlyError", "PlyMesh", "read_ply"]

_TYPES = {
    "char": "i1",
    "int8": "i1",
    "uchar": "u1",
    "uint8": "u1",
    "short": "i2",
    "int16": "i2",
    "ushort": "u2",
    "uint16": "u2",
    "int": "i4",
    "int32": "i4",
    "uint": "u4",
    "uint32": "u4",
    "float": "f4",
    "float32": "f4",
    "double": "f8",
    "float64": "f8",
}
_FORMATS = {"ascii": None, "binary_little_endian": "<", "binary_big_endian": ">"}
_COLOURS = ("red", "green", "blue")
_INDEX_LISTS = ("vertex_indices", "vertex_index")
_MAX_HEADER = 1 << 20


class PlyError(ValueError):
    """A PLY file that cannot be read as written; the message names the file."""


@dataclass
class _Property:
    name: str
    dtype: str  # numpy type code, without byte order
    count_dtype: str | None = None  # a list property's count type


@dataclass
class _Element:
    name: str
    count: int
    properties: list[_Property]

    def fixed_dtype(self, order: str, list_length: int | None = None) -> np.dtype:
        """The element's row as a structured dtype, a list property holding ``list_length`` items."""
        fields = []
        for p in self.properties:
            if p.count_dtype is None:
                fields.append((p.name, order + p.dtype))
            else:
                if list_length is None:
                    raise ValueError("a list property needs its length")
                fields.append((f"{p.name}__count", order + p.count_dtype))
                fields.append((p.name, order + p.dtype, (list_length,)))
        return np.dtype(fields)


@dataclass
class PlyMesh:
    """A PLY mesh.

    Attributes:
        vertices: (V, 3) float64 positions as the file gives them.
        faces: (F, 3) int64 triangles; a polygon of k corners becomes k - 2 triangles (a fan).
        colors: (V, 3) float32 per-vertex colour in [0, 1] as stored (sRGB-encoded, from bytes
            divided by 255 or floats as given), or None.
        polygon_sizes: the number of faces of each size in the file, e.g. ``{4: 1200}``.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray | None
    polygon_sizes: dict[int, int]


def _header(path: Path, data: bytes) -> tuple[str, list[_Element], int]:
    end = data.find(b"end_header", 0, _MAX_HEADER)
    if not data.startswith(b"ply") or end < 0:
        raise PlyError(f"{path}: not a PLY file (no 'ply' magic and 'end_header' line)")
    newline = data.find(b"\n", end)
    body = newline + 1 if newline >= 0 else len(data)
    lines = data[:end].decode("ascii", errors="replace").splitlines()
    form, elements = None, []
    for number, line in enumerate(lines[1:], start=2):
        words = line.split()
        if not words or words[0] in ("comment", "obj_info"):
            continue
        if words[0] == "format":
            if len(words) < 2 or words[1] not in _FORMATS:
                raise PlyError(f"{path}: header line {number}: unknown format {line!r}")
            form = words[1]
        elif words[0] == "element":
            if len(words) != 3 or not re.fullmatch(r"\d+", words[2]):
                raise PlyError(f"{path}: header line {number}: expected 'element <name> <count>', got {line!r}")
            elements.append(_Element(words[1], int(words[2]), []))
        elif words[0] == "property":
            if not elements:
                raise PlyError(f"{path}: header line {number}: a property before any element")
            if len(words) == 5 and words[1] == "list" and words[2] in _TYPES and words[3] in _TYPES:
                elements[-1].properties.append(_Property(words[4], _TYPES[words[3]], _TYPES[words[2]]))
            elif len(words) == 3 and words[1] in _TYPES:
                elements[-1].properties.append(_Property(words[2], _TYPES[words[1]]))
            else:
                raise PlyError(f"{path}: header line {number}: cannot read property {line!r}")
    if form is None:
        raise PlyError(f"{path}: the header has no 'format' line")
    return form, elements, body


def _element(elements: list[_Element], name: str) -> _Element | None:
    return next((e for e in elements if e.name == name), None)


def _check_vertex(path: Path, vertex: _Element | None) -> None:
    if vertex is None or vertex.count == 0:
        raise PlyError(f"{path}: no vertices")
    names = [p.name for p in vertex.properties]
    missing = [axis for axis in "xyz" if axis not in names]
    if missing:
        raise PlyError(f"{path}: the vertices have no {', '.join(missing)} coordinate")
    if any(p.count_dtype is not None for p in vertex.properties):
        raise PlyError(f"{path}: a vertex list property is not supported")


def _indices_property(path: Path, face: _Element) -> _Property:
    lists = [p for p in face.properties if p.count_dtype is not None]
    named = [p for p in lists if p.name in _INDEX_LISTS]
    if not (named or lists):
        raise PlyError(f"{path}: the faces have no vertex_indices list")
    return (named or lists)[0]


def _binary_elements(path: Path, data: bytes, order: str, elements: list[_Element], start: int) -> dict:
    """Each element's rows as structured arrays (faces: a list of arrays, one per polygon size)."""
    out: dict = {}
    offset = start
    for element in elements:
        lists = [p for p in element.properties if p.count_dtype is not None]
        left = len(data) - offset
        if not lists:
            dtype = element.fixed_dtype(order)
            need = element.count * dtype.itemsize
            if need > left:
                raise PlyError(
                    f"{path}: truncated: the header claims {element.count} {element.name} rows "
                    f"({need} bytes) and the file holds {left} bytes after the header"
                )
            out[element.name] = np.frombuffer(data, dtype, element.count, offset)
            offset += need
            continue
        if len(lists) > 1:
            raise PlyError(f"{path}: element {element.name!r} has more than one list property")
        # the smallest a row can be (a triangle): refuse before reading a count the file cannot hold
        least = element.fixed_dtype(order, 3).itemsize
        if element.count * least > left:
            raise PlyError(
                f"{path}: truncated: the header claims {element.count} {element.name} rows (at least "
                f"{element.count * least} bytes) and the file holds {left} bytes after the header"
            )
        out[element.name], offset = _binary_lists(path, data, order, element, offset)
    return out


def _binary_lists(path: Path, data: bytes, order: str, element: _Element, offset: int) -> tuple[list, int]:
    """Rows of an element with one list property, per polygon size: with one ``frombuffer`` when
    every row has the first row's size, else row by row."""
    listed = next(p for p in element.properties if p.count_dtype is not None)
    prefix = 0  # the list's count sits after the scalar properties before it
    for p in element.properties[: element.properties.index(listed)]:
        prefix += np.dtype(p.dtype).itemsize
    count_type = np.dtype(order + listed.count_dtype)

    def size_at(at: int) -> int:
        if len(data) - at < prefix + count_type.itemsize:
            raise PlyError(f"{path}: truncated: fewer {element.name} rows than the header's {element.count}")
        return int(np.frombuffer(data, count_type, 1, at + prefix)[0])

    first = size_at(offset)
    dtype = element.fixed_dtype(order, first)
    if element.count * dtype.itemsize <= len(data) - offset:
        rows = np.frombuffer(data, dtype, element.count, offset)
        if (rows[f"{listed.name}__count"] == first).all():
            return [rows], offset + element.count * dtype.itemsize
    by_size: dict[int, list] = {}
    for _ in range(element.count):
        dtype = element.fixed_dtype(order, size_at(offset))
        if dtype.itemsize > len(data) - offset:
            raise PlyError(f"{path}: truncated: fewer {element.name} rows than the header's {element.count}")
        by_size.setdefault(dtype, []).append(np.frombuffer(data, dtype, 1, offset))
        offset += dtype.itemsize
    return [np.concatenate(rows) for rows in by_size.values()], offset


def _ascii_elements(path: Path, data: bytes, elements: list[_Element], start: int) -> dict:
    """Each element's values: scalar properties by name (float64 columns), or, for an element
    with a list, its lists per length."""
    lines = [line.split() for line in data[start:].decode("ascii", errors="replace").splitlines()]
    lines = [line for line in lines if line]
    out: dict = {}
    cursor = 0
    for element in elements:
        rows = lines[cursor : cursor + element.count]
        if len(rows) < element.count:
            raise PlyError(
                f"{path}: truncated: the header claims {element.count} {element.name} rows, the file holds {len(rows)}"
            )
        cursor += element.count
        listed = [k for k, p in enumerate(element.properties) if p.count_dtype is not None]
        try:
            if not listed:
                table = np.array(rows, dtype=np.float64)
                if table.ndim != 2 or table.shape[1] != len(element.properties):
                    raise ValueError
                out[element.name] = {p.name: table[:, k] for k, p in enumerate(element.properties)}
                continue
            polygons: dict[int, list] = {}
            for row in rows:
                size = int(row[listed[0]])
                polygons.setdefault(size, []).append([int(v) for v in row[listed[0] + 1 : listed[0] + 1 + size]])
            out[element.name] = {
                size: np.array(values, np.int64).reshape(-1, size) for size, values in polygons.items()
            }
        except ValueError:
            raise PlyError(f"{path}: a {element.name} row does not hold what the header says") from None
    return out


def _fan(polygons: dict[int, np.ndarray]) -> tuple[np.ndarray, dict[int, int]]:
    """Triangles (F, 3) of polygons given per size (n, k): corners (0, i, i + 1)."""
    triangles = []
    for size, corners in sorted(polygons.items()):
        if size < 3:
            continue
        for i in range(1, size - 1):
            triangles.append(corners[:, [0, i, i + 1]])
    sizes = {size: len(corners) for size, corners in sorted(polygons.items())}
    return (np.concatenate(triangles) if triangles else np.zeros((0, 3), np.int64)), sizes


def read_ply(path: str | Path) -> PlyMesh:
    """Read a PLY mesh (ascii or binary, either byte order).

    Raises:
        PlyError: naming the file: not a PLY file, a header the file does not hold (truncated, or
            claiming more rows than its bytes), no vertices or no triangles, a face naming a vertex
            that does not exist, a coordinate that is NaN or infinite.
    """
    path = Path(path)
    data = path.read_bytes()
    form, elements, start = _header(path, data)
    vertex, face = _element(elements, "vertex"), _element(elements, "face")
    _check_vertex(path, vertex)
    if face is None or face.count == 0:
        raise PlyError(f"{path}: no faces: a point cloud, not a mesh")
    indices = _indices_property(path, face)
    if _FORMATS[form] is None:
        parsed = _ascii_elements(path, data, elements, start)
        columns = parsed["vertex"]
        polygons = parsed["face"]
    else:
        parsed = _binary_elements(path, data, _FORMATS[form], elements, start)
        columns = parsed["vertex"]
        polygons = {}
        for rows in parsed["face"]:
            corners = np.asarray(rows[indices.name], np.int64).reshape(len(rows), -1)
            polygons[corners.shape[1]] = corners
    vertices = np.stack([np.asarray(columns[axis], np.float64) for axis in "xyz"], axis=1)
    if not np.isfinite(vertices).all():
        bad = int((~np.isfinite(vertices).all(axis=1)).sum())
        raise PlyError(f"{path}: {bad} vertices have a NaN or infinite coordinate")
    faces, sizes = _fan(polygons)
    if len(faces) == 0:
        raise PlyError(f"{path}: no triangles (every face has fewer than 3 corners)")
    outside = faces[(faces < 0) | (faces >= len(vertices))]
    if len(outside):
        raise PlyError(f"{path}: a face names vertex {int(outside[0])}; the file has {len(vertices)} vertices")
    colors = None
    names = [p.name for p in vertex.properties]
    if all(channel in names for channel in _COLOURS):
        stored = np.stack([np.asarray(columns[c]) for c in _COLOURS], axis=1)
        kinds = {p.dtype for p in vertex.properties if p.name in _COLOURS}
        integer = all(kind[0] in "iu" for kind in kinds)
        colors = (stored.astype(np.float32) / 255.0) if integer else stored.astype(np.float32)
        if not np.isfinite(colors).all():
            raise PlyError(f"{path}: a vertex colour is NaN or infinite")
        colors = np.clip(colors, 0.0, 1.0)
    return PlyMesh(vertices, faces, colors, sizes)
