"""Camera envelopes: the pose figures they bound, the projection into them, their verdicts."""

from __future__ import annotations

import math
from pathlib import Path

import pytest
import torch
import yaml

from kadv.geometry import intrinsics_from_fov, look_at, perturb_world_T_cam, yaw_pitch_roll
from kadv.penalties import ENVELOPES, Envelope, get_envelope, view_validity
from kadv.render import ExactRenderer
from kadv.scenes import box_room

ROOM = ExactRenderer(box_room(seed=0, size=(4.0, 3.0, 5.0), num_boxes=0))  # floor y = 0, ceiling y = 3
UPRIGHT, ROBOT = ENVELOPES["upright"], ENVELOPES["robot"]


def _pose(eye, target, roll_deg: float = 0.0) -> torch.Tensor:
    """(1, 4, 4) float64: look_at turned by ``roll_deg`` about its optical axis."""
    base = look_at(torch.tensor(eye), torch.tensor(target)).double()[None]
    omega = torch.tensor([[0.0, 0.0, math.radians(roll_deg)]], dtype=torch.float64)
    return perturb_world_T_cam(base, omega, torch.zeros(1, 3, dtype=torch.float64))


def _degrees(world_T_cam: torch.Tensor) -> list[float]:
    return torch.rad2deg(yaw_pitch_roll(world_T_cam[:, :3, :3]))[0].tolist()


def test_the_figures_are_the_poses_heading_elevation_bank_and_height() -> None:
    pose = _pose([1.0, 1.2, 1.0], [1.0, 2.2, 2.0], roll_deg=10.0)  # north (+z), 45 degrees up
    figures = ROBOT.figures(ROOM, pose)
    yaw, pitch, roll = torch.rad2deg(figures.angles[0]).tolist()
    assert yaw == pytest.approx(0.0, abs=1e-9) and pitch == pytest.approx(45.0) and roll == pytest.approx(10.0)
    assert float(figures.height[0]) == pytest.approx(1.2, abs=1e-5)  # the floor is at y = 0
    assert figures.reasons() == ["roll 10.0° beyond ±2°"]


def test_a_pose_inside_comes_back_bit_for_bit_and_one_outside_lands_on_the_bounds() -> None:
    inside = _pose([1.0, 1.2, 1.0], [3.0, 1.0, 4.0], roll_deg=1.0)
    outside = _pose([1.0, 2.5, 1.0], [1.5, 3.0, 3.0], roll_deg=-7.0)  # 2.5 m up, 14 degrees up, rolled
    base = torch.cat([inside, outside])
    params = torch.tensor([[0.01, -0.02, 0.0, 0.1, 0.0, 0.0], [0.0, -0.3, 0.0, 0.0, 0.0, 0.1]], dtype=torch.float64)
    projected = ROBOT.project(ROOM, base, params)
    assert torch.equal(projected[0], params[0])
    moved = perturb_world_T_cam(base, projected[:, :3], projected[:, 3:])
    before = _degrees(perturb_world_T_cam(base[1:], params[1:, :3], params[1:, 3:]))
    yaw, pitch, roll = _degrees(moved[1:])
    assert yaw == pytest.approx(before[0], abs=1e-5)  # the heading is kept (to the axis-angle round trip)
    assert pitch == pytest.approx(min(before[1], 15.0), abs=1e-5) and roll == pytest.approx(-2.0, abs=1e-5)
    assert float(moved[1, 1, 3]) == pytest.approx(1.5, abs=1e-6)  # lowered straight down to the highest bound
    assert ROBOT.figures(ROOM, moved).reasons() == [None, None]


def test_a_view_outside_the_envelope_gets_its_own_verdict_and_reason() -> None:
    pose = torch.cat([_pose([1.0, 1.5, 1.0], [3.0, 1.5, 4.0]), _pose([1.0, 1.5, 1.0], [1.0, 3.0, 2.0])])
    K = intrinsics_from_fov(70.0, 24, 32)
    validity = view_validity(ROOM, pose, K, 24, 32, max_plane_share=None)
    validity.envelope = UPRIGHT.figures(ROOM, pose)
    assert validity.verdicts == ["valid", "outside the envelope"]
    assert validity.reasons[1].startswith("pitch 56.3° outside -30° to 30° (upright (roll within ±5°")


def test_a_centre_with_nothing_below_it_is_outside_a_height_bound() -> None:
    pose = _pose([1.0, -1.0, 1.0], [3.0, -1.0, 4.0])  # under the floor
    assert ROBOT.figures(ROOM, pose).reasons() == ["no surface below the camera, outside 0.3 to 1.5 m"]


def test_the_free_envelope_changes_nothing() -> None:
    params = torch.randn(4, 6, dtype=torch.float64)
    assert get_envelope("free").free and get_envelope("free").project(ROOM, None, params) is params


@pytest.mark.parametrize("name", sorted(ENVELOPES))
def test_each_preset_file_holds_the_python_preset(name: str) -> None:
    node = yaml.safe_load((Path(__file__).parents[2] / "conf" / "envelope" / f"{name}.yaml").read_text())
    assert Envelope(**{k: tuple(v) if isinstance(v, list) else v for k, v in node.items()}) == ENVELOPES[name]


@pytest.mark.parametrize(
    "settings, message",
    [
        ({"pitch_deg": (30.0, -30.0)}, r"envelope.pitch_deg \[30.0, -30.0\] is empty or leaves \[-90, 90\]"),
        ({"height": (-1.0, 2.0)}, r"envelope.height \[-1.0, 2.0\] is empty or leaves >= 0"),
        ({"max_roll_deg": -5.0}, r"envelope.max_roll_deg must be in \[0, 180\] or null, got -5.0"),
        ({"pitch_deg": 30.0}, r"envelope.pitch_deg must be \[lowest, highest\] or null, got 30.0"),
    ],
)
def test_bounds_that_hold_no_pose_are_refused_by_name(settings: dict, message: str) -> None:
    with pytest.raises(ValueError, match=message):
        Envelope("custom", **settings)


def test_an_unknown_preset_is_refused_with_the_choices() -> None:
    with pytest.raises(
        ValueError, match="envelope 'drone' is not a preset; choose one of free, upright, handheld, robot"
    ):
        get_envelope("drone")
