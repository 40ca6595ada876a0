"""Procedural box rooms: closed rooms with textured furniture boxes, deterministic per seed."""

from __future__ import annotations

import numpy as np
import torch

from kadv.geometry.camera import Camera
from kadv.geometry.pose import look_at
from kadv.scenes.materials import textured_materials
from kadv.scenes.parts import box_parts, room_shell_parts
from kadv.scenes.scene import Scene, assemble_scene

__all__ = ["box_room"]


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
    materials = [floor, ceiling, *walls_paint, *textured_materials(rng, "furniture", num_boxes)]
    W, H, D = width, height, depth
    parts = room_shell_parts((W, H, D), list(range(6)), tile)
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
                parts += box_parts(lo, hi, 6 + index, f"box{index}", tile)
                break
    camera = Camera(
        look_at(torch.tensor(eye), torch.tensor(target)).double(), fov_x_deg, 640, 480, name="box_room_camera"
    )
    light = np.array([[W / 2, H - 0.3, D / 2]])
    return assemble_scene(parts, materials, [camera], light, name=f"box_room_{seed}")
