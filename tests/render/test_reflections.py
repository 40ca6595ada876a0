"""Shading.reflections: coated surfaces mirror what they face, by their coat's Fresnel reflectance,
added per pixel to the exact render's image."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.geometry import intrinsics_from_fov, look_at
from kadv.render import BakeConfig, ExactRenderer, Shading, render_anchor, shading
from kadv.render.colour import coat_table, fresnel_reflectance, untone
from kadv.scenes import Emitters, Material, assemble_scene, box_room
from kadv.scenes.parts import facing, quad_part

SKY = 0.2
HEIGHT, WIDTH = 24, 32


def _floor(
    alpha: float, tmp_path, reflections: bool, max_rays: int = 2**22, sky: Emitters | None = None
) -> ExactRenderer:
    """A 200 m coated floor under a uniform sky (or ``sky``): every reflected ray meets the sky."""
    corners = np.array([[-100.0, 0.0, -100.0], [100.0, 0.0, -100.0], [100.0, 0.0, 100.0], [-100.0, 0.0, 100.0]])
    floor = quad_part(facing(corners, np.array([0.0, 1.0, 0.0])), 0, "floor")
    varnish = Material("varnish", base_color=np.full(3, 0.5), coat_ior=1.5, roughness=alpha)
    sky = sky or Emitters(sky_radiance=np.full(3, SKY))
    scene = assemble_scene([floor], [varnish], name=f"floor_{alpha}", emitters=sky)
    bake = BakeConfig(texel=50.0, rays=16, light_samples=1, cache=str(tmp_path))
    shading = Shading(lighting="baked", bake=bake, reflections=reflections)
    return ExactRenderer(scene, shading, progress=False, max_rays=max_rays)


EYE = torch.tensor([0.0, 1.5, 0.0])
POSE = look_at(EYE, torch.tensor([0.0, 0.0, -4.0])).double()
K = intrinsics_from_fov(70.0, HEIGHT, WIDTH)


@pytest.mark.parametrize("supersample", [1, 2])
def test_a_smooth_coat_trades_its_diffuse_counted_reflection_for_the_fresnel_weighted_sky(tmp_path, supersample):
    """Under a uniform sky, a smooth coat's radiance changes by (F(view angle) - its hemispherical
    mean) x the sky: darker face-on (F = 0.04 < 0.092), brighter at grazing angles; with s x s rays
    per pixel as with one, as the pixel-centre ray's reflection is added to each of the pixel's rays
    on the floor (the row at the horizon, whose pixels show the sky in part, is left out)."""
    renders = {
        on: _floor(0.0, tmp_path, on).render(POSE, K, HEIGHT, WIDTH, supersample=supersample) for on in (False, True)
    }
    floor = renders[False].mask[0, 0]
    edge = floor & ~torch.cat([floor[:1], floor[:-1]])  # the floor's top row, below the sky
    assert edge.sum() == WIDTH
    mask = floor & ~edge
    assert mask.sum() > 0.4 * HEIGHT * WIDTH
    points = renders[False].points[0].permute(1, 2, 0)[mask].double()
    cosine = (EYE.double() - points)[:, 1] / (EYE.double() - points).norm(dim=1)
    renderer = _floor(0.0, tmp_path, True)
    outside = coat_table(renderer.scene)[0, 2]
    expected = (fresnel_reflectance(cosine, 1.5) - outside) * SKY * renderer.baked.exposure
    change = untone(renders[True].rgb[0].permute(1, 2, 0)[mask]) - untone(renders[False].rgb[0].permute(1, 2, 0)[mask])
    np.testing.assert_allclose(change.numpy(), expected[:, None].expand(-1, 3).numpy(), atol=2e-3)
    assert change.min() < -0.005 and change.max() > 0.05  # both ways, as the angles span face-on to grazing


def test_a_rough_coat_renders_the_same_bytes_again_and_the_same_image_however_its_rays_are_batched(
    tmp_path, monkeypatch
):
    """The lobe's samples hang on each ray's direction, not on its place in a batch: rendered in
    parts, or with every row cast and masked as on a GPU, the image moves by float rounding only,
    as it does without reflections, not by a new draw of its noise."""
    whole = _floor(0.3, tmp_path, True).render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    again = _floor(0.3, tmp_path, True).render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    parts = _floor(0.3, tmp_path, True, max_rays=500).render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    assert torch.equal(whole, again)
    assert (whole - parts).abs().max() < 1e-6
    monkeypatch.setattr(shading, "_COMPACTING", ())  # every row cast, masked, as on a GPU
    masked = _floor(0.3, tmp_path, True).render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    assert (whole - masked).abs().max() < 1e-6
    smooth = _floor(0.0, tmp_path, True).render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    assert not torch.equal(whole, smooth)  # the roughness is read


def test_reflections_leave_a_scene_without_coats_as_it_was(tmp_path):
    scene = box_room(seed=0)
    bake = BakeConfig(texel=0.2, rays=16, light_samples=4, cache=str(tmp_path))
    pose = (
        scene.cameras[0].world_T_cam
        if scene.cameras
        else look_at(torch.tensor([1.0, 1.2, 1.0]), torch.tensor([2.0, 1.0, 3.0])).double()
    )
    off, on = (
        ExactRenderer(scene, Shading(lighting="baked", bake=bake, reflections=r), progress=False)
        .render(pose, K, HEIGHT, WIDTH)
        .rgb
        for r in (False, True)
    )
    assert torch.equal(off, on)
    with pytest.raises(ValueError, match=r"render\.shading\.reflections"):
        Shading(reflections="yes")


def _pixel_noise(image: torch.Tensor) -> float:
    """Mean absolute difference of horizontally neighbouring pixels of (3, H, W), on the floor's rows."""
    rows = image[:, image.shape[1] // 2 :]
    return float((rows[..., 1:] - rows[..., :-1]).abs().mean())


def test_a_rough_coats_single_reflection_rays_are_averaged_over_the_neighbouring_pixels(tmp_path, monkeypatch):
    """One ray per pixel through a rough lobe scatters from pixel to pixel; the render averages the
    mirrored light over its neighbours (a Gaussian of half the lobe's alpha), so that under a
    uniform sky the rough floor's reflection changes smoothly across the image, while its mean stays."""
    height, width = 96, 128
    K_fine = intrinsics_from_fov(70.0, height, width)
    off = _floor(0.3, tmp_path, False).render(POSE, K_fine, height, width).rgb[0].permute(1, 2, 0)
    change = {}
    for smoothing, share in ((shading._REFLECTION_SMOOTHING, shading._LOBE_SHARE), (1e-6, 0.0)):
        monkeypatch.setattr(shading, "_REFLECTION_SMOOTHING", smoothing)
        monkeypatch.setattr(shading, "_LOBE_SHARE", share)
        on = _floor(0.3, tmp_path, True).render(POSE, K_fine, height, width).rgb[0].permute(1, 2, 0)
        change[smoothing] = (untone(on) - untone(off)).permute(2, 0, 1)
    smoothed, single = change.values()
    assert _pixel_noise(single) > 2.0 * _pixel_noise(smoothed)
    floor = slice(height // 2, None)
    assert abs(float(smoothed[:, floor].mean() - single[:, floor].mean())) < 0.1 * float(single[:, floor].abs().mean())


def test_a_rough_coats_mirror_image_of_a_bright_patch_of_sky_is_averaged_over_a_share_of_its_lobe(
    tmp_path, monkeypatch
):
    """A floor of GGX alpha 0.3 under a sky with a bright patch ahead: a fixed 0.03 rad average of
    its single rays per pixel shows the patch's mirror image in blotches (few rays of the wide lobe
    meet it), as the grey room's floor showed its windows. Against the mean of 16 unaveraged renders
    whose rays are turned by 25 microradians (new lobe samples, the same image), at a quarter of the
    resolution, the render's relative RMS error is under 0.35 and under 0.6 of the fixed width's
    (measured 0.25 and 0.54; exposed values below white, so that no ray's light is clipped)."""
    sky = np.full((32, 64, 3), 0.5)
    sky[8:14, :3] = sky[8:14, -3:] = 4.0  # 15-45 degrees up, within 17 degrees of -z
    height, width = 96, 128
    K_fine = intrinsics_from_fov(70.0, height, width)

    def mirrored(turn: float) -> torch.Tensor:
        """(3, H / 4, W / 4) the light the reflections add to the view turned by ``turn`` m at 4 m."""
        pose = look_at(EYE, torch.tensor([turn, 0.0, -4.0])).double()
        on, off = (
            _floor(0.3, tmp_path, r, sky=Emitters(envmap=sky)).render(pose, K_fine, height, width).rgb[0]
            for r in (True, False)
        )
        assert on.max() < 0.99  # no ray's light clipped at white
        change = untone(on.permute(1, 2, 0)) - untone(off.permute(1, 2, 0))
        return torch.nn.functional.avg_pool2d(change.permute(2, 0, 1)[None], 4)[0]

    def error(image: torch.Tensor) -> float:
        return float((image - reference)[:, patch].pow(2).mean().sqrt() / reference[:, patch].mean())

    averaged = mirrored(0.0)
    monkeypatch.setattr(shading, "_LOBE_SHARE", 0.0)
    fixed = mirrored(0.0)
    monkeypatch.setattr(shading, "_REFLECTION_SMOOTHING", 1e-6)
    reference = torch.stack([mirrored(1e-4 * k) for k in range(16)]).mean(dim=0)
    patch = reference.mean(dim=0) > 0.1 * reference.mean(dim=0).max()  # where the patch shows
    assert patch.sum() > 100
    assert error(averaged) < 0.35 and error(averaged) < 0.6 * error(fixed)


def test_with_reflections_the_shading_stays_view_independent_and_an_anchors_colours_serve_the_render(tmp_path):
    """Reflections are added to the exact render's finished image, not to the shading: an anchor
    layer's colours (what the warp reprojects) are the same with them on as off, and a render fed
    those colours, triangles and reflection terms as its sub-pixel rays is the render that casts
    them itself."""
    on, off = _floor(0.3, tmp_path, True), _floor(0.3, tmp_path, False)
    anchors = {r is on: render_anchor(r, POSE[None], K, HEIGHT, WIDTH, supersample=2) for r in (on, off)}
    assert torch.equal(anchors[True].rgb, anchors[False].rgb)
    assert anchors[False].reflecting is None and anchors[True].reflecting.shape[1] == 6
    sub = {
        "sub_rgb": anchors[True].rgb[:, 0],
        "sub_ids": anchors[True].triangle_ids[:, 0],
        "sub_terms": anchors[True].reflecting,
    }
    fed = on.render(POSE, K, HEIGHT, WIDTH, supersample=2, **sub).rgb
    cast = on.render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb
    assert (fed - cast).abs().max() < 1e-6
    assert (cast - off.render(POSE, K, HEIGHT, WIDTH, supersample=2).rgb).abs().max() > 0.02
    for missing in ("sub_ids", "sub_terms"):
        with pytest.raises(ValueError, match=missing):
            on.render(POSE, K, HEIGHT, WIDTH, supersample=2, **{k: v for k, v in sub.items() if k != missing})
