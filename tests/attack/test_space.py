from __future__ import annotations

import math

import numpy as np
import pytest
import torch

from kadv.attack import FOV, AttackConfig
from kadv.geometry import fov_intrinsics, intrinsics_from_fov
from kadv.penalties import Envelope

FREE_FOV = Envelope("custom", fov_deg=(40.0, 100.0))


def test_a_fixed_field_of_view_keeps_six_coordinates_and_the_init_view_s_camera() -> None:
    space = AttackConfig().space(70.0)
    assert space.dims == 6 and space.zeros(3).shape == (3, 6)
    assert torch.equal(space.intrinsics(space.zeros(2), 48, 64), intrinsics_from_fov(70.0, 48, 64))
    assert space.fov_deg(space.zeros(2)).tolist() == [70.0, 70.0]


def test_a_free_field_of_view_is_a_seventh_coordinate_sampled_over_its_range() -> None:
    space = AttackConfig(envelope=FREE_FOV).space(70.0)
    assert space.dims == 7
    points = space.sample(np.random.default_rng(0).uniform(size=(4000, 7)))
    fov = space.fov_deg(points)
    assert fov.min() >= 40.0 and fov.max() <= 100.0
    # uniform over the range: each decile holds about a tenth of the draws
    counts = np.histogram(fov.numpy(), bins=10, range=(40.0, 100.0))[0]
    assert counts.min() > 300 and counts.max() < 500
    # the pose coordinates are drawn as with the field of view fixed
    six = AttackConfig().space(70.0).sample(np.random.default_rng(0).uniform(size=(4000, 7))[:, :6])
    assert torch.equal(points[:, :6], six)


def test_the_box_maps_onto_the_bounds_and_back() -> None:
    space = AttackConfig(envelope=FREE_FOV).space(70.0)
    unit = torch.tensor([[-1.0] * 7, [1.0] * 7, [0.0] * 7], dtype=torch.float64)
    points = space.from_box(unit)
    assert space.fov_deg(points).tolist() == pytest.approx([40.0, 100.0, 70.0])
    assert points[1, :3].tolist() == pytest.approx([math.radians(45.0)] * 3)
    assert torch.allclose(space.to_box(points), unit)


def test_bounds_clamp_the_field_of_view_to_its_range_widened_to_the_init_view_s() -> None:
    inside = AttackConfig(envelope=FREE_FOV).space(70.0)
    far = torch.tensor([[0.0] * 6 + [50.0], [0.0] * 6 + [-45.0], [0.0] * 6 + [5.0]], dtype=torch.float64)
    assert inside.fov_deg(inside.bound(far)).tolist() == [100.0, 40.0, 75.0]
    # an init view outside the range keeps its own field of view: the init view is a point of the space
    narrow = AttackConfig(envelope=FREE_FOV).space(30.0)
    assert narrow.fov_deg(narrow.bound(narrow.zeros())).tolist() == [30.0]
    assert narrow.fov_deg(narrow.bound(far)).tolist() == [80.0, 30.0, 35.0]


def test_the_intrinsics_are_each_view_s_and_differentiable_in_its_field_of_view() -> None:
    space = AttackConfig(envelope=FREE_FOV).space(70.0)
    points = torch.tensor([[0.0] * 6 + [-20.0], [0.0] * 6 + [10.0]], dtype=torch.float64, requires_grad=True)
    K = space.intrinsics(points, 48, 64)
    for k, fov in zip(K.detach(), (50.0, 80.0)):
        assert torch.allclose(k, intrinsics_from_fov(fov, 48, 64))
    K[:, 0, 0].sum().backward()
    # f = (W / 2) / tan(fov / 2): df/dfov = -(W / 4) / sin^2(fov / 2), per radian
    expected = [-(64 / 4) / math.sin(math.radians(f) / 2) ** 2 * math.pi / 180 for f in (50.0, 80.0)]
    assert points.grad[:, FOV].tolist() == pytest.approx(expected)
    assert points.grad[:, :FOV].abs().max() == 0


def test_fov_intrinsics_match_the_single_camera_s() -> None:
    fov = torch.tensor([30.0, 70.0, 120.0], dtype=torch.float64)
    for k, f in zip(fov_intrinsics(fov, 24, 32), fov.tolist()):
        assert torch.allclose(k, intrinsics_from_fov(f, 24, 32))


@pytest.mark.parametrize(("bounds", "words"), [((100, 40), "empty"), ((0.5, 90), "(1, 179)"), ((40, 179), "(1, 179)")])
def test_a_field_of_view_range_outside_1_to_179_degrees_or_reversed_is_refused_in_one_line(bounds, words) -> None:
    with pytest.raises(ValueError, match=r"envelope\.fov_deg") as error:
        Envelope(fov_deg=bounds)
    assert words in str(error.value) and "\n" not in str(error.value)
