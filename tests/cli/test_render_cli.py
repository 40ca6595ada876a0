"""kadv-render: its files through the installed script, and the README's examples and the views it
must refuse through its ``main`` in this process (the script's start proves nothing more there)."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from kadv.cli.render import main as render_main
from tests.cli.in_process import call_main
from tests.conftest import scenes_root

pytestmark = pytest.mark.real_scenes

SCRIPT = Path(sys.executable).parent / "kadv-render"
README = Path(__file__).resolve().parents[2] / "README.md"


def _environment(cache: Path | None) -> dict[str, str]:
    env = {"KADV_SCENES": str(scenes_root()), "HYDRA_FULL_ERROR": "0"}
    return env | ({"KADV_CACHE": str(cache)} if cache is not None else {})


def _script(cwd: Path, *overrides: str) -> subprocess.CompletedProcess:
    """The installed kadv-render in ``cwd``, in its own process."""
    return subprocess.run(
        [str(SCRIPT), "hydra.run.dir=run", *overrides],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=300,
        env={**os.environ, **_environment(None)},
    )


def _run(cwd: Path, *overrides: str, cache: Path | None = None) -> subprocess.CompletedProcess:
    """kadv-render as its script would call it, in ``cwd`` but in this process."""
    return call_main(render_main, ["kadv-render", "hydra.run.dir=run", *overrides], cwd, _environment(cache))


def test_installed_script_writes_aligned_images_raw_depth_and_a_summary(tmp_path: Path) -> None:
    result = _script(tmp_path, "render.height=60", "render.width=80")
    assert result.returncode == 0, result.stderr
    run = tmp_path / "run"
    with Image.open(run / "rgb.png") as rgb, Image.open(run / "mask.png") as mask:
        assert rgb.size == mask.size == (80, 60) and rgb.mode == "RGB"
        mask_array = np.asarray(mask)[..., 0] > 127
    with Image.open(run / "depth_vis.png") as figure:
        assert figure.size[0] > 80  # the colour bar widens the figure
    depth = np.load(run / "depth.npy")
    assert depth.shape == (60, 80) and depth.dtype == np.float32
    assert np.array_equal(depth > 0, mask_array)
    summary = json.loads((run / "render.json").read_text())
    assert summary["hit_fraction"] == 1.0 and summary["scene"] == "box_room_0"
    assert summary["validity"]["verdict"] == "valid" and "valid" in result.stdout
    assert summary["depth_range_m"] == pytest.approx([float(depth.min()), float(depth.max())])
    assert np.asarray(summary["K"]).shape == (3, 3) and np.asarray(summary["world_T_cam"]).shape == (4, 4)


def test_baked_lighting_is_baked_once_then_read_from_the_cache(tmp_path: Path) -> None:
    size = ["render.height=30", "render.width=40", "render.bake.texel=0.25", "render.bake.rays=8"]
    images = {}
    for name, lighting in (("direct", "direct"), ("first", "baked"), ("second", "baked")):
        (tmp_path / name).mkdir()
        result = _run(tmp_path / name, *size, f"render.lighting={lighting}", cache=tmp_path / "cache")
        assert result.returncode == 0, result.stderr
        assert ("baking box_room_0" in result.stderr) == (name == "first")  # the bake's progress bar
        with Image.open(tmp_path / name / "run" / "rgb.png") as rgb:
            images[name] = np.asarray(rgb)
    assert len(list((tmp_path / "cache" / "lighting").glob("box_room_0-*.npz"))) == 1
    assert np.array_equal(images["first"], images["second"]) and not np.array_equal(images["first"], images["direct"])


def test_look_at_override_and_clear_error_for_bad_index(tmp_path: Path) -> None:
    ok = _run(
        tmp_path,
        "render.height=30",
        "render.width=40",
        "camera.eye=[1,1.5,1]",
        "camera.target=[3,1,3]",
        "camera.fov_x_deg=90",
    )
    assert ok.returncode == 0, ok.stderr
    bad = _run(tmp_path, "camera.index=5")
    assert bad.returncode == 2 and "camera.index=5" in bad.stderr


def _readme_render_examples() -> list[list[str]]:
    lines = re.findall(r"^\.venv/bin/kadv-render(.*?)(?:#.*)?$", README.read_text(), re.MULTILINE)
    return [line.split() for line in lines]


@pytest.mark.parametrize("overrides", _readme_render_examples(), ids=lambda o: " ".join(o)[:60])
def test_readme_examples_render_valid_views(overrides: list[str], tmp_path: Path) -> None:
    # the README names the scenes where a checkout finds them; tests honour KADV_TEST_SCENES
    small = [
        o.replace("../shared/scenes", str(scenes_root()))
        for o in overrides
        if not o.startswith(("render.width", "render.height"))
    ]
    result = _run(tmp_path, *small, "render.height=24", "render.width=32")
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "run" / "render.json").read_text())
    assert summary["validity"]["verdict"] == "valid" and summary["hit_fraction"] > 0.5


def test_the_file_camera_beside_a_wall_is_moved_clear(tmp_path: Path) -> None:
    result = _run(tmp_path, "scene=grey_white_room", "render.lighting=direct", "render.height=24", "render.width=32")
    assert result.returncode == 0, result.stderr
    assert "moved" in json.loads((tmp_path / "run" / "render.json").read_text())["camera"]


@pytest.mark.parametrize("eye, verdict", [("[3,1.5,-4]", "outside the scene"), ("[2.5,0.3,2.3]", "inside an object")])
def test_an_impossible_eye_is_refused_unless_allowed(eye: str, verdict: str, tmp_path: Path) -> None:
    camera = [
        f"camera.eye={eye}",
        "camera.target=[3,1,3.5]",
        "camera.fov_x_deg=70",
        "render.height=24",
        "render.width=32",
    ]
    refused = _run(tmp_path, *camera)
    assert refused.returncode == 2 and len(refused.stderr.strip().splitlines()) == 1, refused.stderr
    assert verdict in refused.stderr and "camera.allow_invalid=true" in refused.stderr
    assert not (tmp_path / "run" / "rgb.png").exists()
    allowed = _run(tmp_path, *camera, "camera.allow_invalid=true")
    assert allowed.returncode == 0, allowed.stderr
    assert json.loads((tmp_path / "run" / "render.json").read_text())["validity"]["verdict"] == verdict


def test_an_eye_on_a_wall_has_no_hits_in_its_mask(tmp_path: Path) -> None:
    """The box room's wall x = 0: an eye on its plane sees no depth, and the mask says so."""
    result = _run(
        tmp_path,
        "camera.eye=[0.0,1.5,2.0]",
        "camera.target=[-1,1.5,2.0]",
        "camera.fov_x_deg=70",
        "render.height=24",
        "render.width=32",
        "camera.allow_invalid=true",
    )
    assert result.returncode == 0, result.stderr
    summary = json.loads((tmp_path / "run" / "render.json").read_text())
    depth = np.load(tmp_path / "run" / "depth.npy")
    assert summary["validity"]["verdict"] != "valid"
    assert summary["hit_fraction"] == pytest.approx(float((depth > 0).mean()))
