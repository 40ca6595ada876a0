"""kadv.diagnostics.reference: Mitsuba 3 renders the same scene from the same camera as kadv does."""

from __future__ import annotations

import numpy as np
import pytest
import torch

from kadv.attack import file_init_views
from kadv.cli.attack import main as attack_main
from kadv.cli.report import main as report_main
from kadv.diagnostics.reference import compare_view, load_mitsuba_scene, mitsuba_depth, save_comparison
from kadv.geometry import intrinsics_from_fov, look_at
from kadv.models import load_model
from kadv.render import ExactRenderer
from kadv.scenes import load_scene
from tests.cli.in_process import call_main
from tests.conftest import cached_real_scene, scenes_root

pytestmark = pytest.mark.reference

_BOX = """<scene version="0.6.0">
  <bsdf type="roughconductor" id="metal"><float name="extEta" value="1"/></bsdf>
  <bsdf type="diffuse" id="wall"><texture type="bitmap" name="reflectance">
    <string name="filename" value="tex.png"/><string name="filterType" value="trilinear"/></texture></bsdf>
  <shape type="cube"><transform name="toWorld"><scale x="2" y="1.5" z="3"/></transform>
    <ref id="wall"/></shape>
  <shape type="sphere"><point name="center" x="0.5" y="-0.5" z="1"/><float name="radius" value="0.4"/>
    <ref id="metal"/></shape>
  <emitter type="sunsky"><vector name="sunDirection" x="0" y="1" z="0"/><float name="skyScale" value="2"/></emitter>
</scene>
"""


@pytest.fixture(scope="module")
def old_style_scene(tmp_path_factory) -> tuple:
    """A closed box with a sphere, written in the Mitsuba 0.6 dialect the gallery files use."""
    from PIL import Image

    folder = tmp_path_factory.mktemp("mitsuba06")
    Image.fromarray((np.random.default_rng(0).random((16, 16, 3)) * 255).astype(np.uint8)).save(folder / "tex.png")
    (folder / "scene.xml").write_text(_BOX)
    return folder / "scene.xml", ExactRenderer(load_scene(folder / "scene.xml"))


def test_old_dialect_loads_and_both_renderers_see_the_same_depth(old_style_scene):
    path, renderer = old_style_scene
    pose = look_at(torch.tensor([-1.0, 0.3, -2.0]), torch.tensor([0.5, -0.5, 1.0])).double()
    scene = load_mitsuba_scene(path, [(pose.numpy(), 60.0)], 24, 32, 4)
    assert len(scene.emitters()) == 2  # sunsky became a constant sky and a directional sun
    ours = renderer.render(pose, intrinsics_from_fov(60.0, 24, 32), 24, 32).depth[0, 0].double().numpy()
    theirs = mitsuba_depth(scene, 0, 24, 32)
    assert (theirs > 0).all() and (ours > 0).all()  # a closed box: every ray hits
    relative = np.abs(theirs - ours) / ours
    # the walls agree to float precision; kadv tessellates the sphere Mitsuba intersects analytically
    assert np.median(relative) < 1e-6 and relative.max() < 1e-2


def test_a_mirrored_camera_would_be_caught(old_style_scene):
    """The depth check is sensitive to the camera conversion: a camera turned half a turn differs."""
    path, renderer = old_style_scene
    pose = look_at(torch.tensor([-1.0, 0.3, -2.0]), torch.tensor([0.5, -0.5, 1.0])).double()
    turned = pose.clone()
    turned[:3, :2] *= -1  # the camera's x and y axes flipped: the image rotated by 180 degrees
    scene = load_mitsuba_scene(path, [(turned.numpy(), 60.0)], 24, 32, 4)
    ours = renderer.render(pose, intrinsics_from_fov(60.0, 24, 32), 24, 32).depth[0, 0].double().numpy()
    assert np.median(np.abs(mitsuba_depth(scene, 0, 24, 32) - ours) / ours) > 1e-2


@pytest.mark.real_scenes
def test_real_scene_depth_agrees_at_the_file_camera(tmp_path):
    """japanese_classroom: a sunsky, rough conductors with extEta, and a camera 2 cm from a wall."""
    name = "japanese_classroom"
    renderer = ExactRenderer(cached_real_scene(name))
    view = file_init_views(renderer, 0.1)[0]
    scene = load_mitsuba_scene(
        scenes_root() / name / "scene.xml", [(view.world_T_cam.numpy(), view.fov_x_deg)], 24, 32, 4
    )
    comparison = compare_view(scene, 0, renderer, load_model("kadv_tiny"), view.world_T_cam, view.fov_x_deg, 24, 32, 4)
    assert comparison.depth_rel_err <= 1e-3
    assert comparison.mitsuba_rgb.mean() > 0.05 and np.isfinite(comparison.psnr)
    assert 0.0 <= comparison.pred_delta1 <= 1.0
    from PIL import Image

    written = save_comparison(tmp_path / "view.png", {"direct": comparison, "again": comparison}, "test")
    assert Image.open(written).size[0] > 3 * 32


@pytest.mark.real_scenes
def test_kadv_report_reference_scores_each_adversarial_view_on_both_renderers(tmp_path):
    """kadv-report --reference on a run in a Mitsuba scene: one row per kept view and a mean drop;
    on a run in a generated room (no XML to give Mitsuba) one line and exit status 2."""
    from kadv.report.summary import RunSummary

    path = scenes_root() / "modern_hall" / "scene.xml"
    small = ["render.height=24", "render.width=32", "init.count=1", "init.candidates=8", "attack=random"]
    small += ["attack.budget_passes=12", "video=false", "progress=false", "render.lighting=direct"]
    # the commands' mains in this process: their scripts' own processes are tested in tests/cli
    for name, scene in (("xml", ["scene=file", f"scene.path={path}"]), ("box", ["scene=box_room"])):
        ran = call_main(attack_main, ["kadv-attack", f"hydra.run.dir={tmp_path / name}", *scene, *small], tmp_path)
        assert ran.returncode == 0, ran.stderr
    report = ["kadv-report", "--reference", "--reference-spp", "4", "--no-transfer", "--no-progress"]
    result = call_main(report_main, [*report, str(tmp_path / "xml")])
    assert result.returncode == 0, result.stderr
    summary = RunSummary.read(tmp_path / "xml" / "summary.json")
    lines = (tmp_path / "xml" / "report" / "reference_xml.csv").read_text().strip().splitlines()
    kept = sum(len(view.adversarial) for view in summary.init_views)
    assert len(lines) == 1 + kept + 1  # header, the kept views, the mean drops
    first = lines[1].split(",")
    assert abs(float(first[2]) - summary.init_views[0].init.delta1) < 1e-3  # kadv's init delta1, as the run scored it
    assert all(0.0 <= float(v) <= 1.0 for line in lines[1:-1] for v in line.split(",")[2:])
    refused = call_main(report_main, [*report, str(tmp_path / "box")])
    assert refused.returncode == 2 and "no run's scene is a Mitsuba XML file" in refused.stderr
    assert len(refused.stderr.strip().splitlines()) == 2  # the skipped run's line, then the error
    no_samples = [*report[:2], "--reference-spp", "0", *report[4:], str(tmp_path / "xml")]
    refused = call_main(report_main, no_samples)
    assert refused.returncode == 2 and "--reference-spp must be >= 1, got 0" in refused.stderr
