"""The in-memory scene: triangles with per-corner UVs and normals, materials, cameras, lights."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from kadv._renamed import renamed_attribute
from kadv.geometry.camera import Camera
from kadv.scenes.emitters import DEFAULT_LAMP_RADIANCE, Emitters

__all__ = ["CONDUCTOR_GREY", "Material", "MeshPart", "Scene", "assemble_scene", "rotation_to_y_up", "world_from_file"]

# the display grey a metal is shaded with as diffuse, times its reflectance: a mirror is no white wall
CONDUCTOR_GREY = 0.75


@dataclass
class Material:
    """Surface appearance used by the exact renderer.

    Attributes:
        name: material name from the file.
        base_color: (3,) display (sRGB-encoded) colour in [0, 1]; multiplies the texture.
        texture: optional (H, W, 3) float32 image in [0, 1], sRGB as stored, row 0 at v = 1.
        opacity: optional (H, W) float32 alpha mask; texels below 0.5 let rays through.
        uv_scale: (2,) multiplier applied to UVs before the texture lookup.
        transparent: glass-like; dropped at load by default.
        emissive: a light source's own surface; dropped at load by default.
        emission: optional (3,) linear radiance of an emissive surface; None: the default lamp's.
        two_sided: back faces are legitimate surfaces (Mitsuba ``twosided``, glTF ``doubleSided``).
        coat_ior: relative index of refraction of a clear dielectric coat over the diffuse base
            (Mitsuba ``plastic``, ``roughplastic``); None: bare. Only baked lighting reads it.
        coat_nonlinear: the coat's internal scattering deepens the base's colour (Mitsuba's
            ``nonlinear``).
        conductor: a metal (Mitsuba ``conductor``, ``roughconductor``): ``base_color`` is its
            reflectance times :data:`CONDUCTOR_GREY`, the diffuse look it has without reflections.
        roughness: GGX roughness (Mitsuba's ``alpha``) of a coat or a metal (0: smooth), read by
            :attr:`kadv.render.Shading.reflections`.
        mirror: a perfect mirror: the exact render shows what its specular bounce meets, under
            every lighting, tinted by ``base_color``; its depth is its own surface's. The bake and
            the differentiable renderer's gradient see a diffuse surface of ``base_color``.
    """

    name: str
    base_color: np.ndarray = field(default_factory=lambda: np.full(3, 0.5, np.float32))
    texture: np.ndarray | None = None
    opacity: np.ndarray | None = None
    uv_scale: np.ndarray = field(default_factory=lambda: np.ones(2, np.float32))
    transparent: bool = False
    emissive: bool = False
    two_sided: bool = True
    emission: np.ndarray | None = None
    coat_ior: float | None = None
    coat_nonlinear: bool = False
    conductor: bool = False
    roughness: float = 0.0
    mirror: bool = False

    def __post_init__(self) -> None:
        self.base_color = np.clip(np.asarray(self.base_color, np.float32).reshape(3), 0.0, 1.0)
        self.uv_scale = np.asarray(self.uv_scale, np.float32).reshape(2)
        if self.texture is not None:
            texture = np.asarray(self.texture, np.float32)
            if texture.ndim != 3 or texture.shape[2] != 3:
                raise ValueError(f"material {self.name!r}: texture must be (H, W, 3), got {texture.shape}")
            self.texture = texture
        if self.opacity is not None:
            self.opacity = np.asarray(self.opacity, np.float32)
        if self.emission is not None:
            self.emission = np.asarray(self.emission, np.float64).reshape(3)


@dataclass
class MeshPart:
    """One loaded shape before assembly: triangles in world coordinates and a material index.

    Attributes:
        vertices: (V, 3) positions.
        faces: (F, 3) vertex indices.
        uvs: optional (F, 3, 2) per-corner texture coordinates.
        normals: optional (F, 3, 3) per-corner shading normals; face normals when absent.
        material: index into the scene's material list.
        name: where the part came from (file or shape), for error messages.
        colors: optional (F, 3, 3) per-corner linear RGB, the colour a scan captured
            (:attr:`Scene.colors`).
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray | None
    normals: np.ndarray | None
    material: int
    name: str
    colors: np.ndarray | None = None


def _face_normals(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    corners = vertices[faces]
    cross = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    doubled_area = np.linalg.norm(cross, axis=1)
    normals = cross / np.maximum(doubled_area, 1e-30)[:, None]
    return normals, 0.5 * doubled_area


def _emitting_side(triangles: np.ndarray, normals: np.ndarray | None) -> np.ndarray:
    """Emitter triangles (T, 3, 3) wound so that they emit where their normals (T, 3, 3) point, as
    Mitsuba's emitters do (a mirroring transform flips the winding, not the transformed normals)."""
    if normals is None:
        return triangles
    winding = np.cross(triangles[:, 1] - triangles[:, 0], triangles[:, 2] - triangles[:, 0])
    flip = np.einsum("td,td->t", winding, np.nan_to_num(np.asarray(normals, np.float64)).reshape(-1, 3, 3).sum(1)) < 0
    return np.where(flip[:, None, None], triangles[:, [0, 2, 1]], triangles)


@dataclass
class Scene:
    """A triangle scene in kadv's world frame (metres, y up after load-time normalisation).

    Attributes:
        vertices: (V, 3) float64 positions.
        faces: (F, 3) int64 vertex indices.
        uvs: (F, 3, 2) float32 per-corner texture coordinates (zeros where the file has none).
        normals: (F, 3, 3) float32 per-corner unit shading normals.
        material_ids: (F,) int64 index into ``materials`` per triangle.
        materials: the materials.
        cameras: cameras the file defines (may be empty).
        lights: (L, 3) float64 positions of the file's light sources (may be empty): the direct
            shading's lights.
        emitters: the light sources as the lighting bake integrates them (empty: the bake's
            documented defaults).
        name: a label for reports.
        interior: optional (2, 3) box (minimum corner, maximum corner) where cameras belong, for
            scenes that know it (generated rooms, whose windows look onto courtyards); None: the
            bounds.
        colors: optional (F, 3, 3) float32 per-corner linear RGB, the light a scan's sensor
            captured (vertex colours), shown as it is by ``render.lighting=scanned``; NaN on the
            triangles that have none (their material's colour or texel is shown). None: no triangle
            has one.
        captured_by: what says the scene's colour is light a sensor captured, so that
            ``render.lighting=auto`` shows it as scanned: the dataset whose scan layout the file had
            (:mod:`kadv.scenes.scans`), :data:`kadv.scenes.load.UNLIT_GLTF` for a glTF whose
            materials are unlit, or :data:`kadv.scenes.load.CAPTURED` for a file said to be
            captured; None: its colour is a material's, which kadv lights.
        world_T_file: (4, 4) the map from the file's coordinates (file units, its own axes, before a
            dataset's alignment) to kadv's world (metres, y up): the scale, the turn to y-up and any
            alignment (:func:`world_from_file`). Identity for a generated room.
        trajectory: (N, 4, 4) world_T_cam (OpenCV camera) along which the scan was captured, in
            kadv's world (:mod:`kadv.scenes.trajectories`), or None.
        trajectory_source: the file the trajectory was read from.
    """

    vertices: np.ndarray
    faces: np.ndarray
    uvs: np.ndarray
    normals: np.ndarray
    material_ids: np.ndarray
    materials: list[Material]
    cameras: list[Camera] = field(default_factory=list)
    lights: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    name: str = "scene"
    interior: np.ndarray | None = None
    emitters: Emitters = field(default_factory=Emitters)
    colors: np.ndarray | None = None
    captured_by: str | None = None
    world_T_file: np.ndarray = field(default_factory=lambda: np.eye(4))
    trajectory: np.ndarray | None = None
    trajectory_source: str | None = None
    scan = renamed_attribute("captured_by")

    def to_world(self, file_T_cam: np.ndarray) -> np.ndarray:
        """Camera poses (N, 4, 4) in the file's own frame as world_T_cam in kadv's world: the
        rotation turned (not scaled), the centre mapped by :attr:`world_T_file`."""
        scale = np.cbrt(abs(np.linalg.det(self.world_T_file[:3, :3])))
        out = np.array(file_T_cam, np.float64).copy()
        out[:, :3, :3] = self.world_T_file[:3, :3] / scale @ out[:, :3, :3]
        out[:, :3, 3] = out[:, :3, 3] @ self.world_T_file[:3, :3].T + self.world_T_file[:3, 3]
        return out

    def __post_init__(self) -> None:
        self.vertices = np.asarray(self.vertices, np.float64).reshape(-1, 3)
        self.faces = np.asarray(self.faces, np.int64).reshape(-1, 3)
        self.material_ids = np.asarray(self.material_ids, np.int64).reshape(-1)
        self.lights = np.asarray(self.lights, np.float64).reshape(-1, 3)
        n = len(self.faces)
        if n == 0:
            raise ValueError(f"scene {self.name!r}: has no triangles")
        if not np.isfinite(self.vertices).all():
            raise ValueError(f"scene {self.name!r}: vertices contain NaN or inf")
        if self.faces.min() < 0 or self.faces.max() >= len(self.vertices):
            raise ValueError(f"scene {self.name!r}: face indices out of range")
        if self.uvs.shape != (n, 3, 2) or self.normals.shape != (n, 3, 3) or self.material_ids.shape != (n,):
            raise ValueError(f"scene {self.name!r}: per-triangle arrays do not match {n} faces")
        if self.colors is not None:
            self.colors = np.asarray(self.colors, np.float32)
            if self.colors.shape != (n, 3, 3):
                raise ValueError(
                    f"scene {self.name!r}: colours must be (F, 3, 3) per corner, got {self.colors.shape} for {n} faces"
                )
        if self.material_ids.max() >= len(self.materials) or self.material_ids.min() < 0:
            raise ValueError(f"scene {self.name!r}: material ids out of range")
        face_normals, areas = _face_normals(self.vertices, self.faces)
        if float(areas.sum()) <= 1e-12:
            raise ValueError(f"scene {self.name!r}: total surface area is zero (degenerate triangles only)")
        self.face_normals = face_normals.astype(np.float32)
        if self.interior is not None:
            self.interior = np.asarray(self.interior, np.float64)
            if self.interior.shape != (2, 3) or not np.all(self.interior[0] < self.interior[1]):
                raise ValueError(f"scene {self.name!r}: interior must be (2, 3) with min < max, got {self.interior}")

    @property
    def num_triangles(self) -> int:
        return len(self.faces)

    @property
    def bounds(self) -> np.ndarray:
        """(2, 3) axis-aligned bounds: row 0 the minimum corner, row 1 the maximum."""
        return np.stack([self.vertices.min(axis=0), self.vertices.max(axis=0)])

    @property
    def camera_region(self) -> np.ndarray:
        """(2, 3) box that camera samplers draw centres from: the interior if known, else the bounds."""
        return self.interior if self.interior is not None else self.bounds


def rotation_to_y_up(up_axis: str | np.ndarray) -> np.ndarray:
    """Rotation taking the file's up axis to +y (right-handed, no mirroring); a (3, 3) rotation is
    taken as it is (:func:`kadv.scenes.gravity.rotation_onto_y` of an estimated up)."""
    if isinstance(up_axis, np.ndarray):
        return up_axis
    if up_axis == "y":
        return np.eye(3)
    if up_axis == "z":
        return np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])
    raise ValueError(f"up_axis must be 'y', 'z' or 'auto', got {up_axis!r}")


def assemble_scene(
    parts: list[MeshPart],
    materials: list[Material],
    cameras: list[Camera] | None = None,
    lights: np.ndarray | None = None,
    *,
    name: str = "scene",
    scale: float = 1.0,
    up_axis: str | np.ndarray = "y",
    drop_transparent: bool = True,
    drop_emitters: bool = True,
    interior: np.ndarray | None = None,
    emitters: Emitters | None = None,
    captured_by: str | None = None,
) -> Scene:
    """Concatenate mesh parts into a :class:`Scene`, applying the load options.

    Args:
        parts: shapes in file coordinates.
        materials: materials the parts index.
        cameras: file cameras in file coordinates.
        lights: (L, 3) light positions in file coordinates.
        scale: metres per file unit.
        up_axis: the file's up axis, ``"y"`` or ``"z"``, or a (3, 3) rotation; the scene is rotated to y-up.
        drop_transparent: leave out triangles of transparent (glass) materials.
        drop_emitters: leave out light-source surfaces (their centroids become lights and their
            triangles area emitters).
        interior: (2, 3) box where cameras belong, in file coordinates (see :class:`Scene`).
        emitters: the file's other light sources (point, spot, sky, sun), in file coordinates.
        captured_by: what says its colour is captured light (:attr:`Scene.captured_by`).

    Raises:
        ValueError: on NaN/inf coordinates, a non-positive scale, or nothing left to render.
    """
    if not np.isfinite(scale) or scale <= 0:
        raise ValueError(f"scale must be a positive number, got {scale}")
    rotation = rotation_to_y_up(up_axis)
    light_list = [np.asarray(lights, np.float64).reshape(-1, 3)] if lights is not None else []
    emitters = emitters or Emitters()
    kept, emitters = _renderable_parts(name, parts, materials, light_list, emitters, drop_transparent, drop_emitters)
    arrays = _concatenated(kept, coloured=not all(part.colors is None for part in parts))
    vertices = arrays["vertices"] @ rotation.T * scale
    return Scene(
        vertices=vertices,
        faces=arrays["faces"],
        uvs=arrays["uvs"].astype(np.float32),
        normals=_unit_normals(arrays["normals"] @ rotation.T, vertices, arrays["faces"]).astype(np.float32),
        material_ids=arrays["material_ids"],
        materials=materials,
        cameras=[_turned_camera(camera, rotation, scale) for camera in cameras or []],
        lights=(np.concatenate(light_list) if light_list else np.zeros((0, 3))) @ rotation.T * scale,
        name=name,
        interior=None if interior is None else _turned_box(interior, rotation, scale),
        emitters=emitters.transformed(rotation, scale),
        colors=arrays["colors"],
        captured_by=captured_by,
        world_T_file=world_from_file(rotation, scale),
    )


def _renderable_parts(
    name: str,
    parts: list[MeshPart],
    materials: list[Material],
    light_list: list[np.ndarray],
    emitters: Emitters,
    drop_transparent: bool,
    drop_emitters: bool,
) -> tuple[list[tuple[MeshPart, np.ndarray, np.ndarray]], Emitters]:
    """The parts that are rendered, each with its vertices and faces as arrays, and the emitters
    with the emissive parts' surfaces added (their centroids appended to ``light_list``); an error
    naming the scene ``name`` when none is left."""
    kept = []
    for part in parts:
        part_vertices = np.asarray(part.vertices, np.float64)
        if not np.isfinite(part_vertices).all():
            raise ValueError(f"{part.name}: vertices contain NaN or inf")
        material = materials[part.material]
        part_faces = np.asarray(part.faces, np.int64).reshape(-1, 3)
        if len(part_faces) == 0:
            continue
        if material.emissive and drop_emitters:
            light_list.append(part_vertices[np.unique(part_faces)].mean(axis=0, keepdims=True))
            radiance = DEFAULT_LAMP_RADIANCE if material.emission is None else material.emission
            emitters = emitters.area(_emitting_side(part_vertices[part_faces], part.normals), radiance)
            continue
        if material.transparent and drop_transparent:
            continue
        kept.append((part, part_vertices, part_faces))
    if not kept:
        raise ValueError(f"scene {name!r}: no renderable triangles (all parts empty, transparent or emissive)")
    return kept, emitters


def _concatenated(kept: list[tuple[MeshPart, np.ndarray, np.ndarray]], coloured: bool) -> dict[str, np.ndarray | None]:
    """The parts' vertices, faces (indexing the concatenated vertices), per-corner uvs, normals
    (a part without them: its face normals), material ids and, when ``coloured``, per-corner
    colours (float32; NaN: a part without them; else None)."""
    vertices, faces, uvs, normals, material_ids, colors = [], [], [], [], [], []
    offset = 0
    for part, part_vertices, part_faces in kept:
        n = len(part_faces)
        if part.normals is None:
            part_normals = np.repeat(_face_normals(part_vertices, part_faces)[0][:, None], 3, axis=1)
        else:
            part_normals = np.asarray(part.normals, np.float64).reshape(n, 3, 3)
        vertices.append(part_vertices)
        faces.append(part_faces + offset)
        uvs.append(np.zeros((n, 3, 2)) if part.uvs is None else np.asarray(part.uvs).reshape(n, 3, 2))
        normals.append(part_normals)
        material_ids.append(np.full(n, part.material))
        if coloured:
            colors.append(np.full((n, 3, 3), np.nan, np.float32) if part.colors is None else part.colors)
        offset += len(part_vertices)
    names = ("vertices", "faces", "uvs", "normals", "material_ids")
    arrays = {key: np.concatenate(values) for key, values in zip(names, (vertices, faces, uvs, normals, material_ids))}
    arrays["colors"] = np.concatenate(colors).astype(np.float32) if coloured else None
    return arrays


def _unit_normals(normals: np.ndarray, vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """Per-corner normals (F, 3, 3) made unit length; files carry zero or NaN normals on degenerate
    corners, which fall back to the face normal."""
    norm = np.linalg.norm(normals, axis=-1, keepdims=True)
    flat = np.repeat(_face_normals(vertices, faces)[0][:, None], 3, axis=1)
    bad = ~np.isfinite(norm) | (norm < 1e-8)
    return np.where(bad, flat, normals / np.where(bad, 1.0, norm))


def _turned_camera(camera: Camera, rotation: np.ndarray, scale: float) -> Camera:
    """A file camera in kadv's world: turned by ``rotation`` (3, 3), its centre scaled to metres."""
    pose = camera.world_T_cam.numpy().copy()
    pose[:3, :3] = rotation @ pose[:3, :3]
    pose[:3, 3] = rotation @ pose[:3, 3] * scale
    return Camera(pose, camera.fov_x_deg, camera.width, camera.height, camera.name)


def _turned_box(interior: np.ndarray, rotation: np.ndarray, scale: float) -> np.ndarray:
    """(2, 3) the bounds of a box (2, 3) turned and scaled: all eight corners, for any rotation."""
    box = np.asarray(interior, np.float64).reshape(2, 3)
    corners = np.stack(np.meshgrid(*box.T, indexing="ij"), axis=-1).reshape(-1, 3)
    turned = corners @ rotation.T * scale
    return np.stack([turned.min(axis=0), turned.max(axis=0)])


def world_from_file(rotation: np.ndarray, scale: float) -> np.ndarray:
    """(4, 4): a point in file units, turned by ``rotation`` (3, 3) and scaled to metres."""
    out = np.eye(4)
    out[:3, :3] = rotation * scale
    return out
