"""Meshes through trimesh (glTF/GLB, OBJ+MTL, OFF, STL), keeping every material, texture and
vertex colour."""

from __future__ import annotations

import json
import struct
from pathlib import Path

import numpy as np
import trimesh

from kadv.scenes.scene import Material, MeshPart
from kadv.scenes.textures import image_to_rgba, linear_to_srgb, srgb_to_linear

__all__ = ["TRIMESH_SUFFIXES", "load_mesh_file", "mesh_parts"]

TRIMESH_SUFFIXES = (".glb", ".gltf", ".obj", ".off", ".stl")


def _material_from_visual(visual: object, fallback_name: str) -> Material:
    material = getattr(visual, "material", None)
    if material is None:  # ColorVisuals: per-vertex/face colours, keep their mean
        colors = getattr(visual, "face_colors", None)
        color = np.asarray(colors, np.float32)[:, :3].mean(axis=0) / 255.0 if colors is not None else np.full(3, 0.5)
        return Material(fallback_name, base_color=color)
    name = getattr(material, "name", None) or fallback_name
    if isinstance(material, trimesh.visual.material.PBRMaterial):
        factor = material.baseColorFactor
        factor = np.ones(4) if factor is None else np.asarray(factor, np.float64)
        factor = factor / 255.0 if factor.max() > 1.0 else factor
        texture, alpha = (None, None)
        if material.baseColorTexture is not None:
            texture, alpha = image_to_rgba(material.baseColorTexture)
        mode = (material.alphaMode or "OPAQUE").upper()
        opacity = alpha if (mode == "MASK" and alpha is not None) else None
        transparent = mode == "BLEND" and float(factor[3]) < 0.99 if len(factor) > 3 else False
        emissive_factor = np.asarray(material.emissiveFactor if material.emissiveFactor is not None else [0, 0, 0])
        # A glTF surface both emissive and black is a light fixture's emitting face.
        emissive = bool(emissive_factor.max() > 0) and texture is None and float(factor[:3].max()) < 1e-3
        return Material(
            name,
            base_color=linear_to_srgb(factor[:3]),  # glTF factors are linear, textures sRGB
            texture=texture,
            opacity=opacity,
            transparent=transparent,
            emissive=emissive,
            two_sided=bool(material.doubleSided),
        )
    diffuse = np.asarray(getattr(material, "diffuse", [128, 128, 128, 255]), np.float64) / 255.0
    image = getattr(material, "image", None)
    texture, alpha = image_to_rgba(image) if image is not None else (None, None)
    return Material(name, base_color=diffuse[:3] if texture is None else np.ones(3), texture=texture, opacity=alpha)


def mesh_parts(
    mesh: trimesh.Trimesh,
    transform: np.ndarray,
    material_index: int,
    name: str,
    flat_normals: bool = False,
    linear_colours: bool = False,
) -> MeshPart:
    """Convert one trimesh mesh (in its own frame) to a world-frame :class:`MeshPart`; its vertex
    colours, if any, per corner in linear light (``linear_colours``: stored linear, as glTF's
    ``COLOR_0`` is; else sRGB-encoded, as OBJ and OFF colours are)."""
    faces = np.asarray(mesh.faces, np.int64)
    vertices_h = np.c_[np.asarray(mesh.vertices, np.float64), np.ones(len(mesh.vertices))]
    vertices = (vertices_h @ np.asarray(transform, np.float64).T)[:, :3]
    uv = getattr(mesh.visual, "uv", None)
    uvs = None if uv is None or len(uv) != len(mesh.vertices) else np.asarray(uv, np.float64)[faces]
    normals = None
    if not flat_normals and len(faces):
        normal_matrix = np.linalg.inv(np.asarray(transform, np.float64)[:3, :3]).T
        with np.errstate(invalid="ignore", divide="ignore"):
            normals = (np.asarray(mesh.vertex_normals, np.float64) @ normal_matrix.T)[faces]
    colors = None
    if getattr(mesh.visual, "kind", None) == "vertex" and len(faces):
        stored = np.asarray(mesh.visual.vertex_colors, np.float64)[:, :3] / 255.0
        colors = (stored if linear_colours else srgb_to_linear(stored)).astype(np.float32)[faces]
    elif (untextured := _untextured_vertex_colours(mesh)) is not None and len(faces):
        # glTF's COLOR_0 beside a material without a texture: the vertex colour times the base colour
        colors = untextured.astype(np.float32)[faces]
    return MeshPart(vertices, faces, uvs, normals, material_index, name, colors)


def _untextured_vertex_colours(mesh: trimesh.Trimesh) -> np.ndarray | None:
    """(V, 3) linear colours of a glTF mesh whose material has no texture but whose vertices carry
    ``COLOR_0`` (trimesh keeps them apart from its material), times the base colour; else None."""
    attributes = getattr(mesh.visual, "vertex_attributes", None)
    material = getattr(mesh.visual, "material", None)
    stored = None if attributes is None else attributes.get("color")
    if stored is None or getattr(material, "baseColorTexture", None) is not None:
        return None
    factor = getattr(material, "baseColorFactor", None)
    factor = np.ones(3) if factor is None else np.asarray(factor, np.float64)[:3] / 255.0
    return np.asarray(stored, np.float64)[:, :3] / 255.0 * factor


def _gltf_json(path: Path) -> dict:
    """A glTF's JSON (a .gltf file, or a .glb's first chunk); {} where it cannot be read (trimesh
    then says what is wrong)."""
    try:
        if path.suffix.lower() == ".gltf":
            return json.loads(path.read_text())
        with open(path, "rb") as file:
            header = file.read(20)
            if len(header) < 20 or header[:4] != b"glTF":
                return {}
            return json.loads(file.read(struct.unpack("<I", header[12:16])[0]))
    except (OSError, ValueError):
        return {}


def gltf_unlit(path: Path) -> bool:
    """Whether a glTF's materials are ``KHR_materials_unlit``: colour meant to be shown as it is
    (Habitat's and scan exporters' convention for captured colour), not lit again."""
    gltf = _gltf_json(path)
    return any("KHR_materials_unlit" in m.get("extensions", {}) for m in gltf.get("materials", []))


def _refuse_miscounted_colours(path: Path, gltf: dict) -> None:
    """A glTF primitive whose ``COLOR_0`` holds another count than its ``POSITION``: refused in one
    line naming the mesh (trimesh would drop the colours and show the mesh uncoloured)."""
    accessors = gltf.get("accessors", [])
    for index, mesh in enumerate(gltf.get("meshes", [])):
        for primitive in mesh.get("primitives", []):
            attributes = primitive.get("attributes", {})
            if "COLOR_0" not in attributes or "POSITION" not in attributes:
                continue
            try:
                colours, vertices = (accessors[attributes[k]]["count"] for k in ("COLOR_0", "POSITION"))
            except (IndexError, KeyError, TypeError):
                continue  # trimesh says what is wrong with the accessors
            if colours != vertices:
                name = mesh.get("name") or f"mesh {index}"
                raise ValueError(f"{path}: {name!r} has {colours} COLOR_0 colours for {vertices} vertices")


def _refuse_basis_textures(path: Path, gltf: dict) -> None:
    """A glTF whose textures are Basis Universal (HM3D's ``.basis.glb``, ``KHR_texture_basisu``),
    which no decoder here reads: refused in one line naming the texture, not shown untextured."""
    for index, image in enumerate(gltf.get("images", [])):
        name = image.get("name") or image.get("uri") or f"image {index}"
        if image.get("mimeType") in ("image/ktx2", "image/basis") or str(image.get("uri", "")).endswith(
            (".ktx2", ".basis")
        ):
            raise ValueError(
                f"{path}: texture {name!r} is Basis Universal ({image.get('mimeType') or image.get('uri')}), which "
                "kadv cannot decode; load the dataset's OBJ/JPG variant of this scan instead"
            )
    if "KHR_texture_basisu" in gltf.get("extensionsRequired", []) + gltf.get("extensionsUsed", []):
        raise ValueError(
            f"{path}: its textures are Basis Universal (KHR_texture_basisu), which kadv cannot decode; load the "
            "dataset's OBJ/JPG variant of this scan instead"
        )


def _refuse_missing_obj_textures(path: Path) -> None:
    """An OBJ whose material library, or a texture it names (``map_Kd``, Matterport's and 3RScan's
    atlases), is not on disk: refused in one line naming both, not shown in flat colours."""
    text = path.read_text(errors="replace")
    for line in text.splitlines():
        if not line.startswith("mtllib "):
            continue
        library = path.parent / line.split(maxsplit=1)[1].strip()
        if not library.is_file():
            raise ValueError(f"{path}: its material library {library.name!r} is missing ({library})")
        material = None
        for entry in library.read_text(errors="replace").splitlines():
            words = entry.split()
            if words[:1] == ["newmtl"] and len(words) > 1:
                material = words[1]
            elif words[:1] == ["map_Kd"] and len(words) > 1:
                texture = library.parent / words[-1]  # the file name is last, after any options
                if not texture.is_file():
                    raise ValueError(
                        f"{path}: the texture {words[-1]!r} of material {material!r} in {library.name} is missing "
                        f"({texture})"
                    )


def load_mesh_file(path: Path, materials: list[Material]) -> list[MeshPart]:
    """Load every mesh of a trimesh-readable file as parts, appending its materials to ``materials``.

    Raises:
        ValueError: if the file holds no triangle mesh, cannot be parsed, lacks a texture it names
            (OBJ), or has textures kadv cannot decode (Basis Universal).
    """
    if path.suffix.lower() in (".glb", ".gltf"):
        gltf = _gltf_json(path)
        _refuse_basis_textures(path, gltf)
        _refuse_miscounted_colours(path, gltf)
    if path.suffix.lower() == ".obj":
        _refuse_missing_obj_textures(path)
    try:
        loaded = trimesh.load(str(path), force="scene", process=False)
    except Exception as error:  # trimesh raises many kinds on malformed files
        raise ValueError(f"{path}: could not be read as a mesh ({type(error).__name__}: {error})") from error
    parts: list[MeshPart] = []
    known: dict[int, int] = {}
    for node in loaded.graph.nodes_geometry:
        transform, geometry_name = loaded.graph[node]
        mesh = loaded.geometry[geometry_name]
        if not isinstance(mesh, trimesh.Trimesh) or len(mesh.faces) == 0:
            continue
        key = id(getattr(mesh.visual, "material", mesh.visual))
        if key not in known:
            known[key] = len(materials)
            materials.append(_material_from_visual(mesh.visual, str(geometry_name)))
        linear = path.suffix.lower() in (".glb", ".gltf")
        parts.append(mesh_parts(mesh, transform, known[key], f"{path}:{geometry_name}", linear_colours=linear))
    if not parts:
        raise ValueError(f"{path}: contains no triangle mesh")
    return parts
