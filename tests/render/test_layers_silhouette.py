from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv import box_room
from kadv.geometry import intrinsics_from_fov, look_at, perturb_world_T_cam
from kadv.render import (
    ExactRenderer,
    FoundEdges,
    find_edge_pairs,
    render_anchor,
    silhouette,
    silhouette_term,
    track_edge_pairs,
)
from kadv.render.layers import guard_band_intrinsics
from kadv.render.silhouette import edge_crossings
from kadv.scenes import Material, assemble_scene
from kadv.scenes.parts import box_parts, quad_part


def _panel_before_wall() -> ExactRenderer:
    """A 1 m panel at z = 2 in front of a wall at z = 4 (camera at the origin looking down +z)."""
    materials = [Material("panel", base_color=[1.0, 0.0, 0.0]), Material("wall", base_color=[0.0, 0.0, 1.0])]
    parts = [
        quad_part(np.array([[-0.5, -0.5, 2], [0.5, -0.5, 2], [0.5, 0.5, 2], [-0.5, 0.5, 2]], float), 0, "panel"),
        quad_part(np.array([[-5, -5, 4], [5, -5, 4], [5, 5, 4], [-5, 5, 4]], float), 1, "wall"),
    ]
    return ExactRenderer(assemble_scene(parts, materials, name="panel"))


POSE = look_at(torch.tensor([0.0, 0.0, 0.0]), torch.tensor([0.0, 0.0, 1.0])).double()


def test_depth_peeling_layers_are_sorted_and_complete() -> None:
    renderer = _panel_before_wall()
    K = intrinsics_from_fov(60.0, 16, 16)
    anchor = render_anchor(renderer, POSE, K, 16, 16, layers=3)
    centre_depths = anchor.points[0, :, 2, 8, 8]
    assert torch.allclose(
        centre_depths, torch.tensor([2.0, 4.0, 0.0], dtype=torch.float32), atol=1e-6
    )  # panel, wall, none
    assert anchor.mask[0, :, 0, 8, 8].tolist() == [True, True, False]
    corner = anchor.points[0, :, 2, 0, 0].tolist()  # outside the panel: the wall only
    assert abs(corner[0] - 4.0) < 1e-6 and not anchor.mask[0, 1, 0, 0, 0]


def test_the_second_layer_holds_the_wall_a_box_hides_not_the_box_s_far_side() -> None:
    # a closed 1 m box from z = 2 to 3 in front of a wall at z = 4: a ray through the box meets its
    # front (2 m), its back face from inside (3 m) and the wall (4 m)
    materials = [Material("box", base_color=[1.0, 0.0, 0.0]), Material("wall", base_color=[0.0, 0.0, 1.0])]
    parts = box_parts(np.array([-0.5, -0.5, 2.0]), np.array([0.5, 0.5, 3.0]), 0, "box", tile=1.0)
    parts.append(quad_part(np.array([[-5, -5, 4], [5, -5, 4], [5, 5, 4], [-5, 5, 4]], float), 1, "wall"))
    renderer = ExactRenderer(assemble_scene(parts, materials, name="box before wall"))
    K = intrinsics_from_fov(60.0, 16, 16)
    anchor = render_anchor(renderer, POSE, K, 16, 16, layers=3)
    centre = anchor.points[0, :, 2, 8, 8].tolist()
    assert centre[:2] == pytest.approx([2.0, 4.0], abs=1e-5) and centre[2] == 0.0  # box, wall, nothing
    assert anchor.mask[0, :, 0, 8, 8].tolist() == [True, True, False]
    rgb = anchor.rgb[0, :, :, 8, 8]
    assert rgb[0, 0] > rgb[0, 2] and rgb[1, 2] > rgb[1, 0]  # red box in front, the blue wall behind it


def test_the_boxed_layers_are_each_block_s_mean_and_its_mask_s_least() -> None:
    """Each boxed pixel holds the mean colour and point of the s x s fine pixels from it and 1
    only where all of them hit: a box filter at stride 1 (against torch's pooling)."""
    renderer = _panel_before_wall()
    K = intrinsics_from_fov(60.0, 16, 16)
    anchor = render_anchor(renderer, POSE, K, 16, 16, layers=2, guard_band=2, supersample=3)
    maps = anchor.boxed.maps
    assert maps.shape == (1, 2, 7, 3 * 20 - 2, 3 * 20 - 2)
    fine = torch.cat([anchor.rgb, anchor.points], dim=2)[0]
    mean = torch.nn.functional.avg_pool2d(fine, 3, stride=1)
    least = -torch.nn.functional.max_pool2d(-anchor.mask[0].float(), 3, stride=1)
    torch.testing.assert_close(maps[0, :, 0:6], mean, rtol=1e-6, atol=1e-6)
    assert torch.equal(maps[0, :, 6:7], least)
    # the panel's outline: blocks there mix panel and wall (layer 0) or wall and nothing (layer 1)
    assert 0 < float(least[1].mean()) < 1 and float(least[0].min()) == 1.0


def test_one_lookup_of_the_diagonal_means_is_the_mean_of_four_lookups_half_a_pixel_away() -> None:
    """The warp's gradient lookup: the boxed colour and point read at q + 1/2 in the diagonal means
    equal the mean of the four bilinear lookups at q +- (1/2, 1/2), in value and in their slopes in
    q, across the panel's outline and off the maps' edges too (zero beyond them)."""
    renderer = _panel_before_wall()
    anchor = render_anchor(renderer, POSE, intrinsics_from_fov(60.0, 16, 16), 16, 16, guard_band=2, supersample=2)
    boxed = anchor.boxed
    maps, means = boxed.maps[:, 0, 0:6], boxed.diagonal_means[:, 0]
    assert means.shape[-2:] == (maps.shape[-2] + 1, maps.shape[-1] + 1)
    generator = torch.Generator().manual_seed(0)
    size = torch.tensor([maps.shape[-1], maps.shape[-2]], dtype=torch.float32)
    q = (torch.rand(1, 400, 2, generator=generator) * (size + 2) - 1).requires_grad_(True)

    def read(image: torch.Tensor, pixels: torch.Tensor) -> torch.Tensor:
        scale = 2.0 / torch.tensor([image.shape[-1], image.shape[-2]], dtype=torch.float32)
        return torch.nn.functional.grid_sample(image, pixels * scale - 1.0, align_corners=False)

    diagonals = torch.tensor([[-0.5, -0.5], [0.5, -0.5], [-0.5, 0.5], [0.5, 0.5]])
    four = read(maps, q[:, None] + diagonals[:, None]).mean(2)
    one = read(means, q[:, None] + 0.5)[:, :, 0]
    torch.testing.assert_close(one, four, rtol=1e-5, atol=1e-5)
    assert float(four[:, 0:3].detach().std()) > 0.1  # the lookups saw both the panel and the wall
    weights = torch.randn(four.shape, generator=generator)
    slopes_four, slopes_one = (torch.autograd.grad((v * weights).sum(), q)[0] for v in (four, one))
    torch.testing.assert_close(slopes_one, slopes_four, rtol=1e-4, atol=1e-4)


def test_guard_band_widens_the_view_around_the_same_centre() -> None:
    renderer = _panel_before_wall()
    K = intrinsics_from_fov(60.0, 16, 16)
    anchor = render_anchor(renderer, POSE, K, 16, 16, guard_band=4, supersample=2)
    assert anchor.rgb.shape[-2:] == (48, 48)
    assert torch.allclose(anchor.K[0], guard_band_intrinsics(K, 4, 2))
    assert float(anchor.K[0, 0, 2]) == 2 * (8 + 4)
    # the hi-res pixels around the centre of the current view still see the panel's centre
    assert torch.allclose(
        anchor.points[0, 0, :, 23:25, 23:25].mean(dim=(1, 2)),
        torch.tensor([0.0, 0.0, 2.0], dtype=torch.float32),
        atol=0.05,
    )


def test_edge_pairs_sit_on_the_panel_outline_with_exact_crossings() -> None:
    renderer = _panel_before_wall()
    height = width = 32
    K = intrinsics_from_fov(60.0, height, width)
    exact = renderer.render(POSE, K, height, width)
    pairs = find_edge_pairs(renderer, exact, POSE, K)
    assert len(pairs.a) > 0 and set(pairs.horizontal.tolist()) == {True, False}
    focal = float(K[0, 0])
    # the panel's outline projects to u = cx +- focal * 0.5 / 2 (and likewise in v)
    for a, horizontal, t in zip(pairs.a, pairs.horizontal, pairs.t):
        row, col = divmod(int(a), width)
        coordinate = (col if horizontal else row) + 0.5 + t
        assert min(abs(coordinate - (16 + s * focal * 0.25)) for s in (-1, 1)) < 1e-2


def test_the_uncompacted_search_keeps_the_compacted_pairs_and_gives_the_same_gradient() -> None:
    # what a GPU runs (every neighbour pair, the edges marked: no count to wait for), here on the CPU
    renderer = ExactRenderer(box_room(seed=0))
    eyes = torch.tensor([[0.8, 1.6, 0.8], [3.2, 1.2, 0.9]])
    poses = look_at(eyes, torch.tensor([[3.0, 0.4, 3.5], [1.0, 0.3, 3.0]])).double()
    K = intrinsics_from_fov(70.0, 24, 32)
    exact = renderer.render(poses, K, 24, 32)
    compacted = find_edge_pairs(renderer, exact, poses, K)
    every = find_edge_pairs(renderer, exact, poses, K, compact=False)
    assert compacted.keep is None and len(compacted.a) > 10 and set(compacted.batch.tolist()) == {0, 1}
    assert len(every.a) == 2 * (24 * 31 + 23 * 32)  # each view's horizontal and vertical neighbours
    kept = every.compacted()
    assert kept.keep is None and kept.blocks is None and compacted.compacted() is compacted
    for name in ("batch", "a", "b", "horizontal", "edge", "t"):
        assert torch.equal(getattr(every, name)[every.keep], getattr(compacted, name)), name
        assert torch.equal(getattr(kept, name), getattr(compacted, name)), name
    values = torch.cat([exact.rgb, exact.depth], dim=1)
    weights = torch.rand(values.shape, generator=torch.Generator().manual_seed(0))
    gradients = []
    for pairs in (compacted, every):
        pose = poses.clone().requires_grad_(True)
        (silhouette_term(renderer, pairs, pose, K, values) * weights).sum().backward()
        gradients.append(pose.grad)
    assert gradients[0].abs().sum() > 0 and torch.equal(gradients[0], gradients[1])


@pytest.mark.parametrize("compact", [True, False])
def test_the_bisection_finds_the_same_edges_however_many_steps_a_cast_decides(monkeypatch, compact: bool) -> None:
    # a GPU casts every midpoint of three steps at once, the CPU one midpoint a step: the same rays
    renderer = ExactRenderer(box_room(seed=0))
    eyes = torch.tensor([[0.8, 1.6, 0.8], [3.2, 1.2, 0.9]])
    poses = look_at(eyes, torch.tensor([[3.0, 0.4, 3.5], [1.0, 0.3, 3.0]])).double()
    K = intrinsics_from_fov(70.0, 24, 32)
    exact = renderer.render(poses, K, 24, 32)
    found = []
    for steps in (1, 2, 3, 4, 6):  # 4: a round of four steps, then one of two
        monkeypatch.setitem(silhouette._STEPS_PER_CAST, "cpu", steps)
        found.append(find_edge_pairs(renderer, exact, poses, K, compact))
    assert len(found[0].a) > 10
    for pairs in found[1:]:
        for name in ("batch", "a", "b", "horizontal", "edge", "t", "keep"):
            first, other = getattr(found[0], name), getattr(pairs, name)
            assert (first is None and other is None) or torch.equal(first, other), name


def test_crossing_of_a_known_edge() -> None:
    # vertical edge x = 0.2 at depth 2 between pixel centres u = 10.5 and 11.5 of a focal-10 camera (cx = 10)
    K = torch.tensor([[10.0, 0, 10], [0, 10.0, 10], [0, 0, 1]], dtype=torch.float64)
    edge = torch.tensor([[[0.2, -1.0, 2.0], [0.2, 1.0, 2.0]]], dtype=torch.float64, requires_grad=True)
    uv_a, uv_b = torch.tensor([[10.5, 10.5]], dtype=torch.float64), torch.tensor([[11.5, 10.5]], dtype=torch.float64)
    rays = [torch.linalg.inv(K) @ torch.tensor([u[0, 0], u[0, 1], 1.0], dtype=torch.float64) for u in (uv_a, uv_b)]
    t, genuine = edge_crossings(edge, rays[0][None], rays[1][None], K[None], uv_a, uv_b)
    assert bool(genuine[0]) and float(t.detach()) == float(10 + 10 * 0.2 / 2 - 10.5)  # u = 11 -> t = 0.5
    t.sum().backward()  # dt/dx of the edge = focal / depth = 5 per vertex pair
    assert np.isclose(float(edge.grad[0, :, 0].sum()), 5.0)


def test_edge_pairs_followed_to_a_nearby_view_are_the_pairs_a_search_there_finds() -> None:
    """A panel's straight outline, moved in the image by a small turn and step of the camera: the
    pairs followed from the first view, without a ray, are those a search in the second finds, with
    the same edges and crossings."""
    renderer = _panel_before_wall()
    height = width = 32
    K = intrinsics_from_fov(60.0, height, width)
    searched_first = renderer.render(POSE, K, height, width)
    found = find_edge_pairs(renderer, searched_first, POSE, K)
    moved = perturb_world_T_cam(
        POSE,
        torch.tensor([[0.004, -0.006, 0.003]], dtype=torch.float64),
        torch.tensor([[0.03, 0.02, -0.05]], dtype=torch.float64),
    )
    exact = renderer.render(moved, K, height, width)
    searched = find_edge_pairs(renderer, exact, moved, K)
    followed = track_edge_pairs(renderer, FoundEdges.of(renderer, found, searched_first, POSE, K), exact, moved, K)
    assert len(searched.a) > 40 and not torch.equal(searched.a, found.a)  # the outline moved
    order = lambda pairs: torch.argsort(pairs.a * 2 + pairs.horizontal.long())
    s, f = order(searched), order(followed)
    for name in ("batch", "a", "b", "horizontal", "edge"):
        assert torch.equal(getattr(searched, name)[s], getattr(followed, name)[f]), name
    # the search's crossing is its bisection's last bracket (1/64 of a pixel wide); the followed one exact
    assert float((searched.t[s] - followed.t[f]).abs().max()) <= 2.0**-7
