"""Probe scenes: each is a valid place to start an attack from, and closed where it must be."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from kadv.attack import PenaltyConfig, check_init_views, file_init_views
from kadv.geometry import intrinsics_from_fov
from kadv.losses import depth_metrics
from kadv.models import load_model
from kadv.penalties import distance_to_surface
from kadv.probes import PROBES, probe_names, probe_scene
from kadv.render import ExactRenderer, Shading


def _directions(count: int) -> np.ndarray:
    """``count`` unit vectors spread evenly over the sphere (a Fibonacci lattice)."""
    k = np.arange(count) + 0.5
    y = 1.0 - 2.0 * k / count
    phi = np.pi * (1.0 + 5.0**0.5) * k
    r = np.sqrt(1.0 - y**2)
    return np.stack([r * np.cos(phi), y, r * np.sin(phi)], axis=1)


@pytest.mark.parametrize("name", probe_names())
def test_each_probe_has_valid_init_views_inside_closed_geometry(name: str) -> None:
    scene = probe_scene(name, seed=0)
    assert len(scene.cameras) == 2, "each probe comes with two init views"
    renderer = ExactRenderer(scene)
    penalty = PenaltyConfig()
    views = file_init_views(renderer, penalty.margin)
    # as designed: clear of every surface without being moved
    assert [view.note for view in views] == ["as in the file"] * 2
    check_init_views(renderer, views, penalty, 96, 128)
    centres = torch.stack([view.world_T_cam[:3, 3] for view in views])
    assert (distance_to_surface(renderer, centres) > 2 * penalty.d_th).all()
    directions = _directions(2048)
    for view in views:
        origins = np.broadcast_to(view.world_T_cam[:3, 3].numpy(), directions.shape)
        hits = renderer.cast(origins, directions)
        back = renderer.back_facing(hits, directions).numpy()
        # no camera inside geometry: it sees surfaces from the front (a ray that grazes a box's edge
        # may meet the millimetre by which its faces overlap from behind: a few in a thousand)
        assert back.mean() < 0.005, f"{name}: {int(back.sum())} rays from {view.name} meet a back face"
        # closed around the cameras (the window's courtyard is open to the sky above, which its
        # backdrop hides from the room: only the bake's rays reach it)
        assert hits.hit.all(), f"{name} is closed: every ray from {view.name} meets a surface"


def test_probes_are_deterministic_per_seed_and_vary_with_it() -> None:
    for name in PROBES:
        first, again, other = probe_scene(name, 1), probe_scene(name, 1), probe_scene(name, 2)
        assert np.array_equal(first.vertices, again.vertices)
        assert first.name == f"probe_{name}_1"
        assert not (first.vertices.shape == other.vertices.shape and np.allclose(first.vertices, other.vertices)), (
            f"{name}: seeds 1 and 2 give the same room"
        )


def test_an_unknown_probe_is_named_with_the_list() -> None:
    with pytest.raises(ValueError, match=r"no probe scene 'nope'; the probes are: photo_wall, grazing_floor"):
        probe_scene("nope")


def test_the_mirror_probe_shows_the_room_on_the_mirrors_plane_and_kadv_tiny_reads_its_init_views() -> None:
    scene = probe_scene("mirror", seed=0)
    renderer = ExactRenderer(scene, Shading(lighting="direct"), progress=False)
    glass = [index for index, material in enumerate(scene.materials) if material.mirror]
    views = file_init_views(renderer, PenaltyConfig().margin)
    model = load_model("kadv_tiny")
    for view in views:
        out = renderer.render(view.world_T_cam, intrinsics_from_fov(view.fov_x_deg, 96, 128), 96, 128)
        on_mirror = torch.from_numpy(np.isin(scene.material_ids, glass))[out.triangle_ids.clamp_min(0)] & out.mask
        assert on_mirror.float().mean() > 0.1, f"{view.name} sees the mirror"
        # the depth is the mirror's plane (x = 0.05), and the mirror shows the room, not its own grey
        torch.testing.assert_close(out.points[:, 0:1][on_mirror], torch.full((int(on_mirror.sum()),), 0.05))
        assert out.rgb.permute(1, 0, 2, 3)[:, on_mirror[:, 0]].std(dim=1).min() > 0.05
        delta1 = depth_metrics(model(out.rgb), out.depth, out.mask, "disparity")["delta1"]
        assert delta1 > 0.85, f"kadv-tiny reads {view.name} (delta1 {float(delta1):.3f})"


def test_every_probe_has_its_scene_config() -> None:
    folder = Path(__file__).resolve().parents[2] / "conf" / "scene" / "probe"
    assert sorted(path.stem for path in folder.glob("*.yaml")) == sorted(PROBES)
