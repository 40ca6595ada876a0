"""kadv.diagnostics: the gradient check's pieces, and the check itself on a box room."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.diagnostics import FUNCTIONALS, check_pose, gradient_check_poses, occlusion_edge_mask, smooth_weights
from kadv.geometry import intrinsics_from_fov, look_at
from kadv.render import DiffRenderConfig, ExactRenderer
from kadv.scenes import box_room


def test_smooth_weights_are_seeded_and_smooth() -> None:
    weights = smooth_weights(0, 3, 24, 32)
    assert torch.equal(weights, smooth_weights(0, 3, 24, 32)) and not torch.equal(weights, smooth_weights(1, 3, 24, 32))
    neighbour_step = (weights[..., 1:] - weights[..., :-1]).abs().max()
    assert float(neighbour_step) < 0.2 * float(weights.abs().max())


def test_occlusion_edges_are_marked_only_where_depth_jumps() -> None:
    renderer = ExactRenderer(box_room(seed=0))
    K = intrinsics_from_fov(40.0, 24, 32)
    eye = torch.tensor([1.5, 1.4, 1.8], dtype=torch.float64)
    wall = renderer.render(look_at(eye, eye - torch.tensor([1.0, 0.0, 0.0], dtype=torch.float64)), K, 24, 32)
    assert not bool(occlusion_edge_mask(wall).any())  # one flat wall
    room = renderer.render(renderer.scene.cameras[0].world_T_cam, K, 24, 32)
    edges = occlusion_edge_mask(room)
    assert float(edges.float().mean()) > 0.05  # boxes in front of walls


@pytest.mark.parametrize("backend", ["open3d", "warp"])
def test_gradient_check_on_box_room_poses_meets_the_thresholds(backend: str) -> None:
    """A fast version of benchmarks/gradcheck.py on three box-room poses, the default configuration,
    with either ray caster."""
    renderer = ExactRenderer(box_room(seed=0), backend=backend)
    checks = gradient_check_poses(renderer, 3, 0, 70.0, 48, 64, {"default": DiffRenderConfig()})
    scores = np.array([[c.score(f) for f in FUNCTIONALS] for c in checks["default"]])
    assert np.median(scores[:, 0]) >= 0.99 and np.median(scores[:, 1]) >= 0.99  # interior rgb, depth
    assert np.median(scores[:, 2]) >= 0.95 and np.median(scores[:, 3]) >= 0.95  # full rgb, depth


def test_the_focal_length_s_derivative_meets_the_pose_s_thresholds() -> None:
    """The derivative a searched field of view moves along, as benchmarks/gradcheck.py checks it,
    on three box-room poses: its cosine over eight weight maps per functional."""
    renderer = ExactRenderer(box_room(seed=0))
    configs = {"default": DiffRenderConfig(), "no silhouettes": DiffRenderConfig(silhouette=False)}
    checks = gradient_check_poses(renderer, 3, 0, 70.0, 48, 64, configs, steps=(2e-3, 4e-3, 2e-3))
    scores = np.array([[c.focal_score(f) for f in FUNCTIONALS] for c in checks["default"]])
    assert np.median(scores[:, 0]) >= 0.99 and np.median(scores[:, 1]) >= 0.99  # interior rgb, depth
    assert np.median(scores[:, 2]) >= 0.95 and np.median(scores[:, 3]) >= 0.95  # full rgb, depth
    # the silhouette term carries the edges' motion under a zoom: without it the full rgb falls short
    bare = np.array([c.focal_score("rgb_full") for c in checks["no silhouettes"]])
    assert bare.min() < scores[:, 2].min()


def test_a_kept_anchor_is_checked_inside_its_reach_and_refused_beyond_it() -> None:
    """The warp preset is checked where it warps: by default its anchor sits just inside the reach
    (and the check warps, its gradient nonzero); an offset beyond the reach would check a fresh
    anchor instead of the warp, and is refused."""
    renderer = ExactRenderer(box_room(seed=0))
    camera = renderer.scene.cameras[0]
    K = intrinsics_from_fov(camera.fov_x_deg, 24, 32)
    warp = {"warp": DiffRenderConfig(values="warp", refresh="every_k")}
    check = check_pose(renderer, camera.world_T_cam, K, 24, 32, warp)["warp"]
    assert check.score("depth_interior") >= 0.99  # it warped (else refused), with the warp's gradient
    with pytest.raises(ValueError, match="beyond warp's reach"):
        check_pose(renderer, camera.world_T_cam, K, 24, 32, warp, anchor_offset=(6.0, 0.0))
