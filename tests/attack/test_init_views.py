from __future__ import annotations

import json

import numpy as np
import pytest
import torch

from kadv import ExactRenderer, box_room, look_at
from kadv.attack import (
    InitViewConfig,
    InitViewError,
    PenaltyConfig,
    check_init_views,
    clear_file_camera,
    file_init_views,
    load_init_params,
    sample_init_views,
    sample_valid_views,
    save_init_params,
    score_views,
)
from kadv.penalties import distance_to_surface, view_validity
from kadv.scenes import Scene
from tests.conftest import cached_real_scene

PENALTY = PenaltyConfig()


@pytest.mark.parametrize("facing, sign", [(1.0, 1.0), (-1.0, -1.0)])
def test_a_camera_at_a_wall_moves_along_its_axis_away_from_it(tiny_objective, facing, sign) -> None:
    renderer = tiny_objective.renderer
    eye = torch.tensor([1.5, 1.5, 0.02], dtype=torch.float64)  # 2 cm from the wall z = 0
    pose = look_at(eye, eye + torch.tensor([0.0, 0.0, facing], dtype=torch.float64)).double()
    cleared, moved = clear_file_camera(renderer, pose, PENALTY.margin)
    assert moved * sign > 0  # forward when the wall is behind, backward when it is in front
    assert float(distance_to_surface(renderer, cleared[None, :3, 3])[0]) >= PENALTY.margin
    assert torch.equal(cleared[:3, :3], pose[:3, :3])
    assert torch.allclose(cleared[:3, 3] - pose[:3, 3], moved * pose[:3, 2])


@pytest.mark.real_scenes
@pytest.mark.parametrize("name", ["grey_white_room", "japanese_classroom"])
def test_real_file_cameras_next_to_a_wall_are_moved_clear_and_valid(name) -> None:
    renderer = ExactRenderer(cached_real_scene(name))
    camera = renderer.scene.cameras[0]
    assert float(distance_to_surface(renderer, camera.world_T_cam[None, :3, 3])[0]) < PENALTY.margin
    view = file_init_views(renderer, PENALTY.margin)[0]
    assert float(distance_to_surface(renderer, view.world_T_cam[None, :3, 3])[0]) >= PENALTY.margin
    assert 0.0 < abs(float((view.world_T_cam[:3, 3] - camera.world_T_cam[:3, 3]).norm())) < 0.2
    check_init_views(renderer, [view], PENALTY, 60, 80)


def test_sampled_views_are_valid_clear_in_range_and_ranked(tiny_objective) -> None:
    renderer, model = tiny_objective.renderer, tiny_objective.model
    config = InitViewConfig(candidates=12, eye_height=(1.2, 1.6), pitch_deg=(-20.0, 0.0), roll_deg=(0.0, 0.0))
    views = sample_init_views(renderer, model, 4, 3, config, PENALTY, 48, 64)
    assert len(views) == 4 and all(v.source == "sampled" for v in views)
    poses = torch.stack([v.world_T_cam for v in views])
    scores = score_views(model, renderer, poses, torch.full((4,), config.fov_x_deg), 48, 64)
    ranked = (scores.delta1 + config.content_weight * scores.content()).tolist()
    assert ranked == sorted(ranked, reverse=True)  # accuracy and what the view shows, together
    assert ((scores.content() > 0) & (scores.content() <= 1)).all() and (scores.surfaces >= 1).all()
    assert (distance_to_surface(renderer, poses[:, :3, 3]) > 2 * PENALTY.d_th).all()
    centres = poses[:, :3, 3].numpy()
    below = renderer.cast(centres, np.broadcast_to(np.array([0.0, -1.0, 0.0]), centres.shape)).numpy()
    assert ((below.t >= 1.2 - 1e-9) & (below.t <= 1.6 + 1e-9)).all()  # eye height above what is below
    pitch = torch.rad2deg(torch.asin(poses[:, 1, 2]))  # the optical axis' upward component (world y up)
    assert ((pitch >= -20.0 - 1e-6) & (pitch <= 1e-6)).all()
    K = views[0].world_T_cam.new_tensor([[32.0, 0, 32], [0, 32.0, 24], [0, 0, 1]])
    assert view_validity(renderer, poses, K, 48, 64).valid.all()
    again = sample_init_views(renderer, model, 4, 3, config, PENALTY, 48, 64)
    assert all(torch.equal(a.world_T_cam, b.world_T_cam) for a, b in zip(views, again))


def test_init_params_round_trip_and_bad_files_name_themselves(tiny_objective, tmp_path) -> None:
    views = file_init_views(tiny_objective.renderer, PENALTY.margin)
    path = save_init_params(tmp_path / "init_params.json", views)
    loaded = load_init_params(path)
    assert [v.name for v in loaded] == [v.name for v in views]
    assert all(torch.equal(a.world_T_cam, b.world_T_cam) for a, b in zip(loaded, views))
    bad = tmp_path / "bad.json"
    bad.write_text(json.dumps({"init_views": [{**views[0].to_dict(), "world_T_cam": [[1, 0], [0, 1]]}]}))
    with pytest.raises(ValueError, match=r"bad.json"):
        load_init_params(bad)
    with pytest.raises(FileNotFoundError, match=r"missing.json"):
        load_init_params(tmp_path / "missing.json")


def test_an_init_view_inside_a_box_is_refused(tiny_objective) -> None:
    renderer = tiny_objective.renderer
    box = renderer.scene.vertices[renderer.scene.faces[renderer.scene.material_ids == 6]]
    centre = torch.from_numpy(box.reshape(-1, 3).mean(axis=0))
    views = file_init_views(renderer, PENALTY.margin)
    inside = type(views[0])(
        "boxed", "given", look_at(centre, centre + torch.tensor([1.0, 0, 0], dtype=torch.float64)).double(), 70.0
    )
    with pytest.raises(InitViewError, match=r"boxed.*inside an object"):
        check_init_views(renderer, [inside], PENALTY, 24, 32)


def _room_on_a_large_ground() -> Scene:
    """The box room standing on a 220 m x 220 m ground plane, its bounds mostly outdoors (as the
    classroom's are), its file camera kept and no interior box to say where the room is."""
    room = box_room(seed=0)
    half = 110.0
    ground = np.array([[-half, -0.05, -half], [half, -0.05, -half], [half, -0.05, half], [-half, -0.05, half]])
    faces = np.array([[0, 2, 1], [0, 3, 2]]) + len(room.vertices)  # facing up
    return Scene(
        np.concatenate([room.vertices, ground]),
        np.concatenate([room.faces, faces]),
        np.concatenate([room.uvs, np.zeros((2, 3, 2), np.float32)]),
        np.concatenate([room.normals, np.tile(np.float32([0, 1, 0]), (2, 3, 1))]),
        np.concatenate([room.material_ids, [0, 0]]),
        room.materials,
        cameras=room.cameras,
        name="room_on_ground",
    )


def test_sampled_centres_lie_inside_the_room_not_on_a_large_outdoor_ground() -> None:
    scene = _room_on_a_large_ground()
    room_lo, room_hi = box_room(seed=0).bounds
    assert np.prod(np.diff(scene.bounds[:, [0, 2]], axis=0)) > 1000 * np.prod(
        np.diff([room_lo, room_hi], axis=0)[0, [0, 2]]
    )
    renderer = ExactRenderer(scene)
    poses = sample_valid_views(renderer, 24, 0, InitViewConfig(), PENALTY, 48, 64)
    assert len(poses) == 24
    centres = poses[:, :3, 3].numpy()
    inside = ((centres > room_lo) & (centres < room_hi)).all(axis=1)
    assert inside.all(), centres[~inside]


@pytest.mark.parametrize("lighting", ["direct", "scanned"])
def test_every_function_on_the_init_views_path_takes_an_empty_batch(lighting) -> None:
    """A scene where no candidate is left must end in a sentence, not in a reshape of nothing."""
    import kadv
    from kadv.attack import InitViewConfig, PenaltyConfig, captured_init_views, score_views
    from kadv.penalties import distance_to_surface, step_guard, view_validity

    renderer = kadv.ExactRenderer(kadv.box_room(seed=0), kadv.Shading(lighting=lighting))
    none = torch.zeros(0, 4, 4, dtype=torch.float64)
    points = torch.zeros(0, 3, dtype=torch.float64)
    K = kadv.intrinsics_from_fov(70.0, 12, 16)
    validity = view_validity(renderer, none, K, 12, 16, **PenaltyConfig().validity_options())
    assert validity.verdicts == [] and validity.valid.dtype == torch.bool and len(validity.valid) == 0
    assert renderer.render(none, K, 12, 16).rgb.shape == (0, 3, 12, 16)
    assert [len(x) for x in renderer.intersections(points, points)] == [0, 0, 0, 0]
    assert len(distance_to_surface(renderer, points)) == 0
    assert len(step_guard(renderer, points, points, 0.1).allowed) == 0
    scores = score_views(kadv.load_model("kadv_tiny"), renderer, none, torch.zeros(0), 12, 16)
    assert len(scores.delta1) == 0 and len(scores.content()) == 0
    assert captured_init_views(renderer, None, 0, InitViewConfig(), PenaltyConfig(), 12, 16) == []
