"""Scan-like rooms: kadv's own generated rooms turned into what a reconstruction gives, written in
the layouts of the field's scan datasets, so that scans can be tested without shipping any.

A scan's colour is the light its sensor captured: here kadv's baked render of the room, stored per
vertex. Its geometry is what a depth-fusion reconstruction leaves: the surfaces re-meshed into
small irregular triangles, surface noise, holes where the sensor saw nothing, missing patches of
ceiling, floating fragments, and a winding that nothing keeps consistent.
"""

from __future__ import annotations

import dataclasses
import struct
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import torch
import trimesh
from scipy.spatial.transform import Rotation

from kadv.geometry import look_at
from kadv.io import atomic_write
from kadv.render import BakeConfig, ExactRenderer, Shading
from kadv.render.exact import pixel_angle
from kadv.scenes.scene import Scene, rotation_to_y_up

__all__ = [
    "SCAN_LAYOUTS",
    "ScanLike",
    "ScanLikeSettings",
    "scan_like",
    "write_arkitscenes",
    "write_matterport",
    "write_replica",
    "write_scan",
    "write_scannet",
    "write_scannetpp",
]

_VIEW_OFFSET = 0.02  # metres off the surface the colour of a vertex is looked at from
_WALL_SIDES = {"x-": (0, 0), "x+": (0, 1), "z-": (2, 0), "z+": (2, 1)}  # side -> (axis, low or high end)
_WALL_REACH = 0.05  # metres from the room's box within which a face belongs to one of its walls


@dataclass(frozen=True)
class ScanLikeSettings:
    """How a room is turned into a scan.

    Attributes:
        edge: the longest triangle edge, metres (a reconstruction's resolution).
        jitter: vertices slid along their surface at random by up to this share of ``edge``
            (irregular triangles).
        noise: standard deviation of the surface noise, metres.
        holes: holes in the walls and the floor, each a disc of missing surface.
        hole_radius: (smallest, largest) radius of a hole, metres.
        ceiling_missing: share of the ceiling left out, in patches (an open room, as Replica's).
        floaters: fragments of surface floating in the room, a few triangles each.
        flip_share: share of triangles whose winding is reversed.
        bake: the baked light the colours are rendered with.
        cut_height: metres above the floor where the scan stops (an operator who swept at chest
            height): everything higher is left out, the ceiling with it; None: the whole room.
        missing_walls: walls left out whole, each named by the side of the room it bounds: ``x-``,
            ``x+``, ``z-``, ``z+`` (kadv's y-up frame).
        capture_views: camera poses along the synthetic path it was "captured" along (a loop
            round the room at chest height, looking in), written in each layout's trajectory format.
    """

    edge: float = 0.1
    jitter: float = 0.25
    noise: float = 0.003
    holes: int = 5
    hole_radius: tuple[float, float] = (0.15, 0.4)
    ceiling_missing: float = 0.3
    floaters: int = 12
    flip_share: float = 0.5
    bake: BakeConfig = dataclasses.field(default_factory=BakeConfig)
    cut_height: float | None = None
    missing_walls: tuple[str, ...] = ()
    capture_views: int = 48

    def __post_init__(self) -> None:
        unknown = sorted(set(self.missing_walls) - set(_WALL_SIDES))
        if unknown:
            raise ValueError(f"missing_walls: no side {', '.join(unknown)}; the sides are {', '.join(_WALL_SIDES)}")


@dataclass
class ScanLike:
    """A scan-like room in kadv's y-up world frame (the writers turn it Z-up).

    Attributes:
        vertices: (V, 3) float64 positions, metres.
        faces: (F, 3) int64 triangles, winding at random.
        colors: (V, 3) uint8 sRGB colour captured at each vertex.
        source: the room it was made from.
        missing_ceiling: (P, 4) the ceiling's missing patches: centre x, y, z and radius, metres.
        trajectory: (N, 4, 4) world_T_cam (OpenCV camera) of the synthetic capture path.
    """

    vertices: np.ndarray
    faces: np.ndarray
    colors: np.ndarray
    source: Scene
    missing_ceiling: np.ndarray
    trajectory: np.ndarray = dataclasses.field(default_factory=lambda: np.zeros((0, 4, 4)))


def _interior(room: Scene) -> np.ndarray:
    """The room's faces that bound its interior: those with a centroid inside ``interior`` (grown by
    a few centimetres), so that a generated room's courtyard and backdrops are left out."""
    box = room.camera_region
    centroids = room.vertices[room.faces].mean(axis=1)
    inside = np.all((centroids >= box[0] - 0.05) & (centroids <= box[1] + 0.05), axis=1)
    return room.faces[inside]


def _ceiling_faces(vertices: np.ndarray, faces: np.ndarray, top: float) -> np.ndarray:
    """(F,) bool: faces in the ceiling's plane (horizontal, within 2 cm of the room's top)."""
    corners = vertices[faces]
    normal = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    horizontal = np.abs(normal[:, 1]) > 0.99 * np.linalg.norm(normal, axis=1)
    return horizontal & (np.abs(corners[:, :, 1].mean(axis=1) - top) < 0.02)


def _captured_colours(room: Scene, points: np.ndarray, normals: np.ndarray, bake: BakeConfig) -> np.ndarray:
    """(V, 3) uint8: the room's baked render at surface points (V, 3), seen along their normals
    (V, 3) from whichever side of the surface the room's free space faces."""
    renderer = ExactRenderer(room, Shading(lighting="baked", bake=bake, reflections=False), progress=False)
    points_t, normals_t = torch.from_numpy(np.array(points)), torch.from_numpy(np.array(normals))
    colour = torch.zeros(len(points), 3, dtype=torch.float32)
    found = torch.zeros(len(points), dtype=torch.bool)
    for side in (1.0, -1.0):
        origins = points_t + side * _VIEW_OFFSET * normals_t
        directions = -side * normals_t
        hits, maps = renderer.cast_and_shade(origins, directions, pixel_angle(torch.eye(3) * 500.0), True, False)
        seen = hits.hit & ~renderer.hidden_side(hits, directions) & ~found
        colour = torch.where(seen[:, None], maps["rgb"].float(), colour)
        found |= seen
    return np.round(colour.numpy() * 255.0).clip(0, 255).astype(np.uint8)


def scan_like(room: Scene, seed: int = 0, settings: ScanLikeSettings | None = None) -> ScanLike:
    """Turn a generated ``room`` (:func:`kadv.box_room`, :func:`kadv.procedural_room`) into a
    scan-like mesh: its interior re-meshed into irregular triangles of at most ``settings.edge``,
    coloured by kadv's baked render, with surface noise, holes, missing ceiling patches, floating
    fragments and random winding, deterministically for ``seed``."""
    settings = settings or ScanLikeSettings()
    rng = np.random.default_rng(seed)
    vertices, faces = trimesh.remesh.subdivide_to_size(room.vertices, _interior(room), max_edge=settings.edge)
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    normals = np.asarray(mesh.vertex_normals, np.float64)
    colours = _captured_colours(room, vertices, normals, settings.bake)
    keep = np.ones(len(faces), bool)
    centroids = vertices[faces].mean(axis=1)
    top = float(room.camera_region[1, 1])
    ceiling = _ceiling_faces(vertices, faces, top)
    # holes in walls and floor: discs around surface points the sensor never saw
    walls = np.flatnonzero(~ceiling)
    for centre in centroids[rng.choice(walls, settings.holes, replace=False)] if len(walls) else []:
        radius = rng.uniform(*settings.hole_radius)
        keep &= np.linalg.norm(centroids - centre, axis=1) > radius
    removed, patches = _ceiling_patches(vertices, faces, centroids, ceiling, settings.ceiling_missing, rng)
    keep &= ~removed
    box = room.camera_region
    if settings.cut_height is not None:  # a sweep at chest height: nothing above it
        keep &= vertices[faces][:, :, 1].max(axis=1) <= box[0, 1] + settings.cut_height
    for side in settings.missing_walls:
        axis, end = _WALL_SIDES[side]
        keep &= np.abs(centroids[:, axis] - box[end, axis]) > _WALL_REACH
    faces = faces[keep]
    # surface noise and irregular triangles: every vertex moved a little
    # irregular triangles: every vertex slid along its surface; then the surface noise across it
    slide = rng.uniform(-1, 1, vertices.shape) * settings.jitter * settings.edge * 0.5
    slide -= np.einsum("vi,vi->v", slide, normals)[:, None] * normals
    vertices = vertices + slide + rng.normal(0.0, settings.noise, vertices.shape)
    # floaters: a few small triangles each, in the room's free space, below the cut
    if settings.cut_height is not None:
        box = box.copy()
        box[1, 1] = min(box[1, 1], box[0, 1] + settings.cut_height)
    if settings.floaters:
        extra_vertices, extra_faces, extra_colours = _floaters(box, settings.floaters, len(vertices), rng)
        vertices = np.concatenate([vertices, extra_vertices])
        faces = np.concatenate([faces, extra_faces])
        colours = np.concatenate([colours, extra_colours])
    flip = rng.uniform(size=len(faces)) < settings.flip_share
    faces = np.where(flip[:, None], faces[:, ::-1], faces)
    if settings.cut_height is not None or settings.missing_walls:  # what was cut away leaves no vertex behind
        used, faces = np.unique(faces, return_inverse=True)
        vertices, colours, faces = vertices[used], colours[used], faces.reshape(-1, 3)
    scan = ScanLike(vertices, faces.astype(np.int64), colours, room, np.array(patches).reshape(-1, 4))
    scan.trajectory = _capture_path(room.camera_region, settings)
    return scan


def _ceiling_patches(
    vertices: np.ndarray, faces: np.ndarray, centroids: np.ndarray, ceiling: np.ndarray, share: float,
    rng: np.random.Generator,
) -> tuple[np.ndarray, list[list[float]]]:  # fmt: skip
    """The ceiling's missing patches: discs around ceiling triangles until ``share`` of the
    ceiling's area is gone; the triangles removed (F,) and each disc's [x, y, z, radius]."""
    patches = []
    area = trimesh.triangles.area(vertices[faces])
    ceiling_area = area[ceiling].sum()
    removed = np.zeros(len(faces), bool)
    while ceiling_area > 0 and area[removed].sum() < share * ceiling_area:
        centre = centroids[rng.choice(np.flatnonzero(ceiling))]
        radius = rng.uniform(0.4, 1.0)
        removed |= ceiling & (np.linalg.norm(centroids - centre, axis=1) < radius)
        patches.append([*centre, radius])
    return removed, patches


def _floaters(box: np.ndarray, count: int, first: int, rng: np.random.Generator) -> tuple[np.ndarray, ...]:
    """``count`` floating fragments in ``box`` (2, 3), two small triangles each: their vertices,
    faces (numbered from vertex ``first``) and uint8 colours."""
    extra_vertices, extra_faces, extra_colours = [], [], []
    for k in range(count):
        centre = rng.uniform(box[0] + 0.3, np.maximum(box[1] - 0.3, box[0] + 0.3))
        corners = centre + rng.normal(0.0, 0.03, (4, 3))
        start = first + 4 * k
        extra_vertices.append(corners)
        extra_faces += [[start, start + 1, start + 2], [start, start + 2, start + 3]]
        extra_colours.append(np.repeat(rng.integers(0, 256, (1, 3)), 4, axis=0))
    colours = np.concatenate([c.astype(np.uint8) for c in extra_colours])
    return np.concatenate(extra_vertices), np.array(extra_faces, np.int64), colours


def _capture_path(box: np.ndarray, settings: ScanLikeSettings) -> np.ndarray:
    """world_T_cam (N, 4, 4): a loop round the room's middle, a quarter of its size in from its
    walls, at chest height (below a cut), each view looking across the room, a little down."""
    centre, half = (box[0] + box[1]) / 2, (box[1] - box[0]) / 2
    height = box[0, 1] + min(1.3, 0.8 * (settings.cut_height or np.inf))
    angle = np.linspace(0.0, 2.0 * np.pi, settings.capture_views, endpoint=False)
    eyes = np.stack([centre[0] + 0.5 * half[0] * np.cos(angle), np.full_like(angle, height),
                     centre[2] + 0.5 * half[2] * np.sin(angle)], axis=1)  # fmt: skip
    targets = np.stack([centre[0] - half[0] * np.cos(angle + 0.6), np.full_like(angle, height - 0.4),
                        centre[2] - half[2] * np.sin(angle + 0.6)], axis=1)  # fmt: skip
    return look_at(torch.from_numpy(eyes), torch.from_numpy(targets)).numpy()


def _file_poses(world_T_cam: np.ndarray, file_T_world: np.ndarray) -> np.ndarray:
    """Camera poses (N, 4, 4) in a layout's file frame (``file_T_world`` rigid)."""
    return file_T_world[None] @ world_T_cam


# kadv's y-up world to the scan layouts' Z-up frame, as a (4, 4) map
_Z_UP_FROM_WORLD = np.eye(4)
_Z_UP_FROM_WORLD[:3, :3] = rotation_to_y_up("z").T


def _z_up(vertices: np.ndarray) -> np.ndarray:
    """kadv's y-up world points (N, 3) in the scan layouts' Z-up frame: the loader's rotation undone."""
    return vertices @ rotation_to_y_up("z")  # its inverse, transposed


def _ply_bytes(vertices: np.ndarray, colours: np.ndarray, polygons: list[np.ndarray], normals=None) -> bytes:
    """A binary little-endian PLY: float x y z (and nx ny nz), uchar red green blue (alpha when
    no normals), faces as lists of int indices, one list per polygon array (n, k)."""
    fields = [("x", "<f4"), ("y", "<f4"), ("z", "<f4")]
    fields += [("nx", "<f4"), ("ny", "<f4"), ("nz", "<f4")] if normals is not None else []
    fields += [("red", "u1"), ("green", "u1"), ("blue", "u1")] + ([("alpha", "u1")] if normals is None else [])
    vertex = np.zeros(len(vertices), fields)
    vertex["x"], vertex["y"], vertex["z"] = vertices.T
    if normals is not None:
        vertex["nx"], vertex["ny"], vertex["nz"] = normals.T
    else:
        vertex["alpha"] = 255
    vertex["red"], vertex["green"], vertex["blue"] = colours.T
    rows = []
    for corners in polygons:
        face = np.zeros(len(corners), [("n", "u1"), ("indices", "<i4", (corners.shape[1],))])
        face["n"], face["indices"] = corners.shape[1], corners
        rows.append(face.tobytes())
    header = ["ply", "format binary_little_endian 1.0", "comment written by kadv.datasets.scan_like"]
    header += [
        f"element vertex {len(vertices)}",
        *(f"property float {name}" for name, _ in fields[: 3 + 3 * (normals is not None)]),
    ]
    header += [f"property uchar {name}" for name, kind in fields if kind == "u1"]
    header += [f"element face {sum(len(p) for p in polygons)}", "property list uchar int vertex_indices", "end_header"]
    return ("\n".join(header) + "\n").encode() + vertex.tobytes() + b"".join(rows)


def write_scannet(
    scan: ScanLike, folder: str | Path, scene: str = "scene0000_00", yaw_deg: float = 30.0, sens: bool = False
) -> Path:
    """ScanNet's layout: ``<scene>/<scene>_vh_clean_2.ply`` (binary, vertex x y z, red green blue
    alpha; triangles) in the sensor's own frame, Z up, metres, and ``<scene>/<scene>.txt`` whose
    ``axisAlignment`` (row-major 4 x 4) maps it into the aligned frame (here: the room's, turned by
    ``yaw_deg`` about z and shifted); the capture path as SensReader exports it, ``pose/<i>.txt``
    (camera-to-world in the sensor's frame), or with ``sens`` as ``<scene>.sens`` (its frames'
    colour and depth a few stand-in bytes each). Returns the mesh's path."""
    folder = Path(folder) / scene
    folder.mkdir(parents=True, exist_ok=True)
    angle = np.radians(yaw_deg)
    alignment = np.eye(4)
    alignment[:3, :3] = [[np.cos(angle), -np.sin(angle), 0], [np.sin(angle), np.cos(angle), 0], [0, 0, 1]]
    alignment[:3, 3] = [0.7, -1.2, 0.0]
    raw = (_z_up(scan.vertices) - alignment[:3, 3]) @ alignment[:3, :3]  # the inverse of the alignment
    mesh = folder / f"{scene}_vh_clean_2.ply"
    data = _ply_bytes(raw, scan.colors, [scan.faces])
    atomic_write(mesh, lambda tmp: tmp.write_bytes(data))
    text = "axisAlignment = " + " ".join(f"{v:.9g}" for v in alignment.ravel()) + "\nsceneType = Living room\n"
    atomic_write(folder / f"{scene}.txt", lambda tmp: tmp.write_text(text))
    poses = _file_poses(scan.trajectory, np.linalg.inv(alignment) @ _Z_UP_FROM_WORLD)
    if sens:
        atomic_write(folder / f"{scene}.sens", lambda tmp: tmp.write_bytes(_sens_bytes(poses)))
    else:
        (folder / "pose").mkdir(exist_ok=True)
        for i, pose in enumerate(poses):
            text = "\n".join(" ".join(f"{v:.9g}" for v in row) for row in pose) + "\n"
            atomic_write(folder / "pose" / f"{i}.txt", lambda tmp, t=text: tmp.write_text(t))
    return mesh


def _sens_bytes(poses: np.ndarray) -> bytes:
    """A ScanNet ``.sens`` (version 4) holding ``poses`` (N, 4, 4), each frame's colour and depth a
    few stand-in bytes (a reader must skip them)."""
    header = struct.pack("<IQ", 4, 6) + b"kadv-s" + struct.pack("<64f", *np.eye(4).ravel().tolist() * 4)
    header += struct.pack("<ii4If", 2, 1, 32, 24, 32, 24, 1000.0) + struct.pack("<Q", len(poses))
    frames = [
        struct.pack("<16f", *pose.ravel().tolist()) + struct.pack("<QQQQ", i, i, 7, 5) + bytes(range(7)) + bytes(5)
        for i, pose in enumerate(poses)
    ]
    return header + b"".join(frames)


def write_arkitscenes(scan: ScanLike, folder: str | Path, video_id: str = "41069025") -> Path:
    """ARKitScenes' layout: ``<video_id>/<video_id>_3dod_mesh.ply`` (binary, vertex x y z, red
    green blue alpha; triangles), Z up, metres, and the capture path as ``lowres_wide.traj`` (per
    line a timestamp, the world-to-camera axis-angle and translation). Returns the mesh's path."""
    folder = Path(folder) / video_id
    folder.mkdir(parents=True, exist_ok=True)
    mesh = folder / f"{video_id}_3dod_mesh.ply"
    data = _ply_bytes(_z_up(scan.vertices), scan.colors, [scan.faces])
    atomic_write(mesh, lambda tmp: tmp.write_bytes(data))
    lines = []
    for i, pose in enumerate(_file_poses(scan.trajectory, _Z_UP_FROM_WORLD)):
        camera_T_world = np.linalg.inv(pose)
        values = [*Rotation.from_matrix(camera_T_world[:3, :3]).as_rotvec(), *camera_T_world[:3, 3]]
        lines.append(f"{1000 + 0.1 * i:.3f} " + " ".join(f"{v:.9g}" for v in values))
    text = "\n".join(lines) + "\n"
    atomic_write(folder / "lowres_wide.traj", lambda tmp: tmp.write_text(text))
    return mesh


def write_scannetpp(scan: ScanLike, folder: str | Path, scene: str = "0a5c013435") -> Path:
    """ScanNet++'s layout: ``<scene>/scans/mesh_aligned_0.05.ply`` (binary, vertex x y z, red green
    blue alpha; triangles), Z up, metres, and the capture path as COLMAP's
    ``<scene>/dslr/colmap/images.txt`` (world-to-camera quaternions and translations). Returns the
    mesh's path."""
    folder = Path(folder) / scene
    (folder / "scans").mkdir(parents=True, exist_ok=True)
    mesh = folder / "scans" / "mesh_aligned_0.05.ply"
    data = _ply_bytes(_z_up(scan.vertices), scan.colors, [scan.faces])
    atomic_write(mesh, lambda tmp: tmp.write_bytes(data))
    lines = ["# Image list with two lines of data per image:"]
    for i, pose in enumerate(_file_poses(scan.trajectory, _Z_UP_FROM_WORLD)):
        camera_T_world = np.linalg.inv(pose)
        x, y, z, w = Rotation.from_matrix(camera_T_world[:3, :3]).as_quat()
        values = " ".join(f"{v:.9g}" for v in (w, x, y, z, *camera_T_world[:3, 3]))
        lines += [f"{i + 1} {values} 1 DSC{i:05d}.JPG", "12.5 20.5 -1"]
    (folder / "dslr" / "colmap").mkdir(parents=True, exist_ok=True)
    text = "\n".join(lines) + "\n"
    atomic_write(folder / "dslr" / "colmap" / "images.txt", lambda tmp: tmp.write_text(text))
    return mesh


def _quads(vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pairs of triangles sharing an edge, in nearly one plane, as quads (Q, 4), and the triangles
    left alone (T, 3): Replica's meshes are made of quads."""
    mesh = trimesh.Trimesh(vertices, faces, process=False)
    used = np.zeros(len(faces), bool)
    quads = []
    normals = mesh.face_normals
    for (a, b), edge in zip(mesh.face_adjacency, mesh.face_adjacency_edges):
        if used[a] or used[b] or abs(float(normals[a] @ normals[b])) < 0.99:
            continue
        apex_a = next(v for v in faces[a] if v not in edge)
        apex_b = next(v for v in faces[b] if v not in edge)
        # a's corners in its own order from its apex, then b's apex between a's two edge corners
        rolled = np.roll(faces[a], -int(np.flatnonzero(faces[a] == apex_a)[0]))
        quads.append([rolled[0], rolled[1], apex_b, rolled[2]])
        used[a] = used[b] = True
    return np.array(quads, np.int64).reshape(-1, 4), faces[~used]


def write_replica(scan: ScanLike, folder: str | Path, name: str = "room_0") -> Path:
    """Replica's layout: ``<name>/mesh.ply`` (binary, vertex x y z, nx ny nz, red green blue;
    quads, and the triangles no quad took), Z up, metres. Returns the mesh's path."""
    folder = Path(folder) / name
    folder.mkdir(parents=True, exist_ok=True)
    vertices = _z_up(scan.vertices)
    quads, triangles = _quads(vertices, scan.faces)
    normals = np.asarray(trimesh.Trimesh(vertices, scan.faces, process=False).vertex_normals)
    data = _ply_bytes(vertices, scan.colors, [quads, triangles], normals=normals)
    mesh = folder / "mesh.ply"
    atomic_write(mesh, lambda tmp: tmp.write_bytes(data))
    return mesh


def write_matterport(
    scan: ScanLike, folder: str | Path, house: str = "1f2e3d4c5b6a79880123456789abcdef", atlas: int = 512
) -> Path:
    """Matterport3D's layout: ``<house>/<house>.obj`` with ``<house>.mtl`` and its texture
    atlases ``<house>_000_00.jpg``, ... (each triangle a small patch of an atlas, the captured
    colours painted in it), Z up, metres. Returns the OBJ's path."""
    from PIL import Image

    folder = Path(folder) / house
    folder.mkdir(parents=True, exist_ok=True)
    cell = 8  # texels per triangle patch side: two triangles share a cell
    per_atlas = (atlas // cell) ** 2 * 2
    vertices = _z_up(scan.vertices)
    obj = [f"mtllib {house}.mtl"] + [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in vertices]
    mtl, uv_lines, face_lines = [], [], []
    u, v = np.meshgrid(np.arange(cell), np.arange(cell), indexing="xy")
    inside_lower = (u + v) <= cell - 1  # the texels of a cell's lower-left triangle
    for start in range(0, len(scan.faces), per_atlas):
        chunk = scan.faces[start : start + per_atlas]
        index = start // per_atlas
        name = f"{house}_{index:03d}_00"
        image = np.zeros((atlas, atlas, 3), np.uint8)
        face_lines.append(f"usemtl {name}")
        for k, face in enumerate(chunk):
            slot, upper = divmod(k, 2)
            row, column = divmod(slot, atlas // cell)
            x0, y0 = column * cell, row * cell
            corners = [(x0, y0), (x0 + cell, y0), (x0, y0 + cell)] if not upper else [
                (x0 + cell, y0 + cell), (x0, y0 + cell), (x0 + cell, y0)
            ]  # fmt: skip
            colours = scan.colors[face].astype(np.float64)
            texels = inside_lower if not upper else ~inside_lower
            weight_1 = (u if not upper else cell - 1 - u) / (cell - 1)
            weight_2 = (v if not upper else cell - 1 - v) / (cell - 1)
            weight_0 = 1.0 - weight_1 - weight_2
            paint = (
                weight_0[..., None] * colours[0] + weight_1[..., None] * colours[1] + weight_2[..., None] * colours[2]
            )
            block = image[y0 : y0 + cell, x0 : x0 + cell]
            block[texels] = np.clip(np.round(paint[texels]), 0, 255).astype(np.uint8)
            first = len(uv_lines) + 1
            uv_lines += [f"vt {cx / atlas:.6f} {1.0 - cy / atlas:.6f}" for cx, cy in corners]
            a, b, c = (int(i) + 1 for i in face)
            face_lines.append(f"f {a}/{first} {b}/{first + 1} {c}/{first + 2}")
        Image.fromarray(image).save(folder / f"{name}.jpg", quality=95)
        mtl += [f"newmtl {name}", "Ka 1 1 1", "Kd 1 1 1", f"map_Kd {name}.jpg", ""]
    atomic_write(folder / f"{house}.mtl", lambda tmp: tmp.write_text("\n".join(mtl)))
    conf = ["dataset matterport", f"n_images {len(scan.trajectory)}"]
    for i, pose in enumerate(_file_poses(scan.trajectory, _Z_UP_FROM_WORLD)):
        gl = pose @ np.diag([1.0, -1.0, -1.0, 1.0])  # OpenGL's camera axes, as Matterport writes them
        conf.append(f"scan d{i}.png i{i}.jpg " + " ".join(f"{v:.9g}" for v in gl.ravel()))
    (folder / "undistorted_camera_parameters").mkdir(exist_ok=True)
    text = "\n".join(conf) + "\n"
    atomic_write(folder / "undistorted_camera_parameters" / f"{house}.conf", lambda tmp: tmp.write_text(text))
    path = folder / f"{house}.obj"
    text = "\n".join([*obj, *uv_lines, *face_lines]) + "\n"
    atomic_write(path, lambda tmp: tmp.write_text(text))
    return path


SCAN_LAYOUTS = {
    "scannet": write_scannet,
    "scannetpp": write_scannetpp,
    "arkitscenes": write_arkitscenes,
    "replica": write_replica,
    "matterport": write_matterport,
}


def write_scan(scan: ScanLike, folder: str | Path, layout: str) -> Path:
    """Write ``scan`` in one of :data:`SCAN_LAYOUTS`' layouts under ``folder``; the mesh's path."""
    if layout not in SCAN_LAYOUTS:
        raise ValueError(f"layout must be one of {', '.join(SCAN_LAYOUTS)}, got {layout!r}")
    return SCAN_LAYOUTS[layout](scan, folder)
