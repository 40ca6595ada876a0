"""Procedural box rooms: closed rooms with textured furniture boxes, deterministic per seed."""
from __future__ import annotations

import numpy as np
import skimage.data
import torch

from kadv.geometry.camera import Camera
from kadv.geometry.pose import look_at
from kadv.scenes.scene import Material, MeshPart, Scene, assemble_scene

__all__ = ["box_room", "quad_part", "textured_materials"]

_GREY_IMAGES = ("brick", "grass", "gravel", "camera", "moon")
_COLOUR_IMAGES = ("coffee", "chelsea", "astronaut", "immunohistochemistry", "rocket")


def _downsample(image: np.ndarray, size: int = 256) -> np.ndarray:
    step = max(1, min(image.shape[:2]) // size)
    return image[::step, ::step]


def _photo(rng: np.random.Generator) -> np.ndarray:
    return _downsample(getattr(skimage.data, _COLOUR_IMAGES[rng.integers(len(_COLOUR_IMAGES))])())[..., :3] / 255.0


def _grey_photo(rng: np.random.Generator, tint: np.ndarray, contrast: float) -> np.ndarray:
    grey = _downsample(getattr(skimage.data, _GREY_IMAGES[rng.integers(len(_GREY_IMAGES))])()) / 255.0
    return (1.0 - contrast + contrast * grey[:, :, None]) * tint


def _checker(rng: np.random.Generator, tint: np.ndarray) -> np.ndarray:
    cells = int(rng.integers(2, 9))
    board = (np.indices((64, 64)).sum(axis=0) // (64 // cells)) % 2
    return np.where(board[:, :, None] == 0, tint, rng.uniform(0.1, 0.9, size=3))


def _stripes(rng: np.random.Generator, tint: np.ndarray) -> np.ndarray:
    phase = np.linspace(0, 2 * np.pi * int(rng.integers(2, 8)), 64)
    stripes = 0.5 + 0.5 * np.sin(phase)[None, :, None]
    return np.broadcast_to(stripes * tint + (1 - stripes) * tint[::-1] * 0.5, (64, 64, 3))


def textured_materials(rng: np.random.Generator, role: str, count: int) -> list[Material]:
    """Random materials for a surface role, as interiors tend to have them.

    Roles: "paint" (walls, ceiling: a tint with a low-contrast grain), "floor" (planks, tiles,
    carpet-like grain) and "furniture" (anything, including photographs and bold patterns).
    """
    materials = []
    for index in range(count):
        tint = rng.uniform(0.35, 1.0, size=3)
        if role == "paint":
            texture = _grey_photo(rng, tint, contrast=rng.uniform(0.05, 0.25))
        elif role == "floor":
            kind = rng.integers(3)
            texture = (_stripes(rng, tint) if kind == 0 else _checker(rng, tint) if kind == 1
                       else _grey_photo(rng, tint, contrast=rng.uniform(0.3, 0.8)))
        elif role == "furniture":
            kind = rng.integers(4)
            texture = (_grey_photo(rng, tint, 1.0), _photo(rng), _checker(rng, tint), _stripes(rng, tint))[kind]
        else:
            raise ValueError(f"unknown material role {role!r}")
        materials.append(Material(f"{role}{index}", base_color=np.ones(3), texture=np.clip(texture, 0, 1)))
    return materials


def quad_part(corners: np.ndarray, material: int, name: str, uv_extent: tuple[float, float] = (1.0, 1.0)) -> MeshPart:
    """Two triangles of the quad ``corners`` (4, 3), UVs spanning ``uv_extent``.

    The front face's normal is (c3 - c0) x (c1 - c0); corner 0 has uv (0, 0), corner 1 (u, 0).
    """
    u, v = uv_extent
    uv = np.array([[0, 0], [u, 0], [u, v], [0, v]], np.float64)
    faces = np.array([[0, 2, 1], [0, 3, 2]])
    return MeshPart(np.asarray(corners, np.float64), faces, uv[faces], None, material, name)


def _overlapped(corners: np.ndarray, margin: float = 1e-3) -> np.ndarray:
    """Grow a quad by ``margin`` past its edges: faces that merely touch leave float cracks rays slip through."""
    u = corners[1] - corners[0]
    v = corners[3] - corners[0]
    u_hat, v_hat = u / np.linalg.norm(u), v / np.linalg.norm(v)
    signs = np.array([[-1, -1], [1, -1], [1, 1], [-1, 1]], np.float64)
    return corners + margin * (signs[:, :1] * u_hat + signs[:, 1:] * v_hat)


def _box_parts(lo: np.ndarray, hi: np.ndarray, material: int, name: str, tile: float) -> list[MeshPart]:
    x0, y0, z0 = lo
    x1, y1, z1 = hi
    c = lambda x, y, z: [x, y, z]  # noqa: E731
    faces = [
        [c(x0, y0, z0), c(x1, y0, z0), c(x1, y1, z0), c(x0, y1, z0)],
        [c(x1, y0, z1), c(x0, y0, z1), c(x0, y1, z1), c(x1, y1, z1)],
        [c(x0, y0, z1), c(x0, y0, z0), c(x0, y1, z0), c(x0, y1, z1)],
        [c(x1, y0, z0), c(x1, y0, z1), c(x1, y1, z1), c(x1, y1, z0)],
        [c(x0, y1, z0), c(x1, y1, z0), c(x1, y1, z1), c(x0, y1, z1)],
        [c(x0, y0, z1), c(x1, y0, z1), c(x1, y0, z0), c(x0, y0, z0)],
    ]
    parts = []
    for index, corners in enumerate(np.array(faces, np.float64)):
        corners = _overlapped(corners)
        extent = (np.linalg.norm(corners[1] - corners[0]) / tile, np.linalg.norm(corners[3] - corners[0]) / tile)
        parts.append(quad_part(corners, material, f"{name}.face{index}", extent))
    return parts


def box_room(
    seed: int = 0,
    size: tuple[float, float, float] | None = None,
    num_boxes: int = 4,
    tile: float = 1.0,
    fov_x_deg: float = 70.0,
) -> Scene:
    """A closed room (floor, ceiling, four walls) with random furniture boxes.

    Walls face into the room and boxes outwards, so a back face seen from a camera means the camera
    is outside the room or inside a box.

    The room spans x in [0, W], y in [0, H] (y up, floor at 0) and z in [0, D]. The file camera
    stands 1.5 m high near the corner (0, 0) looking across the room, at least 1 m from every box.

    Args:
        seed: the random seed; the same seed gives the same room, bit for bit.
        size: (W, H, D) in metres; random (3.5-7 x 2.5-3.2 x 3.5-7) when None.
        num_boxes: furniture boxes to place (fewer if they do not fit).
        tile: metres per texture repeat.
        fov_x_deg: the file camera's horizontal field of view.
    """
    rng = np.random.default_rng(seed)
    if size is None:
        size = (rng.uniform(3.5, 7.0), rng.uniform(2.5, 3.2), rng.uniform(3.5, 7.0))
    width, height, depth = (float(v) for v in size)
    if min(width, height, depth) < 2.0:
        raise ValueError(f"box_room: every side must be >= 2 m, got {size}")
    floor, ceiling = textured_materials(rng, "floor", 1) + textured_materials(rng, "paint", 1)
    paint = textured_materials(rng, "paint", 2)  # most walls share one paint, an accent wall may differ
    walls_paint = [paint[int(rng.random() < 0.25)] for _ in range(4)]
    materials = [floor, ceiling, *walls_paint] + textured_materials(rng, "furniture", num_boxes)
    W, H, D = width, height, depth
    walls = {
        "floor": [[0, 0, 0], [W, 0, 0], [W, 0, D], [0, 0, D]],
        "ceiling": [[0, H, D], [W, H, D], [W, H, 0], [0, H, 0]],
        "wall_z0": [[W, 0, 0], [0, 0, 0], [0, H, 0], [W, H, 0]],
        "wall_z1": [[0, 0, D], [W, 0, D], [W, H, D], [0, H, D]],
        "wall_x0": [[0, 0, 0], [0, 0, D], [0, H, D], [0, H, 0]],
        "wall_x1": [[W, 0, D], [W, 0, 0], [W, H, 0], [W, H, D]],
    }
    parts = []
    for index, (name, corners) in enumerate(walls.items()):
        corners = _overlapped(np.array(corners, np.float64))
        extent = (np.linalg.norm(corners[1] - corners[0]) / tile, np.linalg.norm(corners[3] - corners[0]) / tile)
        parts.append(quad_part(corners, index, name, extent))
    eye = np.array([min(1.0, W / 4), 1.5, min(1.0, D / 4)])
    target = np.array([W * 0.65, 1.0, D * 0.65])
    placed: list[tuple[np.ndarray, np.ndarray]] = []
    for index in range(num_boxes):
        for _ in range(50):
            extent = rng.uniform([0.3, 0.3, 0.3], [min(1.2, W / 3), min(1.5, H / 2), min(1.2, D / 3)])
            lo = np.array([rng.uniform(0.1, W - extent[0] - 0.1), 0.0, rng.uniform(0.1, D - extent[2] - 0.1)])
            hi = lo + extent
            gap = np.maximum(np.maximum(lo - eye, eye - hi), 0.0)
            apart = all(np.any(lo >= b_hi + 0.1) or np.any(hi <= b_lo - 0.1) for b_lo, b_hi in placed)
            if np.linalg.norm(gap) >= 1.0 and apart:
                placed.append((lo, hi))
                parts += _box_parts(lo, hi, 6 + index, f"box{index}", tile)
                break
    camera = Camera(
        look_at(torch.tensor(eye), torch.tensor(target)).double(), fov_x_deg, 640, 480, name="box_room_camera"
    )
    light = np.array([[W / 2, H - 0.3, D / 2]])
    return assemble_scene(parts, materials, [camera], light, name=f"box_room_{seed}")
