"""Poses and cameras (OpenCV convention: x right, y down, z forward; metres)."""

from __future__ import annotations

from kadv.geometry.camera import (
    Camera,
    batched_intrinsics,
    fov_intrinsics,
    intrinsics_from_fov,
    pixel_rays,
    scaled_size,
    to_open3d_pinhole,
)
from kadv.geometry.pose import (
    axis_angle_to_matrix,
    check_world_T_cam,
    look_at,
    matrix_to_axis_angle,
    perturb_world_T_cam,
    pose_distance,
    rc_from_world_T_cam,
    rotation_from_yaw_pitch_roll,
    world_T_cam_from_rc,
    yaw_pitch_roll,
)

__all__ = [
    "Camera",
    "axis_angle_to_matrix",
    "batched_intrinsics",
    "check_world_T_cam",
    "fov_intrinsics",
    "intrinsics_from_fov",
    "look_at",
    "matrix_to_axis_angle",
    "perturb_world_T_cam",
    "pixel_rays",
    "pose_distance",
    "rc_from_world_T_cam",
    "rotation_from_yaw_pitch_roll",
    "scaled_size",
    "to_open3d_pinhole",
    "world_T_cam_from_rc",
    "yaw_pitch_roll",
]
