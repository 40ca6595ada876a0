"""Pinhole cameras: intrinsics, per-pixel rays, and the conversion to Open3D's conventions."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import open3d as o3d
import torch

from kadv.geometry.pose import check_world_T_cam

__all__ = [
    "Camera",
    "batched_intrinsics",
    "camera_rays",
    "fov_intrinsics",
    "intrinsics_from_fov",
    "pixel_rays",
    "scaled_size",
    "to_open3d_pinhole",
    "world_rays",
]


def scaled_size(height: int, width: int, scale: float) -> tuple[int, int]:
    """The height and width of renders at ``scale`` times ``height`` x ``width`` (at least 8 pixels each)."""
    return max(8, round(scale * height)), max(8, round(scale * width))


def intrinsics_from_fov(fov_x_deg: float, height: int, width: int) -> torch.Tensor:
    """Intrinsics K (3, 3) of a pinhole camera with square pixels and horizontal field of view.

    Pixel centres sit at integer + 0.5, so the principal point is the image centre (W/2, H/2).

    Raises:
        ValueError: if the field of view is not in (0, 180) degrees or the size is not positive.

    Examples:
        >>> K = intrinsics_from_fov(90.0, 240, 320)
        >>> K.dtype, K.shape
        (torch.float64, torch.Size([3, 3]))
        >>> [round(K[0, 0].item(), 9), K[0, 2].item(), K[1, 2].item()]  # f = (W / 2) / tan(45 deg)
        [160.0, 160.0, 120.0]
    """
    if not (0.0 < float(fov_x_deg) < 180.0) or not math.isfinite(float(fov_x_deg)):
        raise ValueError(f"fov_x_deg must be in (0, 180), got {fov_x_deg}")
    if height <= 0 or width <= 0:
        raise ValueError(f"image size must be positive, got height={height}, width={width}")
    focal = 0.5 * width / math.tan(math.radians(fov_x_deg) / 2.0)
    return torch.tensor([[focal, 0.0, width / 2.0], [0.0, focal, height / 2.0], [0.0, 0.0, 1.0]], dtype=torch.float64)


@dataclass
class Camera:
    """A camera a scene file defines, in the OpenCV convention.

    Attributes:
        world_T_cam: camera-to-world pose (4, 4), float64.
        fov_x_deg: horizontal field of view in degrees.
        width: film width in pixels the file asks for (for the aspect ratio), if any.
        height: film height in pixels, if any.
        name: where the camera came from.
    """

    world_T_cam: torch.Tensor
    fov_x_deg: float
    width: int | None = None
    height: int | None = None
    name: str = field(default="camera")

    def __post_init__(self) -> None:
        self.world_T_cam = check_world_T_cam(
            torch.as_tensor(self.world_T_cam, dtype=torch.float64), f"{self.name}.world_T_cam"
        )[0]
        intrinsics_from_fov(self.fov_x_deg, 1, 1)  # validates the field of view

    def intrinsics(self, height: int, width: int) -> torch.Tensor:
        """K (3, 3) for an image of the given size with this camera's horizontal field of view."""
        return intrinsics_from_fov(self.fov_x_deg, height, width)


def fov_intrinsics(fov_x_deg: torch.Tensor, height: int, width: int) -> torch.Tensor:
    """Intrinsics (B, 3, 3) float64 of pinhole cameras with square pixels, the principal point at
    the image centre and horizontal fields of view ``fov_x_deg`` (B,) in degrees, differentiable in them
    (:func:`intrinsics_from_fov` for one)."""
    focal = 0.5 * width / torch.tan(torch.deg2rad(fov_x_deg.double()) / 2.0)
    zero, one = torch.zeros_like(focal), torch.ones_like(focal)
    rows = [
        torch.stack([focal, zero, zero + width / 2.0], dim=-1),
        torch.stack([zero, focal, zero + height / 2.0], dim=-1),
        torch.stack([zero, zero, one], dim=-1),
    ]
    return torch.stack(rows, dim=-2)


def batched_intrinsics(K: torch.Tensor, batch: int) -> torch.Tensor:
    """Intrinsics (batch, 3, 3) float64 from (3, 3) (shared by the batch) or (batch, 3, 3).

    Raises:
        ValueError: on another shape, NaN/inf entries or a focal length that is not positive.

    Examples:
        >>> K = intrinsics_from_fov(60.0, 48, 64)
        >>> batched_intrinsics(K, 4).shape
        torch.Size([4, 3, 3])
    """
    K = torch.as_tensor(K, dtype=torch.float64)
    if K.shape == (3, 3):
        K = K.expand(batch, 3, 3)
    if K.shape != (batch, 3, 3):
        raise ValueError(f"K: expected (3, 3) or ({batch}, 3, 3), got {tuple(K.shape)}")
    if not bool(torch.isfinite(K).all()) or bool((K[:, 0, 0] <= 0).any()) or bool((K[:, 1, 1] <= 0).any()):
        raise ValueError("K: intrinsics must be finite with positive focal lengths")
    return K


def camera_rays(
    K: torch.Tensor, height: int, width: int, supersample: int = 1, device: torch.device | str | None = None
) -> torch.Tensor:
    """Camera-frame rays (B, H, s, W, s, 3) float64 with z = 1 through pixel (sub-)centres, for
    intrinsics K (B, 3, 3), made on ``device`` (None: K's): a hit at ray parameter t is the
    camera-frame point t * ray."""
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    # inverted where K is (the host: an inverse checks for singular matrices, a wait on a GPU), then
    # copied without waiting
    device = K.device if device is None else torch.device(device)
    K_inv = torch.linalg.inv(K.double()).to(device, non_blocking=True)
    sub = (torch.arange(s, dtype=torch.float64, device=device) + 0.5) / s
    v = torch.arange(height, dtype=torch.float64, device=device)[:, None] + sub[None, :]  # (H, s)
    u = torch.arange(width, dtype=torch.float64, device=device)[:, None] + sub[None, :]  # (W, s)
    vv = v[:, :, None, None].expand(height, s, width, s)
    uu = u[None, None, :, :].expand(height, s, width, s)
    pixels = torch.stack([uu, vv, torch.ones_like(uu)], dim=-1)  # (H, s, W, s, 3)
    return torch.einsum("bij,hawcj->bhawci", K_inv, pixels)


def pixel_rays(
    world_T_cam: torch.Tensor,
    K: torch.Tensor,
    height: int,
    width: int,
    supersample: int = 1,
    device: torch.device | str | None = None,
) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame rays through pixel (sub-)centres, for all cameras at once.

    Directions have camera-frame z = 1 (not unit length), so a ray parameter is a z-depth.

    Args:
        world_T_cam: poses (B, 4, 4).
        K: intrinsics (3, 3) or (B, 3, 3).
        height: image height in pixels.
        width: image width in pixels.
        supersample: s; each pixel gets s x s rays on a regular sub-grid.
        device: where the rays are made (None: the pose's device).

    Returns:
        origins, directions: float64 tensors (B, H, s, W, s, 3) on ``device``; averaging over axes
        2 and 4 gives per-pixel values. The origins are a broadcast view of the B centres.

    Examples:
        >>> from kadv.geometry import look_at
        >>> world_T_cam = look_at(torch.tensor([0.0, 1.0, 0.0]), torch.tensor([0.0, 1.0, 5.0]))
        >>> origins, directions = pixel_rays(world_T_cam, intrinsics_from_fov(90.0, 2, 2), 2, 2)
        >>> tuple(origins.shape), tuple(directions.shape)  # (B, H, s, W, s, 3) with s = 1
        ((1, 2, 1, 2, 1, 3), (1, 2, 1, 2, 1, 3))
        >>> origins[0, 0, 0, 0, 0].tolist(), directions[0, 1, 0, 1, 0].round(decimals=9).tolist()  # lower right
        ([0.0, 1.0, 0.0], [-0.5, -0.5, 1.0])
    """
    pose = check_world_T_cam(world_T_cam).detach().double()
    device = pose.device if device is None else device
    return world_rays(pose, camera_rays(batched_intrinsics(K, pose.shape[0]), height, width, supersample, device))


def world_rays(world_T_cam: torch.Tensor, rays_cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """World-frame origins and directions, float64 tensors (B, ..., 3) on the rays' device, of
    camera-frame rays (B, ..., 3) (from :func:`camera_rays`) of cameras at poses (B, 4, 4); the
    origins are a broadcast view of the B centres."""
    pose = world_T_cam.detach().double().to(rays_cam.device, non_blocking=True)  # (B, 4, 4): nothing to wait for
    dirs_world = torch.einsum("bij,b...j->b...i", pose[:, :3, :3], rays_cam)
    origins = pose[:, :3, 3].reshape(len(pose), *[1] * (rays_cam.dim() - 2), 3).expand_as(dirs_world)
    return origins, dirs_world


def to_open3d_pinhole(world_T_cam: torch.Tensor, K: torch.Tensor) -> tuple[o3d.core.Tensor, o3d.core.Tensor]:
    """Intrinsic and extrinsic (cam_T_world) tensors for ``RaycastingScene.create_rays_pinhole``.

    Open3D (>= 0.18) also puts pixel centres at integer + 0.5, so K passes through unchanged
    (``tests/geometry/test_camera.py`` pins that both give the same rays).

    Args:
        world_T_cam: one pose (4, 4).
        K: intrinsics (3, 3) in kadv's convention.

    Examples:
        >>> import numpy as np
        >>> from kadv.geometry import look_at
        >>> world_T_cam = look_at(torch.tensor([0.0, 1.0, 0.0]), torch.tensor([0.0, 1.0, 5.0]))
        >>> intrinsic, extrinsic = to_open3d_pinhole(world_T_cam, intrinsics_from_fov(90.0, 2, 2))
        >>> bool(np.allclose(extrinsic.numpy() @ [0.0, 1.0, 0.0, 1.0], [0.0, 0.0, 0.0, 1.0]))  # eye -> origin
        True
    """
    pose = check_world_T_cam(world_T_cam)[0].detach().double()
    intrinsic = torch.as_tensor(K, dtype=torch.float64)
    cam_T_world = torch.linalg.inv(pose)
    return o3d.core.Tensor(intrinsic.numpy()), o3d.core.Tensor(cam_T_world.numpy())
