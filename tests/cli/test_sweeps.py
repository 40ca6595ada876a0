"""Multiruns: job folders named by their overrides, reruns that skip finished jobs, failures that
do not stop the others, the joblib and submitit launchers, and the report on a sweep."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from kadv.cli.report import main as report_main
from tests.cli.in_process import call_main

BIN = Path(sys.executable).parent
TINY = [
    "render.height=24",
    "render.width=32",
    "attack.budget_evaluations=6",
    "init.count=1",
    "init.candidates=4",
    "progress=false",
    "video=false",
]
GRID = ["scene.seed=0,1", "attack=gradient,random"]


def _sweep(cwd: Path, *overrides: str, timeout: int = 600) -> subprocess.CompletedProcess:
    return subprocess.run(
        [str(BIN / "kadv-attack"), "-m", "hydra.sweep.dir=sweep", *TINY, *overrides],
        cwd=cwd,
        capture_output=True,
        text=True,
        timeout=timeout,
    )


def _jobs(cwd: Path) -> dict[str, Path]:
    return {p.name: p for p in (cwd / "sweep").iterdir() if p.is_dir() and not p.name.startswith(".")}


def _summaries(cwd: Path) -> list[Path]:
    return sorted((cwd / "sweep").glob("*/summary.json"))


def _check_grid(cwd: Path) -> None:
    jobs = _jobs(cwd)
    assert len(jobs) == 4 and len(_summaries(cwd)) == 4
    for name, folder in jobs.items():  # each folder is named after its own overrides
        summary = json.loads((folder / "summary.json").read_text())
        assert f"attack={summary['method']}" in name
        assert f"scene.seed={summary['scene'].removeprefix('box_room_')}" in name


@pytest.mark.parametrize("launcher", ["hydra/launcher=joblib hydra.launcher.n_jobs=2", "hydra/launcher=submitit_local"])
def test_a_2x2_sweep_through_a_launcher(launcher: str, tmp_path: Path) -> None:
    result = _sweep(tmp_path, *GRID, *launcher.split())
    assert result.returncode == 0, result.stderr[-2000:]
    _check_grid(tmp_path)


@pytest.fixture(scope="module")
def killed_sweep(tmp_path_factory) -> tuple[Path, dict[Path, int], subprocess.CompletedProcess]:
    """The 2x2 grid killed once a job has finished, then run again to the end: the sweep's folder,
    the jobs finished before the kill (with their summaries' mtimes), and the rerun. The report's
    test reads the finished sweep too."""
    cwd = tmp_path_factory.mktemp("killed_sweep")
    command = [str(BIN / "kadv-attack"), "-m", "hydra.sweep.dir=sweep", *TINY, *GRID]
    process = subprocess.Popen(
        command, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    deadline = time.monotonic() + 300
    while not _summaries(cwd) and process.poll() is None and time.monotonic() < deadline:
        time.sleep(0.05)
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    finished = {p: p.stat().st_mtime_ns for p in _summaries(cwd)}
    return cwd, finished, _sweep(cwd, *GRID)


def test_a_killed_sweep_finishes_on_a_rerun_without_redoing_jobs(killed_sweep) -> None:
    cwd, finished, result = killed_sweep
    assert 1 <= len(finished) < 4
    assert result.returncode == 0, result.stderr[-2000:]
    _check_grid(cwd)
    assert result.stdout.count("already complete") == len(finished)
    assert all(p.stat().st_mtime_ns == mtime for p, mtime in finished.items())  # none ran twice


def test_a_failing_job_does_not_stop_the_others(tmp_path: Path) -> None:
    result = _sweep(tmp_path, "attack.budget_evaluations=6,-1", "scene.seed=0")
    assert result.returncode != 0
    failures = json.loads((tmp_path / "sweep" / "failures.json").read_text())
    assert len(failures) == 1
    assert (
        "attack.budget_evaluations=-1" in failures[0]["overrides"]
        and "attack.budget_evaluations" in failures[0]["error"]
    )
    assert len(_summaries(tmp_path)) == 1 and "attack.budget_evaluations=6" in _summaries(tmp_path)[0].parent.name
    fixed = _sweep(tmp_path, "attack.budget_evaluations=6,7", "scene.seed=0")  # a clean rerun clears the record
    assert fixed.returncode == 0 and not (tmp_path / "sweep" / "failures.json").exists()


def test_kadv_report_writes_the_tables_and_a_page_chromium_renders(killed_sweep, tmp_path: Path) -> None:
    cwd, _, rerun = killed_sweep
    assert rerun.returncode == 0
    result = subprocess.run(
        [str(BIN / "kadv-report"), "sweep", "--no-progress"], cwd=cwd, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-2000:]
    out = cwd / "sweep" / "report"
    for method in ("gradient", "random"):  # the study's tables for each method in the sweep
        table2 = (out / f"table2_{method}.md").read_text()
        assert "| kadv_tiny |" in table2 and "box_room_0 L_depth" in table2 and "Avg delta1" in table2
        assert (out / f"table3_{method}.csv").read_text().startswith("model,box_room_0 dL_depth,")
    methods = (out / "methods.csv").read_text().splitlines()
    assert len(methods) == 5 and {"gradient", "random"} <= {line.split(",")[2] for line in methods[1:]}
    transfer = (out / "transfer_delta1.csv").read_text().splitlines()
    assert transfer[0] == "views of \\ scored by,kadv_tiny" and len(transfer) == 2
    chromium = "/usr/bin/chromium"
    assert Path(chromium).exists(), "headless Chromium is missing: apt-get install -y chromium"
    dom = subprocess.run(
        [
            chromium,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={tmp_path / 'chromium'}",
            "--virtual-time-budget=5000",
            "--dump-dom",
            (out / "report.html").as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
    assert dom.count("<table") == 7  # tables 2 and 3 of each method, methods, transfer delta1 and L_depth
    assert dom.count("<tr>") == 4 * 3 + 5 + 2 * 2  # tables 2 and 3: header, model, Avg; methods; transfer
    images = int(dom.split('data-images="')[1].split('"')[0])
    assert images == 1 + 2 * 2 and f'data-images-loaded="{images}"' in dom  # curves, gallery, maps
    assert 'href="box_room_0' not in dom and dom.count('<a href="') >= 4


def test_kadv_report_names_a_missing_directory(tmp_path: Path) -> None:
    result = call_main(report_main, ["kadv-report", str(tmp_path / "nothing")])
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0 and "nothing" in result.stderr
