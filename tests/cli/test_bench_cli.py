"""kadv-bench from the command line: freeze, run (killed and resumed, sharded over a launcher),
verify and the leaderboard's page in headless Chromium; wrong input in one line, exit status 2."""

from __future__ import annotations

import json
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import trimesh

from kadv.bench import Protocol, SceneSpec, freeze_suite
from kadv.cli.bench import main as bench_main
from tests.cli.browser import rendered_dom
from tests.cli.in_process import call_main
from tests.cli.waiting import wait_for

BIN = Path(sys.executable).parent
PROTOCOL = Protocol(radius_passes=(6, 6, 8), min_seeds=2, size=(24, 32), lighting="direct")
SEEDS = "seeds=[0,1]"


@pytest.fixture(scope="module")
def suite_file(tmp_path_factory) -> Path:
    specs = [SceneSpec(f"box{k}", {"kind": "box_room", "seed": k}) for k in (0, 1)]
    return freeze_suite("boxes", specs, PROTOCOL, views_per_scene=2).save(tmp_path_factory.mktemp("suite") / "s.json")


def _run(suite_file: Path, out: Path, *overrides: str) -> subprocess.Popen:
    command = [str(BIN / "kadv-bench"), "run", *overrides, f"suite={suite_file}", SEEDS, f"out={out}", "progress=false"]
    return subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)


def _cells(out: Path) -> list:
    """The entry's units without their seconds (the machine's, not the result's)."""
    units = json.loads((out / "entry.json").read_text())["units"]
    return [[{k: v for k, v in cell.items() if k != "seconds"} for cell in unit["cells"]] for unit in units]


@pytest.fixture(scope="module")
def entry(suite_file, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("run")
    process = _run(suite_file, out)
    assert process.wait(timeout=600) == 0, process.stderr.read()[-2000:]
    assert "suite score" in process.stdout.read()
    return out


def test_a_run_killed_with_sigkill_resumes_to_the_same_entry(suite_file, entry, tmp_path) -> None:
    out = tmp_path / "killed"
    process = _run(suite_file, out)
    wait_for(lambda: len(list((out / "units").glob("*.json"))) >= 3, process, "three units were written")
    process.send_signal(signal.SIGKILL)
    process.wait()
    assert not (out / "entry.json").exists()
    again = _run(suite_file, out)
    assert again.wait(timeout=600) == 0, again.stderr.read()[-2000:]
    assert _cells(out) == _cells(entry)
    assert not [p for p in (out / "units").iterdir() if p.name.startswith(".")]  # no temporary left


def test_shards_run_as_a_hydra_multirun_and_merge_into_the_same_entry(suite_file, entry, tmp_path) -> None:
    out = tmp_path / "sharded"
    process = _run(suite_file, out, "-m", "shard=0,1,2", "shards=3")
    assert process.wait(timeout=600) == 0, process.stderr.read()[-2000:]
    assert _cells(out) == _cells(entry)
    assert sorted(p.name for p in (out / "jobs").iterdir() if p.is_dir()) == ["shard0", "shard1", "shard2"]


def test_verify_checks_an_entry_and_refuses_a_forged_one_in_one_line(suite_file, entry, tmp_path) -> None:
    path = entry / "entry.json"
    pictures = tmp_path / "worst"
    result = call_main(bench_main, ["kadv-bench", "verify", str(path), f"suite={suite_file}", f"pictures={pictures}"])
    assert result.returncode == 0 and "24 cells verified" in result.stdout, result.stderr
    assert sorted(p.name for p in pictures.iterdir()) == ["box0.png", "box1.png"]
    data = json.loads(path.read_text())
    data["units"][3]["cells"][1]["delta1"] -= 0.05
    forged = tmp_path / "forged.json"
    forged.write_text(json.dumps(data))
    result = call_main(bench_main, ["kadv-bench", "verify", str(forged), f"suite={suite_file}"])
    assert result.returncode == 2 and result.stderr.count("\n") == 1
    assert f"{forged}: scene 'box0', view 1, seed 1, radius 1: delta1" in result.stderr


def test_the_leaderboard_page_renders_in_headless_chromium(suite_file, entry, tmp_path) -> None:
    out = tmp_path / "board"
    result = call_main(
        bench_main, ["kadv-bench", "table", str(entry / "entry.json"), f"suite={suite_file}", f"out={out}"]
    )
    assert result.returncode == 0, result.stderr
    assert {p.name for p in out.iterdir()} == {f"leaderboard.{e}" for e in ("md", "json", "png", "html")}
    dom = rendered_dom(out / "leaderboard.html", tmp_path / "chromium")
    # the scores (a header and a model) and the per-scene table (a header and two scenes)
    assert dom.count("<table>") == 2 and dom.count("<tr>") == 2 + 3 and "<td>kadv_tiny</td>" in dom
    assert "ranking: kadv_tiny" in dom and 'src="data:image/png;base64,' in dom


def test_kadv_bench_freezes_the_user_s_own_scenes_under_a_root(tmp_path) -> None:
    mesh = trimesh.creation.box(extents=(4.0, 3.0, 5.0))
    mesh.invert()
    (tmp_path / "scans" / "room_a").mkdir(parents=True)
    mesh.export(tmp_path / "scans" / "room_a" / "room.glb")
    out = tmp_path / "mine.json"
    arguments = ["scenes=room_a/room.glb", f"root={tmp_path / 'scans'}", "name=mine", f"out={out}", "views=2"]
    result = call_main(bench_main, ["kadv-bench", "freeze", *arguments, "lighting=direct", "size=24,32"])
    assert result.returncode == 0, result.stderr
    assert out.with_suffix(".png").is_file()  # the sheet of its init views
    suite = json.loads(out.read_text())
    assert (
        suite["scenes"][0]["node"] == {"kind": "file", "path": "room_a/room.glb"}
        and len(suite["scenes"][0]["views"]) == 2
    )


@pytest.mark.parametrize(
    "arguments, message",
    [
        (["kadv-bench", "audit"], "'audit' is not a verb of kadv-bench"),
        (["kadv-bench", "table"], "takes one or more entry files"),
        (["kadv-bench", "verify", "missing.json"], "entry missing.json: no such file"),
        (["kadv-bench", "freeze", "name=x", "out=x.json", "scenes=none.glb"], "scenes: none.glb is not a file"),
        (["kadv-bench", "merge", "suite=offline-v2", "out=x"], "suite offline-v2: no such file (or shipped suite)"),
        (["kadv-bench", "table", "a.json", "colour=red"], "takes the keys suite, out"),
    ],
)
def test_wrong_input_is_one_line_and_exit_status_2(arguments, message, tmp_path) -> None:
    result = call_main(bench_main, arguments, cwd=tmp_path)
    assert result.returncode == 2 and result.stderr.count("\n") == 1 and message in result.stderr, result.stderr


def test_a_run_with_too_few_seeds_or_a_bad_shard_says_so_in_one_line(suite_file, tmp_path) -> None:
    for overrides, message in (([], "the suite asks for 2 distinct seeds"), (["shard=3", "shards=2"], "shard must be")):
        command = [str(BIN / "kadv-bench"), "run", f"suite={suite_file}", f"out={tmp_path}", *overrides]
        if not overrides:
            command.append("seeds=[0]")
        result = subprocess.run(command, capture_output=True, text=True, timeout=300)
        assert result.returncode == 2 and message in result.stderr and "Traceback" not in result.stderr, result.stderr


def test_kadv_report_writes_the_study_s_table_2_from_suite_entries(suite_file, entry, tmp_path) -> None:
    from kadv.cli.report import main as report_main

    result = call_main(
        report_main, ["kadv-report", str(entry / "entry.json"), "--suite", str(suite_file), "-o", str(tmp_path)]
    )
    assert result.returncode == 0, result.stderr
    header, row = (tmp_path / "table2_boxes.csv").read_text().splitlines()
    assert header.split(",") == [
        "model", "box0 L_depth", "box0 delta1", "box1 L_depth", "box1 delta1", "Avg L_depth", "Avg delta1"
    ]  # fmt: skip
    units = json.loads((entry / "entry.json").read_text())["units"]
    box1 = [u["cells"][-1]["delta1"] for u in units if u["scene"] == 1]  # the largest radius, every view and seed
    assert row.startswith("kadv_tiny,") and float(row.split(",")[4]) == pytest.approx(sum(box1) / len(box1))
