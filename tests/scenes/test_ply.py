"""PLY meshes as scans write them: vertex colours (bytes or floats, with alpha), quads and polygons,
extra properties, both byte orders and ascii; bad files refused in one line naming the file."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import trimesh

from kadv.scenes import load_scene
from kadv.scenes.ply import PlyError, read_ply
from kadv.scenes.textures import srgb_to_linear

# a unit square and a second square beside it, as two quads, each vertex its own colour
VERTICES = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 0, 0], [2, 1, 0]], np.float32)
BYTES = np.array([[255, 0, 0], [0, 255, 0], [0, 0, 255], [255, 255, 255], [10, 20, 30], [40, 50, 60]], np.uint8)
QUADS = np.array([[0, 1, 2, 3], [1, 4, 5, 2]])


def _binary(order: str, colour: str = "uchar", extra: bool = True) -> bytes:
    """A binary PLY of the two quads; ``colour`` uchar or float; with ``extra``: alpha, a vertex
    label and a face segment (as ScanNet and Matterport write them)."""
    kind = "u1" if colour == "uchar" else order + "f4"
    vertex_fields = [("x", order + "f4"), ("y", order + "f4"), ("z", order + "f4")]
    vertex_fields += [(c, kind) for c in ("red", "green", "blue")]
    vertex_fields += [("alpha", kind), ("label", order + "i4")] if extra else []
    vertex = np.zeros(len(VERTICES), vertex_fields)
    vertex["x"], vertex["y"], vertex["z"] = VERTICES.T
    values = BYTES if colour == "uchar" else BYTES / 255.0
    vertex["red"], vertex["green"], vertex["blue"] = values.T
    face_fields = [("n", "u1"), ("corners", order + "i4", (4,))] + ([("segment", order + "i4")] if extra else [])
    face = np.zeros(len(QUADS), face_fields)
    face["n"], face["corners"] = 4, QUADS
    form = {"<": "binary_little_endian", ">": "binary_big_endian"}[order]
    header = ["ply", f"format {form} 1.0", "comment made by a test", f"element vertex {len(VERTICES)}"]
    header += [f"property float {a}" for a in "xyz"] + [f"property {colour} {c}" for c in ("red", "green", "blue")]
    header += [f"property {colour} alpha", "property int label"] if extra else []
    header += [f"element face {len(QUADS)}", "property list uchar int vertex_indices"]
    header += ["property int segment"] if extra else []
    return ("\n".join([*header, "end_header"]) + "\n").encode() + vertex.tobytes() + face.tobytes()


@pytest.mark.parametrize("order", ["<", ">"])
@pytest.mark.parametrize("colour", ["uchar", "float"])
def test_quads_and_vertex_colours_load_whatever_the_byte_order_colour_type_and_extra_properties(
    tmp_path: Path, order: str, colour: str
) -> None:
    path = tmp_path / "scan.ply"
    path.write_bytes(_binary(order, colour))
    mesh = read_ply(path)
    np.testing.assert_array_equal(mesh.vertices, VERTICES)
    assert mesh.polygon_sizes == {4: 2} and len(mesh.faces) == 4  # each quad a fan of two triangles
    covered = {tuple(sorted(face)) for face in mesh.faces.tolist()}
    assert covered == {(0, 1, 2), (0, 2, 3), (1, 4, 5), (1, 2, 5)}
    np.testing.assert_allclose(mesh.colors, BYTES / 255.0, atol=1e-6)
    scene = load_scene(path)
    # per corner, decoded once from sRGB to linear light
    np.testing.assert_allclose(scene.colors, srgb_to_linear(BYTES / 255.0)[mesh.faces], atol=1e-6)


def test_ascii_polygons_of_mixed_sizes_and_a_file_without_colours(tmp_path: Path) -> None:
    lines = ["ply", "format ascii 1.0", "element vertex 6", "property float x", "property float y"]
    lines += ["property float z", "element face 2", "property list uchar int vertex_index", "end_header"]
    lines += [" ".join(map(str, v)) for v in VERTICES] + ["5 0 1 4 5 3", "3 1 4 5"]
    (tmp_path / "polygons.ply").write_text("\n".join(lines) + "\n")
    mesh = read_ply(tmp_path / "polygons.ply")
    assert mesh.colors is None and mesh.polygon_sizes == {3: 1, 5: 1} and len(mesh.faces) == 1 + 3
    scene = load_scene(tmp_path / "polygons.ply")
    assert scene.colors is None and scene.num_triangles == 4


def test_a_ply_written_by_trimesh_reads_back(tmp_path: Path) -> None:
    box = trimesh.creation.box(extents=(2, 3, 4))
    box.visual.vertex_colors = [200, 100, 50, 255]
    for encoding in ("ascii", "binary"):
        (tmp_path / f"{encoding}.ply").write_bytes(trimesh.exchange.ply.export_ply(box, encoding=encoding))
        mesh = read_ply(tmp_path / f"{encoding}.ply")
        np.testing.assert_allclose(mesh.vertices, box.vertices, atol=1e-6)
        np.testing.assert_array_equal(mesh.faces, box.faces)
        np.testing.assert_allclose(mesh.colors[0], np.array([200, 100, 50]) / 255.0, atol=1e-6)


def _header_claims(data: bytes, count: int) -> bytes:
    return data.replace(b"element vertex 6", f"element vertex {count}".encode(), 1)


POINTS = b"ply\nformat ascii 1.0\nelement vertex 1\nproperty float x\nproperty float y\nproperty float z\n"
SEGMENT = (
    b"ply\nformat ascii 1.0\nelement vertex 2\nproperty float x\nproperty float y\nproperty float z\n"
    b"element face 1\nproperty list uchar int vertex_indices\nend_header\n0 0 0\n1 0 0\n2 0 1\n"
)
BAD_PLY = [
    ("truncated", lambda: _binary("<")[:-7], r"truncated: fewer face rows than the header's 2"),
    (
        "header claims more",
        lambda: _header_claims(_binary("<"), 10**9),
        r"truncated: the header claims 1000000000 vertex rows \(\d+ bytes\) and the file holds \d+ bytes",
    ),
    ("nan vertex", lambda: _binary("<").replace(np.float32(1).tobytes(), np.float32("nan").tobytes(), 1), "NaN"),
    ("no faces", lambda: POINTS + b"end_header\n0 0 0\n", "no faces: a point cloud"),
    ("no triangles", lambda: SEGMENT, "no triangles"),
    (
        "a vertex that is not there",
        lambda: _binary("<").replace(np.int32(5).tobytes(), np.int32(9).tobytes()),
        "a face names vertex 9; the file has 6 vertices",
    ),
    ("not a ply", lambda: b"solid cube\n", "not a PLY file"),
]


@pytest.mark.parametrize("make, message", [b[1:] for b in BAD_PLY], ids=[b[0] for b in BAD_PLY])
def test_a_bad_ply_is_refused_in_one_line_naming_the_file(tmp_path: Path, make, message: str) -> None:
    path = tmp_path / "bad.ply"
    path.write_bytes(make())
    with pytest.raises(PlyError, match=message) as error:
        load_scene(path)
    assert str(error.value).startswith(str(path)) and "\n" not in str(error.value)


def test_gltf_vertex_colours_are_linear_and_obj_ones_srgb(tmp_path: Path) -> None:
    box = trimesh.creation.box()
    box.visual.vertex_colors = np.tile([[10, 200, 30, 255]], (len(box.vertices), 1))
    box.export(tmp_path / "box.glb")  # COLOR_0, normalised bytes: linear values
    box.export(tmp_path / "box.obj")  # "v x y z r g b": display values
    from_gltf, from_obj = load_scene(tmp_path / "box.glb"), load_scene(tmp_path / "box.obj")
    np.testing.assert_allclose(from_gltf.colors[0, 0], np.array([10, 200, 30]) / 255.0, atol=1e-6)
    np.testing.assert_allclose(from_obj.colors[0, 0], srgb_to_linear(np.array([10, 200, 30]) / 255.0), atol=1e-3)
    assert load_scene(tmp_path / "box.obj").colors.shape == (12, 3, 3)
