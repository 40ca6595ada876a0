from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import imageio_ffmpeg
import numpy as np
import pytest
import torch
from omegaconf import OmegaConf
from PIL import Image
from transformers import CHMv2Config

from kadv import box_room
from kadv.cli.attack import main as attack_main
from kadv.cli.render import main as render_main
from kadv.cli.train_tiny import main as train_tiny_main
from kadv.geometry import axis_angle_to_matrix, yaw_pitch_roll
from kadv.report.outputs import read_trajectory
from kadv.report.summary import SCHEMA_VERSION, RunSummary
from tests.cli.in_process import call_main
from tests.models.tiny_marigold import save_tiny_marigold

BIN = Path(sys.executable).parent
SMALL = [
    "render.height=48",
    "render.width=64",
    "attack=gradient",
    "attack.gradient.steps=4",
    "attack.gradient.restarts=2",
    "init.count=2",
    "init.candidates=8",
    "progress=false",
]


def _command(tool: str, run_dir: Path, *overrides: str) -> list[str]:
    return [str(BIN / tool), f"hydra.run.dir={run_dir}", *overrides]


def _run(tool: str, cwd: Path, run_dir: str, *overrides: str, env: dict | None = None) -> subprocess.CompletedProcess:
    return subprocess.run(
        _command(tool, cwd / run_dir, *overrides),
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=600,
        env={**os.environ, **(env or {})},
    )


_MAINS = {"kadv-attack": attack_main, "kadv-render": render_main, "kadv-train-tiny": train_tiny_main}


def _run_in_process(tool: str, run_dir: Path | None, *overrides: str) -> subprocess.CompletedProcess:
    """``tool`` called as its console script would call it (in ``run_dir``), in this process."""
    return call_main(_MAINS[tool], [tool, *([f"hydra.run.dir={run_dir}"] if run_dir is not None else []), *overrides])


@pytest.fixture(scope="module")
def demo_runs(tmp_path_factory) -> Path:
    """Two runs of one config to compare: one through the installed script with its video, one in
    this process without."""
    root = tmp_path_factory.mktemp("attack")
    result = _run("kadv-attack", root, "first", *SMALL, "video=true")
    assert result.returncode == 0, result.stderr
    result = _run_in_process("kadv-attack", root / "second", *SMALL, "video=false")
    assert result.returncode == 0, result.stderr
    return root


def test_two_runs_of_one_config_write_identical_trajectories(demo_runs: Path) -> None:
    first = (demo_runs / "first" / "trajectory.csv").read_bytes()
    assert first == (demo_runs / "second" / "trajectory.csv").read_bytes()
    rows = first.decode().splitlines()
    assert len(rows) == 1 + 2 * 2 * 5  # header + init views x restarts x (steps + 1)
    header = rows[0].split(",")
    for column in (
        "step",
        "restart",
        "theta_x",
        "c_z",
        "l_depth",
        "l_dist",
        "objective",
        "delta1",
        "abs_rel",
        "verdict",
        "guard_fraction",
        "coverage",
        "rgb_error",
        "depth_error",
        "refreshed",
    ):
        assert column in header


def test_run_directory_holds_every_artefact(demo_runs: Path) -> None:
    run = demo_runs / "first"
    summary = json.loads((run / "summary.json").read_text())
    assert summary["complete"] and summary["seed"] == 0 and summary["device"] == "cpu"
    # every delta1 and AbsRel in it after a scale-and-shift fit in disparity space: the relative model's own
    assert (summary["alignment"], summary["space"]) == ("scale_shift", "disparity")
    assert {"torch", "kornia", "kadv"} <= set(summary["versions"])
    assert len(summary["init_views"]) == 2
    init_params = json.loads((run / "init_params.json").read_text())["init_views"]
    assert [v["name"] for v in init_params] == [v["name"] for v in summary["init_views"]]
    for view in summary["init_views"]:
        assert view["budget"]["forward"] == 10 and view["budget"]["backward"] == 8
        assert view["agreement"] | {"worsts": None} == {
            "reached": 1, "runs": 1, "planned": 1, "worsts": None, "tolerance": 0.03, "alone": True,
            "stopped_early": False,
        }  # fmt: skip
        for entry in [view["init"], *view["adversarial"]]:
            with Image.open(run / entry["png"]) as image:
                assert image.size[0] > 4 * 64
            arrays = np.load(run / entry["png"].replace(".png", ".npz"))
            assert arrays["rgb"].shape == (48, 64, 3) and arrays["depth"].shape == (48, 64)
            assert arrays["world_T_cam"].shape == (4, 4) and arrays["K"].shape == (3, 3)
            assert np.allclose(arrays["world_T_cam"][:3, 3], entry["centre"])
        assert all(a["loss"] >= b["loss"] for a, b in zip(view["adversarial"], view["adversarial"][1:]))
    for picture in ("loss.png", "map.png"):
        with Image.open(run / picture) as image:
            assert min(image.size) > 200
    assert (run / "trajectory.mp4").stat().st_size > 1000
    assert not (demo_runs / "second" / "trajectory.mp4").exists()
    assert "attack" in (run / "config.yaml").read_text()
    # each row ends with the view's yaw, pitch and roll, the same as its rotation gives them, and
    # its field of view: the init view's, as the search did not set it
    rows = list(csv.DictReader((run / "trajectory.csv").open()))
    assert list(rows[0])[-4:] == ["yaw_deg", "pitch_deg", "roll_deg", "fov_x_deg"]
    assert {float(r["fov_x_deg"]) for r in rows} == {70.0} and "fov_offset_deg" not in rows[0]
    theta = torch.tensor([[float(r[f"theta_{a}"]) for a in "xyz"] for r in rows], dtype=torch.float64)
    angles = torch.rad2deg(yaw_pitch_roll(axis_angle_to_matrix(theta)))
    written = torch.tensor([[float(r[k]) for k in ("yaw_deg", "pitch_deg", "roll_deg")] for r in rows])
    assert torch.allclose(written.double(), angles, atol=1e-6)


def test_the_video_is_h264_yuv420p_with_four_tall_panels_and_the_plan_per_step(demo_runs: Path) -> None:
    run = demo_runs / "first"
    reader = imageio_ffmpeg.read_frames(str(run / "trajectory.mp4"))
    meta = next(reader)
    frames = list(reader)
    assert meta["codec"] == "h264" and meta["pix_fmt"].startswith("yuv420p"), meta
    width, height = meta["size"]
    # four panels of 240 x 320 (the 48 x 64 renders, upscaled) and the 240 x 240 plan, under a 28 px band
    assert (width, height) == (4 * 320 + 240, 28 + 240)
    # one frame per evaluated view of the init view that lost the most delta1: 2 restarts x 5 steps
    assert len(frames) == 10
    first = np.frombuffer(frames[0], np.uint8).reshape(height, width, 3)
    assert first[:28].mean() < first[28:].mean()  # the text band above the panels


def test_a_complete_run_is_skipped(demo_runs: Path) -> None:
    run = demo_runs / "second"
    before = {p: p.stat().st_mtime_ns for p in run.rglob("*") if p.is_file() and ".hydra" not in p.parts}
    result = _run_in_process("kadv-attack", run, *SMALL, "video=false")
    assert result.returncode == 0 and "already complete" in result.stdout
    assert before == {p: p.stat().st_mtime_ns for p in run.rglob("*") if p.is_file() and ".hydra" not in p.parts}


def test_a_run_directory_made_with_other_settings_is_refused_naming_them(demo_runs: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(demo_runs / "second", run)
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and ".hydra" not in p.parts}
    # a changed setting (here a changed default would do the same): the old results must not pass for these
    result = _run_in_process("kadv-attack", run, *SMALL, "video=false", "attack.top_n=2")
    assert result.returncode == 2 and "Traceback" not in result.stderr
    line = f"kadv-attack: error: {run} holds a run made with other settings (attack.top_n: 5 -> 2): remove it"
    assert line in result.stderr and "already complete" not in result.stdout
    assert before == {p: p.read_bytes() for p in run.rglob("*") if p.is_file() and ".hydra" not in p.parts}
    # config.yaml names the lighting render.lighting=auto chose, and auto still matches it
    assert OmegaConf.load(run / "config.yaml").render.lighting == "baked"
    # how it shows its progress is not a setting of what it finds (SMALL has progress=false)
    shown = _run_in_process("kadv-attack", run, *SMALL, "video=false", "progress=true")
    assert shown.returncode == 0 and "already complete" in shown.stdout


def test_a_complete_run_removes_the_partial_results_a_kill_left_after_its_summary(
    demo_runs: Path, tmp_path: Path
) -> None:
    run = tmp_path / "run"
    shutil.copytree(demo_runs / "second", run)
    (run / "partial").mkdir()
    (run / "partial" / "init0.json").write_text("{}")  # killed after the summary, before removing this
    result = _run_in_process("kadv-attack", run, *SMALL, "video=false")
    assert result.returncode == 0 and "already complete" in result.stdout
    assert not (run / "partial").exists()


def test_a_finished_run_keeps_no_partial_results(demo_runs: Path) -> None:
    assert (demo_runs / "first" / "summary.json").is_file() and not (demo_runs / "first" / "partial").exists()


def test_unreadable_partial_files_are_set_aside_and_recomputed(demo_runs: Path, tmp_path: Path) -> None:
    run = tmp_path / "run"
    shutil.copytree(demo_runs / "second", run)
    (run / "summary.json").unlink()
    (run / "partial").mkdir()
    cut = run / "partial" / "init0.json"
    cut.write_text(f'{{"schema": {SCHEMA_VERSION}, "init": {{"index": 0')  # cut short mid-write by something else
    older = run / "partial" / "init1.json"
    older.write_text(json.dumps({"schema": SCHEMA_VERSION - 1, "records": []}))  # another kadv's results
    result = _run_in_process("kadv-attack", run, *SMALL, "video=false")
    assert result.returncode == 0, result.stderr
    warnings = [line for line in (result.stdout + result.stderr).splitlines() if "cannot be read" in line]
    assert len(warnings) == 2 and "init0.json" in warnings[0] and "init1.json" in warnings[1], warnings
    assert "Expecting" in warnings[0] and "schema version" in warnings[1]
    assert sorted(p.name for p in (run / "partial").iterdir()) == ["init0.json.unreadable", "init1.json.unreadable"]
    assert json.loads((run / "summary.json").read_text())["resumed_init_views"] == []
    assert (run / "trajectory.csv").read_bytes() == (demo_runs / "first" / "trajectory.csv").read_bytes()


def test_help_says_what_the_command_does_and_writes() -> None:
    result = _run_in_process("kadv-attack", None, "--help")
    assert result.returncode == 0
    assert result.stdout.startswith("kadv-attack: finds camera views")
    for name in ("trajectory.csv", "summary.json", "init_params.json", "views/", "map.png"):
        assert name in result.stdout


def _inside_box_params(tmp_path: Path) -> Path:
    scene = box_room(seed=0)
    box = scene.vertices[scene.faces[scene.material_ids == 6]].reshape(-1, 3).mean(axis=0)
    pose = np.eye(4)
    pose[:3, 3] = box
    path = tmp_path / "inside.json"
    path.write_text(
        json.dumps(
            {
                "init_views": [
                    {
                        "name": "boxed",
                        "source": "given",
                        "world_T_cam": pose.tolist(),
                        "fov_x_deg": 70.0,
                        "delta1": None,
                        "note": "",
                    }
                ]
            }
        )
    )
    return path


BAD_INPUTS = [
    ("kadv-attack", ["scene=file", "scene.path=/no/such/scene.xml"], "/no/such/scene.xml"),
    ("kadv-attack", ["scene=file", "scene.path={corrupt}"], "corrupt.xml"),
    ("kadv-attack", ["attack=gradient", "attack.gradient.steps=-3"], "attack.gradient.steps"),
    ("kadv-attack", ["attack.method=adam"], "attack.method must be one of"),
    (
        "kadv-attack",
        ["attack=hybrid", "attack.hybrid.screen_scale=2"],
        "attack.hybrid.screen_scale must be in (0, 1], got 2",
    ),
    (
        "kadv-attack",
        ["attack.halving.screen_fraction=1.5"],
        "attack.halving.screen_fraction must be in (0, 1], got 1.5",
    ),
    (
        "kadv-attack",
        ["attack=turbo", "attack.turbo.length_min=2"],
        "attack.turbo needs 0 < length_min < length_init <= length_max, got 2, 0.8, 1.6",
    ),
    ("kadv-attack", ["attack=turbo", "attack.turbo.batch=0"], "attack.turbo.batch must be an integer >= 1, got 0"),
    # text where a number belongs, a number where an integer does, text for a flag: refused by kind
    ("kadv-attack", ["attack=turbo", "attack.turbo.batch=four"], "attack.turbo.batch must be an integer, got 'four'"),
    ("kadv-attack", ["attack.halving.lanes=2.5"], "attack.halving.lanes must be an integer, got 2.5"),
    ("kadv-attack", ["attack.halving.grow=big"], "attack.halving.grow must be a number, got 'big'"),
    ("kadv-attack", ["attack=cma", "attack.cma.ipop=maybe"], "attack.cma.ipop must be true or false, got 'maybe'"),
    ("kadv-attack", ["attack.halving.halve_every=-1"], "attack.halving.halve_every must be an integer >= 0, got -1"),
    (
        "kadv-attack",
        ["loss.alignment=none"],
        "loss.alignment=none scores the prediction as metric depth, but model kadv_tiny outputs relative disparity",
    ),
    ("kadv-attack", ["loss.alignment=affine"], "loss.alignment must be one of scale_shift, scale, none, got 'affine'"),
    ("kadv-attack", ["attack.restarts=0"], "attack.restarts must be an integer >= 1, got 0"),
    ("kadv-attack", ["attack.agreement_delta1=-1"], "attack.agreement_delta1 must be in [0, 1], got -1"),
    ("kadv-attack", ["attack.budget_evaluations=48"], "attack.budget_evaluations was renamed attack.budget_passes"),
    ("kadv-attack", ["penalty.probe_rays=256"], "penalty.probe_rays was renamed penalty.enclosure_rays"),
    ("kadv-attack", ["attack.halving.refine=adam"], "attack.halving.refine must be 'gradient' or 'local', got 'adam'"),
    ("kadv-attack", ["attack.budget_passes=1"], "attack.budget_passes must be at least 2 for attack.halving"),
    ("kadv-attack", ["attack.halving.screen_supersample=2"], "attack.halving.screen_supersample must be below render"),
    ("kadv-attack", ["loss=delta1", "loss.temperature=0"], "loss.temperature must be positive, got 0"),
    ("kadv-attack", ["loss.kind=rmse"], "loss.kind must be one of perceptual, ssim, absrel, delta1, got 'rmse'"),
    # a key the composed config lacks: Hydra's own message is five lines and exit 1
    ("kadv-attack", ["attack.gradient.steps=-3"], "attack has no key 'gradient'; it has: "),
    ("kadv-attack", ["camera.eye=[1,2"], "cannot parse the overrides"),
    ("kadv-attack", ["seed=1.5"], "seed must be an integer"),
    ("kadv-attack", ["attack=nevergrad", "attack.nevergrad.optimizer=NoSuchOpt"], "NGOpt"),
    ("kadv-attack", ["model.name=no_such_model"], "no_such_model"),
    ("kadv-attack", ["render.supersample=0"], "render.supersample"),
    ("kadv-attack", ["model=depth_anything_v2_small"], "depth_anything_v2_small"),
    ("kadv-attack", ["model=no_such_preset"], "no_such_preset"),
    ("kadv-attack", ["model=huggingface", "model.name={canopy}"], "canopy-height model"),
    ("kadv-attack", ["model=depth_pro", "model.output_kind=disparity"], "model.output_kind"),
    ("kadv-attack", ["model=custom", "model.target=no_such_package_kadv.make"], "no_such_package_kadv"),
    ("kadv-attack", ["model=custom", "model.target={wrong_model}:make"], "must map rgb"),
    ("kadv-attack", ["init.params={inside}"], "inside an object"),
    ("kadv-attack", ["init.params=/no/such/init_params.json"], "/no/such/init_params.json"),
    ("kadv-attack", ["device=tpu"], "device='tpu'"),
    ("kadv-attack", ["envelope=drone"], "envelope=drone: no such option in envelope/; one of: free, handheld"),
    ("kadv-attack", ["attack.radii=[[15,0.3],[5,0.1]]"], "attack.radii must increase (each holds the one before)"),
    ("kadv-attack", ["attack.radii=[[-5,0.1]]"], "attack.radii: each radius must be positive, got (-5, 0.1)"),
    (
        "kadv-attack",
        ["render.differentiable.cuda_graphs=maybe"],
        "render.differentiable.cuda_graphs must be true or false, got 'maybe'",
    ),
    ("kadv-attack", ["envelope.pitch_deg=[30,-30]"], "envelope.pitch_deg [30, -30] is empty or leaves [-90, 90]"),
    ("kadv-attack", ["envelope.fov_deg=[100,40]"], "envelope.fov_deg [100, 40] is empty or leaves (1, 179)"),
    ("kadv-attack", ["envelope.fov_deg=[40,180]"], "envelope.fov_deg [40, 180] is empty or leaves (1, 179)"),
    ("kadv-attack", ["attack.radius_shares=[1,2,3]"], "attack.radius_shares splits a profile's passes over its radii"),
    (
        "kadv-attack",
        ["attack.radii=[[5,0.1],[45,1.0]]", "attack.radius_shares=[1,2,3]"],
        "attack.radius_shares must be 2 positive numbers, one a radius, got [1, 2, 3]",
    ),
    ("kadv-attack", ["attack.radius_shares=[1,0]"], "attack.radius_shares must be null or positive numbers"),
    (
        "kadv-attack",
        ["envelope.height=[5,6]", "init.count=1"],
        "init view file0 lies outside the envelope custom (height 5 to 6 m): height",
    ),
    *([("kadv-attack", ["device=cuda"], "no CUDA device")] if not torch.cuda.is_available() else []),
    ("kadv-render", ["camera.eye=[1,1.5]", "camera.target=[3,1,3]", "camera.fov_x_deg=70"], "camera.eye"),
    ("kadv-render", ["camera.eye=[nan,1.5,1]", "camera.target=[3,1,3]", "camera.fov_x_deg=70"], "camera.eye"),
    ("kadv-render", ["camera.eye=[1,1.5,1]", "camera.fov_x_deg=70"], "camera.target"),
    ("kadv-render", ["render.supersample=0"], "render.supersample"),
    ("kadv-render", ["render.heigth=100"], "render has no key 'heigth'; it has: height"),
    ("kadv-render", ["render.lighting=sunny"], "render.lighting must be one of direct, baked, scanned, got 'sunny'"),
    ("kadv-render", ["render.lighting=baked", "render.bake.rays=0"], "render.bake.rays must be an integer >= 1"),
    ("kadv-render", ["render.bake.filter_width=0"], "render.bake.filter_width must be a positive number, got 0"),
    ("kadv-attack", ["render.lighting=baked", "+render.bake.samples=4"], "render.bake.samples"),
    ("kadv-attack", ["+render.foo=1"], "+render.foo=1: render has no key 'foo'; it has: height, width"),
    ("kadv-render", ["+render.shading.glow=2"], "render.shading has no key 'glow'; it has: ambient"),
    ("kadv-attack", ["render.backend=bogus"], "render.backend must be one of auto, open3d, warp, got 'bogus'"),
    ("kadv-attack", ["render.max_rays=0"], "render.max_rays must be an integer >= 1, got 0"),
    ("kadv-render", ["scene=procedural", "scene.seed=abc"], "scene.seed must be an integer, got 'abc'"),
    ("kadv-render", ["scene=procedural", "scene.stairs_share=2"], "scene.stairs_share must be in [0, 1], got 2.0"),
    ("kadv-render", ["scene=file", "scene.path=/no/such/room.glb"], "/no/such/room.glb"),
    ("kadv-attack", ["model=marigold_depth_v1_1", "model.steps=0"], "model.steps must be at least 1, got 0"),
    (
        "kadv-attack",
        ["model=marigold_depth_v1_1", "model.weights={marigold}", "model.ensemble_size=3"],
        "attack.method=halving follows the gradient",
    ),
    ("kadv-train-tiny", ["train.steps=-1"], "train.steps"),
    ("kadv-train-tiny", ["train.seed=7"], "the held-out rooms"),
    ("kadv-train-tiny", ["train.hall_share=1.2"], "train.hall_share (1.2)"),
    ("kadv-train-tiny", ["train.squeeze_share=2"], "train.squeeze_share must be in [0, 1]"),
    ("kadv-train-tiny", ["train.baked_share=-1"], "train.baked_share must be in [0, 1]"),
    ("kadv-train-tiny", ["train.sun_share=-1"], "train.sun_share must be in [0, 1]"),
    ("kadv-train-tiny", ["train.bake.rays=0"], "train.bake.rays must be an integer >= 1"),
    ("kadv-train-tiny", ["train.device=tpu"], "train.device='tpu'"),
    ("kadv-train-tiny", ["train.init_weights=/no/such/tiny.safetensors"], "/no/such/tiny.safetensors"),
    ("kadv-train-tiny", ["train.soup_with=[/no/such/soup.safetensors]"], "train.soup_with: no such weights file"),
]
# small images keep the attack and render cases fast; kadv-train-tiny has no render keys
_SIZE = {"kadv-attack": SMALL[:2], "kadv-render": SMALL[:2]}
_DIRECT = {"kadv-attack": ["render.lighting=direct"], "kadv-render": ["render.lighting=direct"]}


def _bad_input_case(case: int, root: Path, values: dict, in_process: bool) -> subprocess.CompletedProcess:
    tool, overrides, _ = BAD_INPUTS[case]
    overrides = [o.format(**values) for o in overrides]
    # the cases that reach a render need no bake (a fresh cache), unless about lighting
    direct = [] if any("lighting" in o or "bake" in o for o in overrides) else _DIRECT.get(tool, [])
    overrides = [*_SIZE.get(tool, []), *direct, *overrides]
    if in_process:
        return _run_in_process(tool, root / f"run{case}", *overrides)
    return _run(tool, root, f"run{case}", *overrides, env=_OFFLINE)


_OFFLINE = {"HF_HUB_OFFLINE": "1", "HYDRA_FULL_ERROR": "0"}
# one case per command also goes through its installed console script, in its own process
_THROUGH_SCRIPTS = {tool: next(i for i, case in enumerate(BAD_INPUTS) if case[0] == tool) for tool in _MAINS}


@pytest.fixture(scope="module")
def bad_input_values(tmp_path_factory) -> tuple[Path, dict]:
    root = tmp_path_factory.mktemp("bad_inputs")
    corrupt = root / "corrupt.xml"
    corrupt.write_text("<scene version='0.6.0'><shape type='obj'>")
    wrong_model = root / "wrong_model.py"
    wrong_model.write_text("import torch\n\ndef make():\n    return torch.nn.Conv2d(3, 2, 1)\n")
    canopy = root / "canopy"
    CHMv2Config().save_pretrained(canopy)  # refused on its config, before any weights are read
    values = {"corrupt": corrupt, "inside": _inside_box_params(root), "wrong_model": wrong_model, "canopy": canopy}
    return root, {**values, "marigold": save_tiny_marigold(root / "marigold")}


@pytest.fixture(scope="module")
def bad_input_results(bad_input_values) -> dict[int, subprocess.CompletedProcess]:
    """Every BAD_INPUTS case run once, in this process: each command is its ``main`` with the
    script's arguments, so the cases skip the seconds of importing that a process spends."""
    root, values = bad_input_values
    with pytest.MonkeyPatch.context() as patch:
        patch.chdir(root)
        for name, value in {**_OFFLINE, "HF_HOME": str(root / "hf")}.items():
            patch.setenv(name, value)
        return {case: _bad_input_case(case, root, values, in_process=True) for case in range(len(BAD_INPUTS))}


@pytest.mark.parametrize("tool", sorted(_THROUGH_SCRIPTS))
def test_bad_input_through_the_installed_script_gives_one_line_and_exit_status_2(tool, bad_input_values) -> None:
    root, values = bad_input_values
    case = _THROUGH_SCRIPTS[tool]
    result = _bad_input_case(case, root, values, in_process=False)
    assert result.returncode == 2, result.stderr
    assert result.stderr.strip().splitlines() == [f"{tool}: error: " + result.stderr.split(": error: ", 1)[1].strip()]
    assert BAD_INPUTS[case][2] in result.stderr and "Traceback" not in result.stderr


@pytest.mark.parametrize("case", range(len(BAD_INPUTS)), ids=[" ".join(o) for _, o, _ in BAD_INPUTS])
def test_bad_input_gives_one_line_and_exit_status_2(case: int, bad_input_results, bad_input_values) -> None:
    tool, _, named = BAD_INPUTS[case]
    result = bad_input_results[case]
    assert result.returncode == 2, result.stderr
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1 and "Traceback" not in result.stderr, result.stderr
    assert lines[0].startswith(f"{tool}: error: ") and named in lines[0], lines[0]
    assert not (bad_input_values[0] / f"run{case}").exists()  # nothing is written, no run directory


def test_a_profile_run_records_its_profile_in_the_summary(tmp_path: Path) -> None:
    radii = "attack.radii=[[5,0.1],[15,0.3]]"
    result = _run_in_process(
        "kadv-attack", tmp_path / "run", *SMALL, "render.lighting=direct", "init.count=1", "envelope=upright", radii
    )
    assert result.returncode == 0, result.stderr
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    profile = summary.profile
    assert profile["radii"] == [[5.0, 0.1], [15.0, 0.3]] and profile["envelope"] == "upright"
    assert profile["worst"][1] <= profile["worst"][0] <= profile["delta1_init"][0]  # nested: never rising
    assert 0.0 <= profile["score"] <= 1.0 and profile["score_spread"] == 0.0
    # the run itself searched the largest radius: no record moved further
    records = [r for view in read_trajectory(tmp_path / "run" / "trajectory.csv").values() for r in view]
    assert max(np.linalg.norm(r.params[3:]) for r in records) <= 0.3 + 1e-6
    assert "score " in result.stdout and "| 15°, 0.3 m |" in result.stdout
    assert (tmp_path / "run" / "profile.png").stat().st_size > 5_000


def test_a_profile_run_splits_its_passes_over_its_radii_by_their_shares(tmp_path: Path) -> None:
    small = [o for o in SMALL if not o.startswith("attack")]
    overrides = [
        "attack=random",
        "attack.budget_passes=12",
        "attack.radii=[[5,0.1],[15,0.3]]",
        "attack.radius_shares=[1,3]",
    ]
    result = _run_in_process(
        "kadv-attack", tmp_path / "run", *small, "render.lighting=direct", "init.count=1", *overrides
    )
    assert result.returncode == 0, result.stderr
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    # 12 passes a radius on average, 24 in all: a quarter to 5°/0.1 m, three quarters to 15°/0.3 m
    assert [view.budget.passes for view in summary.init_views] == [18]
    assert summary.profile["cost_by_seed"][0]["search_passes"] == 24


def test_a_run_with_restarts_says_beside_each_worst_how_many_runs_reached_it(tmp_path: Path) -> None:
    overrides = ["attack=halving", "attack.budget_passes=30", "attack.restarts=3", "attack.agreement_delta1=1"]
    small = [o for o in SMALL if not o.startswith("attack")]
    result = _run_in_process("kadv-attack", tmp_path / "run", *small, "render.lighting=direct", *overrides)
    assert result.returncode == 0, result.stderr
    assert (
        "| delta1 init (scale_shift) | delta1 adv (scale_shift) | agreement |" in result.stdout
    )  # the alignment named
    assert result.stdout.count("| 2/2 (stopped early, of 3) |") == 2  # any two runs agree within 1
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    for view in summary.init_views:
        assert view.agreement.runs == 2 and view.agreement.planned == 3 and view.budget.passes == 20
    rows = list(csv.DictReader((tmp_path / "run" / "trajectory.csv").open()))
    assert {row["run"] for row in rows} == {"0", "1"}


def test_a_run_with_a_free_field_of_view_names_each_view_s_in_its_table_files_and_pictures(tmp_path: Path) -> None:
    small = [o for o in SMALL if not o.startswith("attack")]
    overrides = ["render.lighting=direct", "attack.budget_passes=20", "envelope.fov_deg=[40,100]"]
    result = _run_in_process("kadv-attack", tmp_path / "run", *small, *overrides)
    assert result.returncode == 0, result.stderr
    assert "| agreement | fov init | fov adv (40° to 100°) |" in result.stdout
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    assert summary.fov_deg == [40.0, 100.0]
    for view in summary.init_views:
        assert view.fov_x_deg == 70.0 and view.init.fov_x_deg == 70.0  # the init views keep their own
        fovs = [a.fov_x_deg for a in view.adversarial]
        assert all(40.0 <= f <= 100.0 for f in fovs)
        assert f"| 70° | {', '.join(f'{f:.0f}°' for f in fovs)} |" in result.stdout
        for metrics in [view.init, *view.adversarial]:  # each picture's camera is its view's
            K = np.load(tmp_path / "run" / metrics.png.replace(".png", ".npz"))["K"]
            assert np.allclose(K[0, 0], 32.0 / np.tan(np.radians(metrics.fov_x_deg) / 2))
    records = [r for view in read_trajectory(tmp_path / "run" / "trajectory.csv").values() for r in view]
    assert all(len(r.params) == 7 and r.fov_x_deg == pytest.approx(70.0 + r.params[6]) for r in records)
    assert len({round(r.fov_x_deg, 3) for r in records}) > 10  # the search moved it


def test_the_metric_model_s_command_names_its_alignment_and_each_view_s_field_of_view(tmp_path: Path) -> None:
    """``kadv-attack model=kadv_tiny_metric loss.alignment=none envelope.fov_deg=[40,100]``, at a
    small size: the embedded metric model scored in metres with the field of view searched."""
    command = ["model=kadv_tiny_metric", "loss.alignment=none", "envelope.fov_deg=[40,100]"]
    small = [o for o in SMALL if not o.startswith("attack")]
    result = _run_in_process("kadv-attack", tmp_path / "run", *small, "attack.budget_passes=20", *command)
    assert result.returncode == 0, result.stderr
    header = "| delta1 init (none) | delta1 adv (none) | agreement | fov init | fov adv (40° to 100°) |"
    assert header in result.stdout
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    assert summary.model == "kadv_tiny_metric" and summary.alignment == "none" and summary.fov_deg == [40.0, 100.0]
    for view in summary.init_views:
        assert all(40.0 <= a.fov_x_deg <= 100.0 for a in view.adversarial) and view.adversarial
