from __future__ import annotations

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from kadv.geometry import (
    axis_angle_to_matrix,
    check_world_T_cam,
    look_at,
    matrix_to_axis_angle,
    perturb_world_T_cam,
    rc_from_world_T_cam,
    world_T_cam_from_rc,
)


def _central_jacobian(fn, x: torch.Tensor, eps: float = 1e-6) -> torch.Tensor:
    columns = []
    for i in range(x.numel()):
        step = torch.zeros_like(x).view(-1)
        step[i] = eps
        step = step.view_as(x)
        columns.append(((fn(x + step) - fn(x - step)) / (2 * eps)).reshape(-1))
    return torch.stack(columns, dim=1)


@pytest.mark.parametrize("value", [0.0, 1e-12, 1e-5, 0.3, 3.0])
def test_axis_angle_gradient_matches_finite_differences_including_zero(value: float) -> None:
    omega = torch.tensor([[value, -0.5 * value, 0.25 * value]], dtype=torch.float64)
    analytic = torch.autograd.functional.jacobian(axis_angle_to_matrix, omega).reshape(9, 3)
    assert torch.isfinite(analytic).all()
    assert torch.allclose(analytic, _central_jacobian(axis_angle_to_matrix, omega), atol=1e-8)


def test_gradient_at_zero_is_the_generator_of_rotations() -> None:
    # d R / d omega_k at 0 is the skew matrix [e_k]x.
    jac = torch.autograd.functional.jacobian(axis_angle_to_matrix, torch.zeros(1, 3, dtype=torch.float64))
    jac = jac.reshape(3, 3, 3)
    skew_z = torch.tensor([[0.0, -1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 0.0, 0.0]], dtype=torch.float64)
    assert torch.allclose(jac[..., 2], skew_z)


@settings(max_examples=50, deadline=None)
@given(st.lists(st.floats(-2.0, 2.0), min_size=3, max_size=3))
def test_axis_angle_round_trip(values: list[float]) -> None:
    omega = torch.tensor(values, dtype=torch.float64)
    rotation = axis_angle_to_matrix(omega)
    assert torch.allclose(rotation @ rotation.T, torch.eye(3, dtype=torch.float64), atol=1e-10)
    assert torch.allclose(axis_angle_to_matrix(matrix_to_axis_angle(rotation)), rotation, atol=1e-6)


def test_world_T_cam_round_trip_and_last_column_is_centre() -> None:
    rotation = axis_angle_to_matrix(torch.tensor([0.1, 0.2, -0.3], dtype=torch.float64))
    centre = torch.tensor([1.0, 2.0, 3.0], dtype=torch.float64)
    pose = world_T_cam_from_rc(rotation, centre)
    assert torch.equal(pose[:3, 3], centre)
    assert torch.equal(pose[3], torch.tensor([0.0, 0.0, 0.0, 1.0], dtype=torch.float64))
    r2, c2 = rc_from_world_T_cam(pose)
    assert torch.equal(r2, rotation) and torch.equal(c2, centre)


def test_look_at_opencv_convention() -> None:
    eye = torch.tensor([1.0, 1.5, 2.0])
    target = torch.tensor([4.0, 1.5, 2.0])
    pose = look_at(eye, target)
    x, y, z = pose[:3, 0], pose[:3, 1], pose[:3, 2]
    assert torch.allclose(z, torch.tensor([1.0, 0.0, 0.0]))  # z forward, at the target
    assert torch.allclose(y, torch.tensor([0.0, -1.0, 0.0]))  # y down = away from +y up
    assert torch.allclose(x, torch.tensor([0.0, 0.0, 1.0]))  # right of +x when y is up
    assert math.isclose(float(torch.linalg.det(pose[:3, :3])), 1.0, rel_tol=1e-6)


def test_perturb_applies_rotation_in_camera_frame_and_offset_in_world() -> None:
    base = look_at(torch.tensor([0.0, 1.0, 0.0]), torch.tensor([0.0, 1.0, 5.0])).double()[None]
    omega = torch.tensor([[0.0, 0.2, 0.0]], dtype=torch.float64)  # yaw about the camera's y axis
    delta = torch.tensor([[0.5, 0.0, 0.0]], dtype=torch.float64)
    pose = perturb_world_T_cam(base, omega, delta)
    assert torch.allclose(pose[0, :3, 3], torch.tensor([0.5, 1.0, 0.0], dtype=torch.float64))
    assert torch.allclose(pose[0, :3, :3], base[0, :3, :3] @ axis_angle_to_matrix(omega[0]))


@pytest.mark.parametrize(
    "pose, message",
    [
        (torch.full((4, 4), float("nan")), "NaN"),
        (torch.diag(torch.tensor([2.0, 1.0, 1.0, 1.0])), "not a rotation"),
        (torch.diag(torch.tensor([-1.0, 1.0, 1.0, 1.0])), "not a rotation"),
        (torch.eye(3), "shape"),
        (torch.tensor([[1.0, 0, 0, 0], [0, 1, 0, 0], [0, 0, 1, 0], [1, 0, 0, 1]]), "last row"),
    ],
)
def test_bad_poses_raise_naming_the_problem(pose: torch.Tensor, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        check_world_T_cam(pose)
