"""The sweep report on synthetic summary.json files of two methods, without a browser."""

from __future__ import annotations

import base64
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from kadv.attack.records import Budget
from kadv.report import write_report
from kadv.report.summary import SCHEMA_VERSION, AnytimePoint, InitViewSummary, RunSummary, ViewMetrics
from kadv.testing.profile import Profile


def _metrics(l_depth: float, delta1: float, png: str) -> ViewMetrics:
    return ViewMetrics(l_depth, 0.0, l_depth, l_depth, delta1, 0.1, [0.0, 0.0, 0.0], [1.0, 1.5, 1.0], 0, 0, png)


def _run(folder: Path, method: str, init: float, adversarial: float, delta1: tuple[float, float]) -> RunSummary:
    (folder / "views").mkdir(parents=True)
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "views" / "init0_adv0.png")
    Image.fromarray(np.zeros((4, 4, 3), np.uint8)).save(folder / "map.png")
    view = InitViewSummary(
        index=0,
        name="file0",
        source="file",
        note="",
        fov_x_deg=70.0,
        init_world_T_cam=np.eye(4).tolist(),
        init=_metrics(init, delta1[0], "views/init0.png"),
        adversarial=[_metrics(adversarial, delta1[1], "views/init0_adv0.png")],
        adversarial_mean={"l_depth": adversarial, "delta1": delta1[1], "abs_rel": 0.1},
        l_depth_gain=adversarial - init,
        anytime=[
            AnytimePoint(1, 0.1, init, delta1[0], 0.1, init),
            AnytimePoint(9, 2.0, adversarial, delta1[1], 0.2, adversarial),
        ],
        invalid_views=0,
        uninformative_views=0,
        guarded_steps=0,
        budget=Budget(10, 0, 3.0),
    )
    summary = RunSummary(
        "box_room_0",
        "kadv_tiny",
        "ssim",
        0,
        "cpu",
        96,
        128,
        [],
        32,
        method,
        init,
        delta1[0],
        adversarial,
        delta1[1],
        Budget(10, 0, 3.0),
        {"kadv": "0"},
        [view],
    )
    summary.write(folder / "summary.json")
    return summary


def test_a_summary_reads_back_equal_and_other_schemas_are_refused(tmp_path: Path) -> None:
    summary = _run(tmp_path / "run", "random", 0.05, 0.35, (0.98, 0.40))
    assert RunSummary.read(tmp_path / "run" / "summary.json") == summary
    text = (tmp_path / "run" / "summary.json").read_text()
    (tmp_path / "run" / "summary.json").write_text(text.replace(f'"schema": {SCHEMA_VERSION}', '"schema": 0'))
    with pytest.raises(ValueError, match=r"summary.json: schema version 0, this kadv reads"):
        RunSummary.read(tmp_path / "run" / "summary.json")
    (tmp_path / "run" / "summary.json").write_text(text.replace('"l_depth_gain"', '"gain"'))
    with pytest.raises(ValueError, match=r"summary.json: not a kadv run summary"):
        RunSummary.read(tmp_path / "run" / "summary.json")


def test_tables_for_each_method_delta1_drop_and_anytime_curves(tmp_path: Path) -> None:
    _run(tmp_path / "sweep" / "a", "gradient", 0.05, 0.15, (0.98, 0.80))
    _run(tmp_path / "sweep" / "b", "random", 0.05, 0.35, (0.98, 0.40))
    written = write_report([tmp_path / "sweep"], tmp_path / "out", progress=False)
    names = {path.name for path in written}
    assert {
        "table2_gradient.md",
        "table2_random.md",
        "table3_gradient.md",
        "table3_random.md",
        "methods.md",
        "curves.png",
        "report.html",
    } <= names
    assert "| kadv_tiny | 0.3500 | 0.4000 |" in (tmp_path / "out" / "table2_random.md").read_text()
    methods = (tmp_path / "out" / "methods.csv").read_text().splitlines()
    assert methods[0].split(",")[3:5] == ["L_depth gain", "delta1 drop"]
    drops = {line.split(",")[2]: float(line.split(",")[4]) for line in methods[1:]}
    assert drops == {"gradient": 0.98 - 0.80, "random": 0.98 - 0.40}
    html = (tmp_path / "out" / "report.html").read_text()
    assert "Anytime curves" in html and "(random attack)" in html  # the gallery's worst view: random's
    assert Image.open(tmp_path / "out" / "curves.png").size[0] > 300


def test_the_page_embeds_the_video_of_the_run_that_lost_the_most_delta1(tmp_path: Path) -> None:
    _run(tmp_path / "sweep" / "a", "gradient", 0.05, 0.15, (0.98, 0.80))
    _run(tmp_path / "sweep" / "b", "random", 0.05, 0.35, (0.98, 0.40))
    for name in ("a", "b"):
        (tmp_path / "sweep" / name / "trajectory.mp4").write_bytes(f"video of {name}".encode())
    write_report([tmp_path / "sweep"], tmp_path / "out", progress=False)
    html = (tmp_path / "out" / "report.html").read_text()
    embedded = "data:video/mp4;base64," + base64.b64encode(b"video of b").decode("ascii")
    assert f'<video controls muted loop playsinline src="{embedded}">' in html  # b lost 0.58, a 0.18
    (tmp_path / "sweep" / "b" / "trajectory.mp4").unlink()
    write_report([tmp_path / "sweep"], tmp_path / "out", progress=False)
    assert base64.b64encode(b"video of a").decode("ascii") in (tmp_path / "out" / "report.html").read_text()


def test_the_anytime_curve_follows_the_attacked_loss_which_never_falls(tmp_path: Path) -> None:
    from kadv.report.html import _anytime_gains
    from kadv.report.sweep import RunRecord

    _run(tmp_path / "run", "hybrid", 0.2, 0.16, (0.9, 0.1))
    summary = RunSummary.read(tmp_path / "run" / "summary.json")
    view = summary.init_views[0]
    # the incumbent by the attacked loss (delta1's error share) has a lower L_depth than the first:
    # the L_depth curve would fall, the loss's does not
    view.anytime = [
        AnytimePoint(1, 0.1, 0.20, 0.9, 0.1, 0.05),
        AnytimePoint(5, 1.0, 0.24, 0.5, 0.3, 0.40),
        AnytimePoint(9, 2.0, 0.16, 0.1, 0.6, 0.80),
    ]
    seconds = np.linspace(0.0, 3.0, 31)
    (gain,) = _anytime_gains(RunRecord(tmp_path / "run", summary, {}), seconds)
    assert np.all(np.diff(gain) >= 0.0)
    assert gain[0] == 0.0 and gain[-1] == pytest.approx(0.75)


def test_the_video_fits_the_page_width(tmp_path: Path) -> None:
    for name, delta1 in (("a", (0.9, 0.1)),):
        _run(tmp_path / "sweep" / name, "random", 0.1, 0.3, delta1)
        (tmp_path / "sweep" / name / "trajectory.mp4").write_bytes(b"video")
    write_report([tmp_path / "sweep"], tmp_path / "out", progress=False)
    html = (tmp_path / "out" / "report.html").read_text()
    assert "figure video, body > img { display: block; max-width: 100%; height: auto; }" in html
    assert '<figure class="video">' in html


def test_a_scene_or_run_named_like_markup_is_escaped_in_the_page(tmp_path: Path) -> None:
    hostile = "<script>alert(1)</script>"
    folder = tmp_path / "sweep" / "<script>run"
    _run(folder, "random", 0.1, 0.3, (0.9, 0.2))
    summary = (folder / "summary.json").read_text().replace('"box_room_0"', json.dumps(hostile))
    (folder / "summary.json").write_text(summary)
    write_report([tmp_path / "sweep"], tmp_path / "out", progress=False)
    html = (tmp_path / "out" / "report.html").read_text()
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html and "&lt;script&gt;run" in html
    assert hostile not in html and "<script>run" not in html
    assert html.count("<script>") == 1  # the page's own: sorting the tables


def _profile(model: str, seed: int, worst: list[float]) -> dict:
    return Profile(
        model=model,
        scene="box_room_0",
        envelope="upright",
        radii=((5.0, 0.1), (15.0, 0.3)),
        seeds=(seed,),
        delta1_init=[0.9],
        worst_by_seed=[worst],
        typical_by_seed=[[w + 0.1 for w in worst]],
        failure_by_seed=[[0.0, 0.25]],
        draws=[[0.85] * 4, [0.8, 0.8, 0.8, 0.4]],
        fail_below=0.5,
        pictures=[],
    ).to_dict()


def test_profile_runs_get_a_table_per_model_and_scene_and_curves_on_the_page(tmp_path: Path) -> None:
    worst = {("kadv_tiny", 0): [0.7, 0.3], ("kadv_tiny", 1): [0.5, 0.1], ("other", 0): [0.9, 0.8]}
    for (model, seed), values in worst.items():
        folder = tmp_path / f"{model}-{seed}"
        summary = _run(folder, "hybrid", 0.05, 0.35, (0.9, 0.4))
        summary.model, summary.seed, summary.profile = model, seed, _profile(model, seed, values)
        summary.write(folder / "summary.json")
    # a run without a profile is in Table 2 but not in the profiles
    _run(tmp_path / "plain", "hybrid", 0.05, 0.35, (0.9, 0.4))
    written = write_report([tmp_path], tmp_path / "report", progress=False)
    assert tmp_path / "report" / "profiles.png" in written
    rows = [line.split(" | ") for line in (tmp_path / "report" / "profiles.md").read_text().splitlines()[4:]]
    assert [row[0].strip("| ") for row in rows] == ["kadv_tiny", "other"]
    tiny = [float(cell.strip(" |")) for cell in rows[0][3:]]
    # seeds, init, the worst per radius averaged over the seeds, the failure rate at the largest,
    # the score (the area under init -> typical: mean of the trapezoids) and its spread over seeds
    scores = [((0.9 + 0.8) / 2 + (0.8 + 0.4) / 2) / 2, ((0.9 + 0.6) / 2 + (0.6 + 0.2) / 2) / 2]
    expected = [2, 0.9, 0.6, 0.2, 0.25, sum(scores) / 2, scores[0] - scores[1]]
    assert tiny == pytest.approx(expected, abs=1e-4)
    html = (tmp_path / "report" / "report.html").read_text()
    assert "Profiles: worst delta1 per radius (envelope upright)" in html
    assert "<h2>Profiles: delta1 against the radius of the camera's move</h2>" in html
