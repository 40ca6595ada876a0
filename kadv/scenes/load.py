"""``load_scene``: one entry point for every supported scene file."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from kadv.scenes.mitsuba import parse_mitsuba
from kadv.scenes.ply import PlyMesh, read_ply
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene
from kadv.scenes.textures import srgb_to_linear
from kadv.scenes.trimesh_loader import TRIMESH_SUFFIXES, load_mesh_file

__all__ = ["SUPPORTED_SUFFIXES", "load_scene", "ply_part"]

SUPPORTED_SUFFIXES = (".xml", ".ply", *TRIMESH_SUFFIXES)


def load_scene(
    path: str | Path,
    *,
    scale: float = 1.0,
    up_axis: str = "y",
    drop_transparent: bool = True,
    drop_emitters: bool = True,
    missing: str = "error",
    name: str | None = None,
) -> Scene:
    """Load a scene file: Mitsuba ``.xml``; ``.ply`` (with its vertex colours, polygons of any size,
    :mod:`kadv.scenes.ply`); or ``.glb/.gltf/.obj/.off/.stl`` through trimesh.

    Args:
        path: the scene file.
        scale: metres per file unit.
        up_axis: the file's up axis (``"y"`` or ``"z"``); kadv's world is y-up.
        drop_transparent: leave out glass-like materials (they would hide what is behind them).
        drop_emitters: leave out light-source surfaces; their centres become the renderer's lights.
        missing: Mitsuba only: ``"error"`` or ``"skip"`` for referenced files that do not exist.
        name: label for reports; defaults to the folder name for ``scene.xml``, else the file stem.

    Raises:
        FileNotFoundError: the path (or a file it references) does not exist.
        ValueError: unsupported extension, unreadable or empty file, NaN vertices, zero area.
    """
    path = Path(path)
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    if not path.is_file():
        raise ValueError(f"scene path is not a file: {path}")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise ValueError(f"unsupported scene format {suffix!r} for {path}; supported: {', '.join(SUPPORTED_SUFFIXES)}")
    if name is None:
        name = path.parent.name if path.stem == "scene" else path.stem
    options = {"scale": scale, "up_axis": up_axis, "drop_transparent": drop_transparent, "drop_emitters": drop_emitters}
    if suffix == ".xml":
        parts, materials, cameras, lights, emitters = parse_mitsuba(path, missing=missing)
        return assemble_scene(parts, materials, cameras, lights, name=name, emitters=emitters, **options)
    if suffix == ".ply":
        materials = [Material(name)]
        return assemble_scene([ply_part(read_ply(path), 0, str(path))], materials, name=name, **options)
    materials: list[Material] = []
    parts = load_mesh_file(path, materials)
    return assemble_scene(parts, materials, name=name, **options)


def ply_part(mesh: PlyMesh, material: int, name: str) -> MeshPart:
    """A :class:`MeshPart` of a PLY mesh: its vertex colours per corner in linear light (PLY stores
    sRGB-encoded values), shading normals averaged at the vertices, weighted by face area."""
    corners = mesh.vertices[mesh.faces]
    area_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    vertex_normals = np.stack(
        [np.bincount(mesh.faces.ravel(), np.repeat(area_normals[:, k], 3), len(mesh.vertices)) for k in range(3)],
        axis=1,
    )
    vertex_normals /= np.maximum(np.linalg.norm(vertex_normals, axis=1, keepdims=True), 1e-30)
    colors = None if mesh.colors is None else srgb_to_linear(mesh.colors).astype(np.float32)[mesh.faces]
    return MeshPart(mesh.vertices, mesh.faces, None, vertex_normals[mesh.faces], material, name, colors)
