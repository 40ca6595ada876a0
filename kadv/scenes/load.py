"""``load_scene``: one entry point for every supported scene file."""

from __future__ import annotations

import dataclasses
import logging
from pathlib import Path

import numpy as np

from kadv.scenes.gravity import estimate_up, rotation_onto_y
from kadv.scenes.mitsuba import parse_mitsuba
from kadv.scenes.ply import PlyMesh, read_ply
from kadv.scenes.scans import recognise_scan
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene
from kadv.scenes.textures import srgb_to_linear
from kadv.scenes.trajectories import find_captured_path
from kadv.scenes.trimesh_loader import TRIMESH_SUFFIXES, gltf_unlit, load_mesh_file

__all__ = ["CAPTURED", "SUPPORTED_SUFFIXES", "UNLIT_GLTF", "load_scene", "ply_part"]

log = logging.getLogger(__name__)

SUPPORTED_SUFFIXES = (".xml", ".ply", *TRIMESH_SUFFIXES)
# Scene.captured_by of a glTF whose materials are KHR_materials_unlit: captured colour, in glTF's own frame
UNLIT_GLTF = "glTF (KHR_materials_unlit)"
# Scene.captured_by of a file said to be captured (load_scene's captured=True) in no layout kadv knows
CAPTURED = "captured (scene.options.captured=true)"
_UNCAPTURED_COLOUR = (
    "%s: not a scan kadv recognises: its colour is lit as a modelled scene's (render.lighting=auto: baked); if "
    "it is captured light (a photo-textured scan), scene.options.captured=true shows it as captured (scanned)"
)


def load_scene(
    path: str | Path,
    *,
    scale: float | None = None,
    up_axis: str | None = None,
    drop_transparent: bool = True,
    drop_emitters: bool = True,
    missing: str = "error",
    name: str | None = None,
    captured: bool | None = None,
) -> Scene:
    """Load a scene file: Mitsuba ``.xml``; ``.ply`` (with its vertex colours, polygons of any size,
    :mod:`kadv.scenes.ply`); or ``.glb/.gltf/.obj/.off/.stl`` through trimesh.

    Args:
        path: the scene file.
        scale: metres per file unit; None: a recognised scan's (:func:`kadv.scenes.scans.recognise_scan`,
            metres), else 1.
        up_axis: the file's up axis (``"y"`` or ``"z"``), rotated to kadv's y-up world, or
            ``"auto"``: estimated from the mesh (:func:`kadv.scenes.gravity.estimate_up`: its floor
            and dominant planes), for a reconstruction left in its first camera's frame; None: a
            recognised scan's (``"z"``), else ``"y"``. The log says what was chosen for a scan, and
            the angle ``auto`` turned the file.
        drop_transparent: leave out glass-like materials (they would hide what is behind them).
        drop_emitters: leave out light-source surfaces; their centres become the renderer's lights.
        missing: Mitsuba only: ``"error"`` or ``"skip"`` for referenced files that do not exist.
        name: label for reports; defaults to the folder name for ``scene.xml``, else the file stem.
        captured: whether the file's colour is light a sensor captured (a scan, a photo-textured
            reconstruction), to be shown as it is (``render.lighting=auto`` then renders it
            ``scanned``): True or False as said; None: the recognised scan layouts and glTFs whose
            materials are ``KHR_materials_unlit``. The log names the lighting chosen for any other
            textured or coloured file, and how to ask for the other.

    Raises:
        FileNotFoundError: the path (or a file it references) does not exist.
        ValueError: unsupported extension, unreadable or empty file, NaN vertices, zero area.
    """
    path = Path(path)
    suffix = _checked_file(path, captured, up_axis)
    if name is None:
        name = path.parent.name if path.stem == "scene" else path.stem
    layout, scale, up_axis = _scan_layout(path, scale, up_axis)
    captured_by = _captured_as(path, suffix, None if layout is None else layout.dataset, captured)
    options = {"scale": 1.0 if scale is None else scale, "up_axis": up_axis or "y", "captured_by": captured_by}
    options |= {"drop_transparent": drop_transparent, "drop_emitters": drop_emitters}
    if suffix == ".xml":
        parts, materials, cameras, lights, emitters = parse_mitsuba(path, missing=missing)
        options["up_axis"] = _up(parts, options, path)
        return assemble_scene(parts, materials, cameras, lights, name=name, emitters=emitters, **options)
    aligned = layout is not None and layout.alignment is not None and suffix == ".ply"
    parts, materials = _mesh_parts(path, suffix, name, layout.alignment if aligned else None)
    options["up_axis"] = _up(parts, options, path)
    if captured is None and captured_by is None and _coloured(parts, materials):
        log.info(_UNCAPTURED_COLOUR, path)
    scene = assemble_scene(parts, materials, name=name, **options)
    if aligned:
        scene.world_T_file = scene.world_T_file @ layout.alignment  # the file's own frame is before alignment
    return _with_captured_path(scene, path, None if layout is None else layout.dataset)


def _scan_layout(path: Path, scale: float | None, up_axis: str | None) -> tuple:
    """The scan layout the file is in (None: none kadv recognises), and the scale and up axis it
    loads with: those given, else the layout's (said in the log)."""
    layout = recognise_scan(path)
    if layout is None:
        return None, scale, up_axis
    chosen = dataclasses.replace(
        layout,
        up_axis=layout.up_axis if up_axis is None else up_axis,
        scale=layout.scale if scale is None else scale,
    )
    log.info("%s: %s", path, chosen.describe())
    return layout, chosen.scale, chosen.up_axis


def _with_captured_path(scene: Scene, path: Path, dataset: str | None) -> Scene:
    """The scene with the camera poses its capture left beside the file (a scan's trajectory), if any."""
    captured_path = find_captured_path(path, dataset)
    if captured_path is not None:
        scene.trajectory = scene.to_world(captured_path.file_T_cam)
        scene.trajectory_source = str(captured_path.source)
        log.info("%s: %d captured camera poses from %s", path, len(scene.trajectory), captured_path.source)
    return scene


def _checked_file(path: Path, captured, up_axis) -> str:
    """The scene file's lower-case suffix, once the file, its format and the options are checked."""
    if not path.exists():
        raise FileNotFoundError(f"scene file not found: {path}")
    if not path.is_file():
        raise ValueError(f"scene path is not a file: {path}")
    suffix = path.suffix.lower()
    if suffix not in SUPPORTED_SUFFIXES:
        raise ValueError(f"unsupported scene format {suffix!r} for {path}; supported: {', '.join(SUPPORTED_SUFFIXES)}")
    if captured is not None and not isinstance(captured, bool):
        raise ValueError(f"scene.options.captured must be true, false or null, got {captured!r}")
    if up_axis not in (None, "y", "z", "auto"):
        raise ValueError(f"scene.options.up_axis must be y, z or auto, got {up_axis!r}")
    return suffix


def _captured_as(path: Path, suffix: str, dataset: str | None, captured: bool | None) -> str | None:
    """:attr:`Scene.captured_by` of the file: the recognised scan's ``dataset``, as ``captured`` says, or
    an unlit glTF's."""
    if captured is not None:
        return (dataset or CAPTURED) if captured else None
    if dataset is None and suffix in (".glb", ".gltf") and gltf_unlit(path):
        log.info("%s: KHR_materials_unlit: its colour is shown as captured", path)
        return UNLIT_GLTF
    return dataset


def _mesh_parts(path: Path, suffix: str, name: str, alignment: np.ndarray | None) -> tuple[list, list[Material]]:
    """The parts and materials of a mesh file (not Mitsuba's): a PLY's one part (moved by a
    dataset's ``alignment`` into its aligned frame, when it has one), or trimesh's."""
    if suffix == ".ply":
        mesh = read_ply(path)
        if alignment is not None:
            mesh.vertices = mesh.vertices @ alignment[:3, :3].T + alignment[:3, 3]
        return [ply_part(mesh, 0, str(path))], [Material(name)]
    materials: list[Material] = []
    return load_mesh_file(path, materials), materials


def _up(parts: list[MeshPart], options: dict, path: Path) -> str | np.ndarray:
    """The up axis the options name, or for ``auto`` the rotation of the up the mesh implies
    (:func:`kadv.scenes.gravity.estimate_up`), logged with the angle it turns the file."""
    if options["up_axis"] != "auto":
        return options["up_axis"]
    offsets = np.cumsum([0] + [len(p.vertices) for p in parts])
    vertices = np.concatenate([np.asarray(p.vertices, np.float64) for p in parts])
    faces = np.concatenate([np.asarray(p.faces, np.int64).reshape(-1, 3) + o for p, o in zip(parts, offsets)])
    estimate = estimate_up(vertices, faces, options["scale"])
    angle = np.degrees(np.arccos(np.clip(estimate.up[1], -1.0, 1.0)))
    frame = "a Manhattan axis" if estimate.manhattan else "its planes' normals"
    log.info(
        "%s: up_axis=auto: up is %s in the file's frame (%s; floor %.1f m²), %.1f° from its y: turned so",
        path, np.round(estimate.up, 3).tolist(), frame, estimate.floor_area, angle,
    )  # fmt: skip
    return rotation_onto_y(estimate.up)


def _coloured(parts: list[MeshPart], materials: list[Material]) -> bool:
    """Whether a mesh file carries its own colour: a texture or vertex colours."""
    return any(m.texture is not None for m in materials) or any(p.colors is not None for p in parts)


def ply_part(mesh: PlyMesh, material: int, name: str) -> MeshPart:
    """A :class:`MeshPart` of a PLY mesh: its vertex colours per corner in linear light (PLY stores
    sRGB-encoded values), and shading normals that need no consistent winding (a scan's is random):
    at each vertex the principal axis of its faces' normals, weighted by face area, turned to the
    side of their area-weighted sum (where a mesh's winding is consistent, its outside)."""
    corners = mesh.vertices[mesh.faces]
    area_normals = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    area = np.linalg.norm(area_normals, axis=1)
    unit = area_normals / np.maximum(area, 1e-30)[:, None]

    def at_vertices(values: np.ndarray) -> np.ndarray:
        return np.bincount(mesh.faces.ravel(), np.repeat(values, 3), len(mesh.vertices))

    tensor = np.empty((len(mesh.vertices), 3, 3))
    for i, j in ((0, 0), (0, 1), (0, 2), (1, 1), (1, 2), (2, 2)):
        tensor[:, i, j] = tensor[:, j, i] = at_vertices(area * unit[:, i] * unit[:, j])
    vertex_normals = np.linalg.eigh(tensor)[1][..., -1]  # the largest eigenvalue's unit eigenvector
    summed = np.stack([at_vertices(area_normals[:, k]) for k in range(3)], axis=1)
    vertex_normals *= np.where((vertex_normals * summed).sum(axis=1) < 0, -1.0, 1.0)[:, None]
    colors = None if mesh.colors is None else srgb_to_linear(mesh.colors).astype(np.float32)[mesh.faces]
    return MeshPart(mesh.vertices, mesh.faces, None, vertex_normals[mesh.faces], material, name, colors)
