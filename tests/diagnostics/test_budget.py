"""kadv.diagnostics.budget: the error budget names the part of a render that differs."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.diagnostics.budget import TERMS, KadvTerms, MitsubaTerms, error_budget, save_budget_figure
from kadv.diagnostics.reference import PIXEL_CLASSES, display_image
from kadv.geometry import intrinsics_from_fov, look_at
from kadv.render import BakeConfig, ExactRenderer, Shading
from kadv.scenes import box_room, load_scene

_DIFFUSE, _COATED = PIXEL_CLASSES.index("diffuse"), PIXEL_CLASSES.index("coated or glossy")


def _views(rng: np.random.Generator) -> tuple[dict, dict]:
    """kadv's and Mitsuba's parts of one 9 x 21 view that agree everywhere: grey light (the exposure
    matches the median of the channels' mean, in display values), 56% of the pixels bright and coated
    (they set that median: an odd count, a pixel's own), 44% darker and diffuse."""
    height, width = 9, 21
    classes = np.full((height, width), _COATED)
    classes[:4] = _DIFFUSE
    light = rng.uniform(0.5, 1.0, (3, height, width, 1)) * np.where(classes == _COATED, 0.3, 0.05)[None, ..., None]
    light = light.repeat(3, axis=-1)
    parts = dict(zip(TERMS, light)) | {"albedo": rng.uniform(0.2, 0.8, (height, width, 3))}
    parts["full"] = sum(parts[t] for t in TERMS)
    ours = parts | {"mask": np.ones((height, width), bool)}
    return ours, {k: v.copy() for k, v in parts.items()} | {"classes": classes}


def test_identical_renders_lose_nothing_anywhere():
    ours, theirs = _views(np.random.default_rng(0))
    budget = error_budget(ours, theirs)
    assert budget.psnr > 100
    assert all(abs(gain) < 1e-6 for gain in budget.gains.values())
    assert budget.best_exposure == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("term", TERMS)
def test_the_term_that_differs_is_the_one_that_gains(term):
    """Mitsuba's ``term`` is 1.5 times kadv's on the diffuse pixels only (the median, on the coated
    ones, keeps the exposure at 1): making that term exact restores the image, no other term helps,
    and the error lies on the diffuse pixels."""
    ours, theirs = _views(np.random.default_rng(1))
    diffuse = (theirs["classes"] == _DIFFUSE)[..., None]
    extra = np.where(diffuse, 0.5 * theirs[term], 0.0)
    theirs[term] = theirs[term] + extra
    theirs["full"] = theirs["full"] + extra
    budget = error_budget(ours, theirs)
    assert budget.psnr < 45
    assert budget.psnr + budget.gains[term] > 100
    assert all(abs(budget.gains[other]) < 1e-3 for other in TERMS if other != term)
    assert budget.class_error["diffuse"] == pytest.approx(1.0)
    assert budget.class_gains["diffuse"] > 50 and budget.class_gains["coated or glossy"] == pytest.approx(0.0)


def test_a_diffuse_albedo_off_by_a_quarter_is_the_albedos_loss():
    ours, theirs = _views(np.random.default_rng(2))
    diffuse = (theirs["classes"] == _DIFFUSE)[..., None]
    for part in (*TERMS, "full", "albedo"):
        theirs[part] = np.where(diffuse, 1.25 * theirs[part], theirs[part])
    budget = error_budget(ours, theirs)
    assert budget.psnr < 45 and budget.psnr + budget.gains["albedo"] > 100
    # the same error made exact by scaling all three terms at once is no single term's
    assert all(budget.gains[t] < budget.gains["albedo"] for t in TERMS)


def test_a_wrong_exposure_is_found_and_counted():
    """Mitsuba's image twice as bright on every pixel but the coated third that sets its median:
    a smaller exposure scale than the median's fits better."""
    ours, theirs = _views(np.random.default_rng(3))
    for part in (*TERMS, "full"):
        theirs[part] = np.where((theirs["classes"] == _DIFFUSE)[..., None], 2.0 * theirs[part], theirs[part])
    budget = error_budget(ours, theirs)
    assert budget.gains["exposure"] > 0.5 and budget.best_exposure < 1.0


_OPEN_CORNER = """<scene version="0.6.0">
  <bsdf type="diffuse" id="floor"><rgb name="reflectance" value="0.6, 0.5, 0.4"/></bsdf>
  <bsdf type="plastic" id="box"><rgb name="diffuseReflectance" value="0.2, 0.3, 0.7"/></bsdf>
  <shape type="rectangle"><transform name="toWorld"><scale value="3"/><rotate x="1" angle="-90"/></transform>
    <ref id="floor"/></shape>
  <shape type="rectangle"><transform name="toWorld"><scale value="3"/><translate z="-3" y="1"/></transform>
    <ref id="floor"/></shape>
  <shape type="cube"><transform name="toWorld"><scale value="0.4"/><translate y="0.4" z="-1"/></transform>
    <ref id="box"/></shape>
  <emitter type="constant"><rgb name="radiance" value="0.3"/></emitter>
  <emitter type="directional"><vector name="direction" x="0.3" y="-1" z="-0.4"/>
    <rgb name="irradiance" value="3"/></emitter>
</scene>
"""


@pytest.mark.reference
def test_kadv_and_mitsuba_split_the_light_alike(tmp_path):
    """A floor and a wall under a sun and a uniform sky, with a plastic box: kadv's terms add up to
    its image, each term's share of the light is Mitsuba's, and Mitsuba's pixel classes name the box
    coated, the floor diffuse and the open top sky."""
    (tmp_path / "scene.xml").write_text(_OPEN_CORNER)
    shading = Shading(lighting="baked", bake=BakeConfig(cache=str(tmp_path / "cache"), texel=0.1))
    renderer = ExactRenderer(load_scene(tmp_path / "scene.xml"), shading, progress=False)
    pose = look_at(torch.tensor([0.5, 1.5, 3.0]), torch.tensor([0.0, 0.3, -1.5])).double()
    height, width = 24, 32
    ours = KadvTerms(renderer).render(pose, intrinsics_from_fov(60.0, height, width), height, width)
    theirs = MitsubaTerms(tmp_path / "scene.xml", [(pose.numpy(), 60.0)], height, width, 64).render(0)
    surface = ours["mask"] & np.isin(theirs["classes"], (_DIFFUSE, _COATED))
    residual = ours["full"] - sum(ours[t] for t in TERMS)
    assert np.abs(residual[surface]).mean() < 0.02 * ours["full"][surface].mean()
    for term in TERMS:
        share = [parts[term][surface].mean() / parts["full"][surface].mean() for parts in (ours, theirs)]
        assert share[0] == pytest.approx(share[1], rel=0.1), term
    counts = np.bincount(theirs["classes"].ravel(), minlength=len(PIXEL_CLASSES))
    assert counts[_DIFFUSE] > 0.5 * height * width and counts[_COATED] > 10
    assert (
        counts[PIXEL_CLASSES.index("sky")] > 10
        and not ours["mask"][theirs["classes"] == PIXEL_CLASSES.index("sky")].any()
    )
    budget = error_budget(ours, theirs)
    path = save_budget_figure(tmp_path / "budget.png", budget, display_image(theirs["full"]), "open corner")
    assert path.stat().st_size > 10_000


def test_the_budget_needs_baked_lighting_and_a_bake_needs_a_baked_renderer():
    direct = ExactRenderer(box_room(seed=0))
    with pytest.raises(ValueError, match=r"render\.lighting=baked"):
        KadvTerms(direct)
    with pytest.raises(ValueError, match=r"render\.lighting=direct"):
        ExactRenderer(direct.scene, baked=object())
