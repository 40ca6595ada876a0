from __future__ import annotations

import math

import numpy as np
import open3d as o3d
import pytest
import torch

from kadv.geometry import Camera, intrinsics_from_fov, look_at, pixel_rays, to_open3d_pinhole


def test_intrinsics_from_fov() -> None:
    K = intrinsics_from_fov(90.0, 180, 320)
    assert math.isclose(float(K[0, 0]), 160.0, rel_tol=1e-12)
    assert float(K[1, 1]) == float(K[0, 0])
    assert (float(K[0, 2]), float(K[1, 2])) == (160.0, 90.0)


@pytest.mark.parametrize("fov", [0.0, 180.0, float("nan"), -5.0])
def test_bad_fov_raises(fov: float) -> None:
    with pytest.raises(ValueError, match="fov"):
        intrinsics_from_fov(fov, 10, 10)


def test_rays_have_unit_camera_z_and_pass_through_pixel_centres() -> None:
    pose = look_at(torch.tensor([0.5, 1.0, -2.0]), torch.tensor([1.0, 0.8, 3.0])).double()
    K = intrinsics_from_fov(60.0, 7, 9)
    origins, dirs = pixel_rays(pose, K, 7, 9)
    assert origins.shape == (1, 7, 1, 9, 1, 3)
    dirs_cam = dirs.reshape(-1, 3).numpy() @ pose[:3, :3].numpy()
    assert np.allclose(dirs_cam[:, 2], 1.0)
    projected = dirs_cam @ K.numpy().T
    u = projected[:, 0].reshape(7, 9)
    v = projected[:, 1].reshape(7, 9)
    assert np.allclose(u, np.arange(9)[None, :] + 0.5)
    assert np.allclose(v, np.arange(7)[:, None] + 0.5)


def test_supersampled_rays_average_to_pixel_centre() -> None:
    pose = torch.eye(4, dtype=torch.float64)
    K = intrinsics_from_fov(60.0, 4, 5)
    _, centre = pixel_rays(pose, K, 4, 5)
    _, sub = pixel_rays(pose, K, 4, 5, supersample=3)
    assert np.allclose(sub.mean(axis=(2, 4)), centre[:, :, 0, :, 0])


def test_open3d_pinhole_conversion_gives_our_rays() -> None:
    pose = look_at(torch.tensor([0.5, 1.0, -2.0]), torch.tensor([1.0, 0.8, 3.0])).double()
    K = intrinsics_from_fov(75.0, 12, 16)
    intrinsic, extrinsic = to_open3d_pinhole(pose, K)
    theirs = o3d.t.geometry.RaycastingScene.create_rays_pinhole(intrinsic, extrinsic, 16, 12).numpy()
    origins, dirs = pixel_rays(pose, K, 12, 16)
    assert np.allclose(theirs[..., :3], origins.reshape(12, 16, 3), atol=1e-5)
    their_dirs = theirs[..., 3:] / (theirs[..., 3:] @ pose[:3, 2].numpy())[..., None]
    assert np.allclose(their_dirs, dirs.reshape(12, 16, 3), atol=1e-5)


def test_camera_rejects_bad_pose() -> None:
    with pytest.raises(ValueError, match="NaN"):
        Camera(torch.full((4, 4), float("nan")), 60.0)
