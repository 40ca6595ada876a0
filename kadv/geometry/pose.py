"""Rigid poses: axis-angle <-> rotation, ``world_T_cam`` from (R, c), look-at.

``world_T_cam`` (..., 4, 4) maps camera-frame points to the world; its rotation block is the
camera's orientation R and its last column the optical centre c.
"""

from __future__ import annotations

import torch
from kornia.geometry.conversions import axis_angle_to_rotation_matrix, rotation_matrix_to_axis_angle

from kadv.checks import check_values

__all__ = [
    "axis_angle_to_matrix",
    "check_world_T_cam",
    "look_at",
    "matrix_to_axis_angle",
    "perturb_world_T_cam",
    "pose_distance",
    "rc_from_world_T_cam",
    "rotation_from_yaw_pitch_roll",
    "world_T_cam_from_rc",
    "yaw_pitch_roll",
]


def axis_angle_to_matrix(axis_angle: torch.Tensor) -> torch.Tensor:
    """Rotation vectors (..., 3) to rotation matrices (..., 3, 3).

    kornia's Rodrigues form has exact, finite derivatives at exactly zero rotation (pinned by
    ``tests/geometry/test_pose.py``), which the attack needs since it starts every run at zero.

    Examples:
        >>> import math
        >>> R = axis_angle_to_matrix(torch.tensor([0.0, math.pi / 2, 0.0], dtype=torch.float64))
        >>> z, x = torch.eye(3, dtype=torch.float64)[2], torch.eye(3, dtype=torch.float64)[0]
        >>> torch.allclose(R @ z, x)  # a quarter turn about y takes z to x
        True
    """
    shape = axis_angle.shape[:-1]
    return axis_angle_to_rotation_matrix(axis_angle.reshape(-1, 3)).reshape(*shape, 3, 3)


def matrix_to_axis_angle(rotation: torch.Tensor) -> torch.Tensor:
    """Rotation matrices (..., 3, 3) to rotation vectors (..., 3) with angle in [0, pi].

    Examples:
        >>> omega = torch.tensor([0.1, -0.2, 0.3], dtype=torch.float64)
        >>> torch.allclose(matrix_to_axis_angle(axis_angle_to_matrix(omega)), omega)
        True
    """
    shape = rotation.shape[:-2]
    return rotation_matrix_to_axis_angle(rotation.reshape(-1, 3, 3)).reshape(*shape, 3)


def pose_distance(a_world_T_cam: torch.Tensor, b_world_T_cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """How far apart two poses (..., 4, 4) are: the angle (...) in radians of the rotation between
    their orientations, and the distance (...) between their centres.

    Examples:
        >>> a = torch.eye(4, dtype=torch.float64)
        >>> b = world_T_cam_from_rc(axis_angle_to_matrix(torch.tensor([0.0, 0.1, 0.0], dtype=torch.float64)),
        ...                         torch.tensor([0.3, 0.0, 0.4], dtype=torch.float64))
        >>> [round(float(d), 6) for d in pose_distance(a, b)]
        [0.1, 0.5]
    """
    turn = a_world_T_cam[..., :3, :3].transpose(-1, -2) @ b_world_T_cam[..., :3, :3]
    centres = b_world_T_cam[..., :3, 3] - a_world_T_cam[..., :3, 3]
    return matrix_to_axis_angle(turn).norm(dim=-1), centres.norm(dim=-1)


def world_T_cam_from_rc(rotation: torch.Tensor, centre: torch.Tensor) -> torch.Tensor:
    """Build ``world_T_cam`` (..., 4, 4) from camera orientation R (..., 3, 3) and centre c (..., 3).

    Examples:
        >>> world_T_cam = world_T_cam_from_rc(torch.eye(3), torch.tensor([1.0, 2.0, 3.0]))
        >>> world_T_cam[:3, 3].tolist(), world_T_cam[3].tolist()
        ([1.0, 2.0, 3.0], [0.0, 0.0, 0.0, 1.0])
    """
    top = torch.cat([rotation, centre.unsqueeze(-1)], dim=-1)
    bottom = torch.zeros_like(top[..., :1, :])
    bottom[..., 0, 3] = 1.0
    return torch.cat([top, bottom], dim=-2)


def rc_from_world_T_cam(world_T_cam: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """Split ``world_T_cam`` (..., 4, 4) into R (..., 3, 3) and centre c (..., 3).

    Examples:
        >>> R, c = rc_from_world_T_cam(world_T_cam_from_rc(torch.eye(3), torch.tensor([1.0, 2.0, 3.0])))
        >>> torch.equal(R, torch.eye(3)), c.tolist()
        (True, [1.0, 2.0, 3.0])
    """
    return world_T_cam[..., :3, :3], world_T_cam[..., :3, 3]


def perturb_world_T_cam(world_T_cam: torch.Tensor, omega: torch.Tensor, delta: torch.Tensor) -> torch.Tensor:
    """Apply the attack's pose parameters: R = R0 exp([omega]x) (camera frame), c = c0 + delta.

    Args:
        world_T_cam: base poses (B, 4, 4).
        omega: rotation vectors in the camera frame (B, 3).
        delta: centre offsets in world metres (B, 3).

    Returns:
        Perturbed poses (B, 4, 4), differentiable in ``omega`` and ``delta``.

    Examples:
        >>> start = look_at(torch.tensor([1.0, 1.5, 1.0]), torch.tensor([3.0, 1.5, 1.0])).double()
        >>> moved = perturb_world_T_cam(start[None], torch.zeros(1, 3, dtype=torch.float64),
        ...                             torch.tensor([[0.0, 0.0, 0.5]], dtype=torch.float64))
        >>> moved[0, :3, 3].tolist(), torch.equal(moved[0, :3, :3], start[:3, :3])  # delta moves the centre only
        ([1.0, 1.5, 1.5], True)
    """
    rotation0, centre0 = rc_from_world_T_cam(world_T_cam)
    return world_T_cam_from_rc(rotation0 @ axis_angle_to_matrix(omega), centre0 + delta)


def look_at(
    eye: torch.Tensor, target: torch.Tensor, up: torch.Tensor | tuple[float, float, float] = (0.0, 1.0, 0.0)
) -> torch.Tensor:
    """OpenCV-convention ``world_T_cam`` (..., 4, 4) of a camera at ``eye`` looking at ``target``.

    The camera's z axis points at the target and its y axis (image down) points away from ``up``.

    Raises:
        ValueError: if eye and target coincide or the view direction is parallel to ``up``.

    Examples:
        >>> world_T_cam = look_at(torch.tensor([1.0, 1.5, 1.0]), torch.tensor([3.0, 1.5, 1.0]))
        >>> world_T_cam[:3, 2].tolist()  # the optical axis (camera z) points at the target
        [1.0, 0.0, 0.0]
        >>> world_T_cam[:3, 1].tolist()  # camera y points down (OpenCV), the world's y is up
        [0.0, -1.0, 0.0]
    """
    eye = torch.as_tensor(eye, dtype=torch.float32)
    target = torch.as_tensor(target, dtype=eye.dtype)
    up = torch.as_tensor(up, dtype=eye.dtype).expand_as(eye)
    forward = target - eye
    norm = forward.norm(dim=-1, keepdim=True)
    if bool((norm < 1e-9).any()):
        raise ValueError("look_at: eye and target coincide")
    z = forward / norm
    x = torch.linalg.cross(z, up)
    x_norm = x.norm(dim=-1, keepdim=True)
    if bool((x_norm < 1e-9).any()):
        raise ValueError("look_at: view direction is parallel to the up vector")
    x = x / x_norm
    y = torch.linalg.cross(z, x)
    return world_T_cam_from_rc(torch.stack([x, y, z], dim=-1), eye)


def check_world_T_cam(world_T_cam: torch.Tensor, name: str = "world_T_cam", atol: float = 1e-4) -> torch.Tensor:
    """Validate poses (B, 4, 4) or (4, 4) and return them as (B, 4, 4).

    Raises:
        ValueError: on a wrong shape, NaN/inf entries, a last row other than [0, 0, 0, 1], or a
            rotation block that is not orthonormal with determinant +1.

    Examples:
        >>> check_world_T_cam(torch.eye(4, dtype=torch.float64)).shape
        torch.Size([1, 4, 4])
        >>> check_world_T_cam(2 * torch.eye(4, dtype=torch.float64))
        Traceback (most recent call last):
        ...
        ValueError: world_T_cam...
    """
    pose = torch.as_tensor(world_T_cam)
    if pose.ndim == 2:
        pose = pose.unsqueeze(0)
    if pose.ndim != 3 or pose.shape[-2:] != (4, 4):
        raise ValueError(f"{name}: expected shape (B, 4, 4) or (4, 4), got {tuple(torch.as_tensor(world_T_cam).shape)}")
    detached = pose.detach().double()
    bottom = torch.eye(4, dtype=torch.float64, device=pose.device)[3]
    rotation = detached[:, :3, :3]

    def rotations() -> torch.Tensor:
        eye = torch.eye(3, dtype=torch.float64, device=pose.device).expand_as(rotation)
        orthonormal = (rotation.transpose(-1, -2) @ rotation - eye).abs().amax(dim=(-1, -2)) < atol
        return orthonormal & ((torch.linalg.det(rotation) - 1.0).abs() < atol)

    if pose.device.type != "cpu":  # one assertion that does not wait for the device
        rigid = torch.isfinite(detached).all() & ((detached[:, 3] - bottom).abs() <= atol).all() & rotations().all()
        check_values(rigid, f"{name}: not a finite rigid pose (last row [0, 0, 0, 1], R^T R = I, det R = +1)")
        return pose
    if not bool(torch.isfinite(detached).all()):
        raise ValueError(f"{name}: pose contains NaN or inf")
    if not bool(torch.allclose(detached[:, 3], bottom.expand_as(detached[:, 3]), atol=atol)):
        raise ValueError(f"{name}: last row must be [0, 0, 0, 1]")
    bad = ~rotations()
    if bool(bad.any()):
        index = int(bad.nonzero()[0, 0])
        raise ValueError(f"{name}[{index}]: rotation block is not a rotation matrix (R^T R != I or det != +1)")
    return pose


def yaw_pitch_roll(rotation: torch.Tensor) -> torch.Tensor:
    """Heading, elevation and bank (..., 3) in radians of camera orientations (..., 3, 3) in kadv's
    y-up world.

    - yaw: the optical axis's heading about the world's y axis, ``atan2(f_x, f_z)``, in (-pi, pi];
    - pitch: the optical axis's elevation above the horizon, in [-pi/2, pi/2] (positive: looking up);
    - roll: the turn about the optical axis from the upright camera (image x horizontal, image
      down towards the floor), positive from image x towards image y; undefined (0) looking straight
      up or down.

    Examples:
        >>> import math
        >>> level = look_at(torch.tensor([0.0, 1.0, 0.0]), torch.tensor([1.0, 2.0, 0.0])).double()
        >>> yaw, pitch, roll = (math.degrees(a) for a in yaw_pitch_roll(level[:3, :3]).tolist())
        >>> round(yaw, 9), round(pitch, 9), abs(roll) < 1e-9  # east (world +x), 45 degrees up, upright
        (90.0, 45.0, True)
    """
    right, down, forward = rotation[..., 0], rotation[..., 1], rotation[..., 2]
    yaw = torch.atan2(forward[..., 0], forward[..., 2])
    pitch = torch.atan2(forward[..., 1], torch.hypot(forward[..., 0], forward[..., 2]))
    roll = torch.atan2(-right[..., 1], -down[..., 1])
    return torch.stack([yaw, pitch, roll], dim=-1)


def rotation_from_yaw_pitch_roll(angles: torch.Tensor) -> torch.Tensor:
    """Camera orientations (..., 3, 3) from yaw, pitch and roll (..., 3) in radians (the inverse of
    :func:`yaw_pitch_roll` for pitch strictly inside (-pi/2, pi/2)).

    Examples:
        >>> angles = torch.tensor([0.3, -0.2, 0.1], dtype=torch.float64)
        >>> torch.allclose(yaw_pitch_roll(rotation_from_yaw_pitch_roll(angles)), angles)
        True
    """
    yaw, pitch, roll = angles.unbind(-1)
    zero = torch.zeros_like(yaw)
    forward = torch.stack([pitch.cos() * yaw.sin(), pitch.sin(), pitch.cos() * yaw.cos()], dim=-1)
    level_right = torch.stack([-yaw.cos(), zero, yaw.sin()], dim=-1)  # forward x up, normalised
    level_down = torch.linalg.cross(forward, level_right)
    cos, sin = roll.cos()[..., None], roll.sin()[..., None]
    right = cos * level_right + sin * level_down
    down = cos * level_down - sin * level_right
    return torch.stack([right, down, forward], dim=-1)
