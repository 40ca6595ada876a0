"""Turning config nodes into library objects (the edge where Hydra meets the library)."""
from __future__ import annotations

import os

# torch's OpenMP threads spin after each op and steal cores from Embree's ray casting.
os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")

from pathlib import Path  # noqa: E402

import torch  # noqa: E402
from omegaconf import DictConfig, OmegaConf  # noqa: E402

from kadv.geometry import look_at  # noqa: E402
from kadv.render import Shading  # noqa: E402
from kadv.scenes import Scene, box_room, load_scene  # noqa: E402

__all__ = ["camera_from_config", "scene_from_config", "shading_from_config"]


def scene_from_config(cfg: DictConfig) -> Scene:
    """Build the scene a ``scene/`` config node describes (``kind: box_room`` or ``kind: file``)."""
    if cfg.kind == "box_room":
        return box_room(seed=int(cfg.seed), num_boxes=int(cfg.num_boxes))
    if cfg.kind == "file":
        options = OmegaConf.to_container(cfg.get("options") or {}, resolve=True)
        return load_scene(Path(cfg.path).expanduser(), **options)
    raise ValueError(f"scene.kind must be 'box_room' or 'file', got {cfg.kind!r}")


def shading_from_config(cfg: DictConfig) -> Shading:
    lights = cfg.get("lights")
    return Shading(
        ambient=float(cfg.ambient),
        diffuse=float(cfg.diffuse),
        lights=None if lights is None else tuple(tuple(float(v) for v in light) for light in lights),
        background=tuple(float(v) for v in cfg.background),
    )


def camera_from_config(cfg: DictConfig, scene: Scene) -> tuple[torch.Tensor, float]:
    """(world_T_cam (4, 4), fov_x_deg) from an explicit pose, a look-at, or a file camera index."""
    fov = cfg.get("fov_x_deg")
    if cfg.get("world_T_cam") is not None:
        pose = torch.tensor(OmegaConf.to_container(cfg.world_T_cam), dtype=torch.float64)
    elif cfg.get("eye") is not None:
        pose = look_at(torch.tensor(list(cfg.eye), dtype=torch.float64),
                       torch.tensor(list(cfg.target), dtype=torch.float64),
                       torch.tensor(list(cfg.up), dtype=torch.float64))
    else:
        if not scene.cameras:
            raise ValueError(f"scene {scene.name!r} defines no camera: give camera.world_T_cam or camera.eye/target")
        index = int(cfg.index)
        if not 0 <= index < len(scene.cameras):
            raise ValueError(f"camera.index={index} but scene {scene.name!r} has {len(scene.cameras)} camera(s)")
        camera = scene.cameras[index]
        return camera.world_T_cam, float(fov if fov is not None else camera.fov_x_deg)
    if fov is None:
        raise ValueError("camera.fov_x_deg is required with an explicit pose")
    return pose, float(fov)
