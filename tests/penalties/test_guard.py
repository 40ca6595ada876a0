from __future__ import annotations

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from kadv.geometry import intrinsics_from_fov, look_at
from kadv.penalties import step_guard, view_validity
from kadv.render import ExactRenderer
from kadv.scenes import MeshPart, assemble_scene, box_room
from kadv.scenes.parts import quad_part

WALL_X = 3.0


def _room_with_thin_wall() -> ExactRenderer:
    room = box_room(seed=5, size=(6.0, 3.0, 4.0), num_boxes=0)
    # a zero-thickness two-sided wall across the whole room at x = 3
    corners = np.array([[WALL_X, 0, 0], [WALL_X, 0, 4], [WALL_X, 3, 4], [WALL_X, 3, 0]], float)
    room_part = MeshPart(room.vertices, room.faces, room.uvs, None, 0, "room")
    parts = [room_part, quad_part(corners, 1, "thin wall")]
    return ExactRenderer(assemble_scene(parts, room.materials, name="thin_wall"))


RENDERER = _room_with_thin_wall()


@settings(max_examples=60, deadline=None)
@given(
    start=st.tuples(st.floats(0.5, 2.5), st.floats(0.5, 2.5), st.floats(0.5, 3.5)),
    steps=st.lists(
        st.tuples(st.floats(1e-4, 8.0), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)), min_size=1, max_size=25
    ),
)
def test_camera_pushed_at_a_thin_wall_never_crosses_it(start, steps) -> None:
    centre = torch.tensor([start], dtype=torch.float64)
    for size, dy, dz in steps:
        direction = torch.tensor([[1.0, dy, dz]], dtype=torch.float64)
        proposal = centre + size * direction / direction.norm()
        check = step_guard(RENDERER, centre, proposal, margin=0.02)
        if not bool(check.allowed[0]):
            # shorten to the clear part of the step, as the attack does, and re-check
            proposal = centre + 0.99 * float(check.max_fraction[0]) * (proposal - centre)
            if not bool(step_guard(RENDERER, centre, proposal, margin=0.02).allowed[0]):
                continue
        centre = proposal
        assert float(centre[0, 0]) < WALL_X


def test_step_through_wall_refused_and_step_before_it_allowed() -> None:
    old = torch.tensor([[2.0, 1.5, 2.0], [2.0, 1.5, 2.0]], dtype=torch.float64)
    new = torch.tensor([[4.0, 1.5, 2.0], [2.5, 1.5, 2.0]], dtype=torch.float64)
    check = step_guard(RENDERER, old, new, margin=0.02)
    assert check.allowed.tolist() == [False, True]
    assert abs(float(check.max_fraction[0]) - (1.0 - 0.02) / 2.0) < 1e-5


def test_ten_thousand_guarded_random_steps_stay_valid() -> None:
    room = box_room(seed=0)
    renderer = ExactRenderer(room)
    rng = np.random.default_rng(0)
    cameras, steps = 100, 100
    base = room.cameras[0].world_T_cam
    centres = base[:3, 3].expand(cameras, 3).clone()
    K = intrinsics_from_fov(70.0, 8, 8)
    refused = 0
    for _ in range(steps):
        size = rng.uniform(0.0, 2.0, size=(cameras, 1))
        direction = rng.normal(size=(cameras, 3))
        proposal = centres + torch.from_numpy(size * direction / np.linalg.norm(direction, axis=1, keepdims=True))
        check = step_guard(renderer, centres, proposal, margin=0.1)
        refused += int((~check.allowed).sum())
        centres = torch.where(check.allowed[:, None], proposal, centres)
        targets = centres + torch.from_numpy(rng.normal(size=(cameras, 3)))
        poses = torch.stack([look_at(c, t) for c, t in zip(centres, targets)])
        # a camera facing one wall is a poor view but a legal place: only the geometric verdicts are checked here
        validity = view_validity(renderer, poses, K, 8, 8, near=0.05, min_distance=0.05, max_plane_share=None)
        assert all(v == "valid" for v in validity.verdicts), validity.reasons
    assert 0 < refused < cameras * steps  # the guard was exercised, and cameras did move
