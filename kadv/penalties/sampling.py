"""Random camera poses a scene accepts: for gradient checks, training views and experiments."""

from __future__ import annotations

import math

import numpy as np
import torch

from kadv.geometry import axis_angle_to_matrix, intrinsics_from_fov, look_at
from kadv.penalties.validity import view_validity
from kadv.render.exact import ExactRenderer

__all__ = ["random_valid_poses"]


def random_valid_poses(
    renderer: ExactRenderer, count: int, rng: np.random.Generator, fov_x_deg: float, min_clearance: float = 0.3
) -> torch.Tensor:
    """``count`` poses (count, 4, 4) inside the scene bounds that :func:`view_validity` accepts.

    Centres are uniform in the scene's camera region (its interior if declared, else its bounds)
    shrunk by ``min_clearance``; headings uniform, pitch in [-35, 15] degrees, roll within +-5 degrees.

    Examples:
        >>> import kadv
        >>> room = kadv.ExactRenderer(kadv.box_room(size=(4.0, 3.0, 5.0), num_boxes=0))
        >>> poses = random_valid_poses(room, 3, np.random.default_rng(0), fov_x_deg=70.0)
        >>> poses.shape, bool(view_validity(room, poses, intrinsics_from_fov(70.0, 24, 32), 24, 32).valid.all())
        (torch.Size([3, 4, 4]), True)
    """
    lo, hi = renderer.scene.camera_region + np.array([[min_clearance] * 3, [-min_clearance] * 3])
    accepted: list[torch.Tensor] = []
    K = intrinsics_from_fov(fov_x_deg, 24, 32)
    for _ in range(100):
        candidates = 4 * (count - len(accepted))
        centres = rng.uniform(lo, hi, size=(candidates, 3))
        yaw = rng.uniform(0, 2 * math.pi, candidates)
        pitch = np.radians(rng.uniform(-35, 15, candidates))
        forward = np.stack([np.cos(pitch) * np.cos(yaw), np.sin(pitch), np.cos(pitch) * np.sin(yaw)], axis=1)
        poses = look_at(torch.from_numpy(centres), torch.from_numpy(centres + forward)).double()
        roll = torch.from_numpy(np.radians(rng.uniform(-5, 5, candidates)))
        poses[:, :3, :3] = poses[:, :3, :3] @ axis_angle_to_matrix(torch.stack([0 * roll, 0 * roll, roll], dim=1))
        result = view_validity(renderer, poses, K, 24, 32)
        keep = result.valid & (result.distance.cpu() >= min_clearance)
        accepted += list(poses[keep])
        if len(accepted) >= count:
            return torch.stack(accepted[:count])
    raise RuntimeError(f"found only {len(accepted)} of {count} valid views in {renderer.scene.name}")
