"""Multiruns: job folders named by their overrides, reruns that skip finished jobs, failures that
do not stop the others, the joblib and submitit launchers, and the report on a sweep."""

from __future__ import annotations

import json
import os
import re
import signal
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest

from kadv.cli.report import main as report_main
from tests.cli.browser import rendered_dom
from tests.cli.in_process import call_main
from tests.cli.waiting import wait_for

BIN = Path(sys.executable).parent
TINY = [
    "render.height=24",
    "render.width=32",
    "attack.budget_passes=6",
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


@dataclass
class KilledSweep:
    """The 2x2 grid killed (SIGKILL) once a job had finished, run again and interrupted (SIGTERM, as
    Slurm or a scheduler sends it) once it worked on an unfinished job, then run to the end."""

    cwd: Path
    killed: dict[Path, int]  # the summaries finished before the kill, and their mtimes
    interrupted: subprocess.CompletedProcess  # the interrupted rerun
    kept: list[Path]  # the summaries there after the interrupted rerun
    finished: subprocess.CompletedProcess  # the last rerun


def _works_on_an_unfinished_job(cwd: Path, pid: int) -> bool:
    """Whether process ``pid`` holds the run directory of a job with no summary yet (the basic
    launcher runs jobs in the sweep's process; a rerun also holds each finished job while it skips it)."""
    for lock in (cwd / "sweep").glob("*/.kadv.lock.json"):
        try:
            holder = json.loads(lock.read_text())["pid"]
        except (OSError, ValueError):  # written or removed as it is read
            continue
        if holder == pid and not (lock.parent / "summary.json").exists():
            return True
    return False


@pytest.fixture(scope="module")
def killed_sweep(tmp_path_factory) -> KilledSweep:
    cwd = tmp_path_factory.mktemp("killed_sweep")
    command = [str(BIN / "kadv-attack"), "-m", "hydra.sweep.dir=sweep", *TINY, *GRID]
    process = subprocess.Popen(
        command, cwd=cwd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True
    )
    wait_for(lambda: bool(_summaries(cwd)), process, "a job finished")
    os.killpg(process.pid, signal.SIGKILL)
    process.wait()
    killed = {p: p.stat().st_mtime_ns for p in _summaries(cwd)}
    rerun = subprocess.Popen(command, cwd=cwd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    wait_for(lambda: _works_on_an_unfinished_job(cwd, rerun.pid), rerun, "the rerun worked on an unfinished job")
    rerun.send_signal(signal.SIGTERM)
    stdout, stderr = rerun.communicate(timeout=600)
    interrupted = subprocess.CompletedProcess(command, rerun.returncode, stdout, stderr)
    return KilledSweep(cwd, killed, interrupted, _summaries(cwd), _sweep(cwd, *GRID))


def test_a_killed_sweep_finishes_on_a_rerun_without_redoing_jobs(killed_sweep: KilledSweep) -> None:
    assert 1 <= len(killed_sweep.killed) < 4
    # the basic launcher runs the jobs in order: those finished before the kill come first
    assert killed_sweep.interrupted.stdout.count("already complete") == len(killed_sweep.killed)
    finished = killed_sweep.finished
    assert finished.returncode == 0, finished.stderr[-2000:]
    _check_grid(killed_sweep.cwd)
    assert all(p.stat().st_mtime_ns == mtime for p, mtime in killed_sweep.killed.items())  # none ran twice


def test_an_interrupted_sweep_says_what_it_kept_and_resumes_each_job_once(killed_sweep: KilledSweep) -> None:
    interrupted, finished = killed_sweep.interrupted, killed_sweep.finished
    assert interrupted.returncode == 143, interrupted.stderr[-2000:]
    last = interrupted.stderr.strip().splitlines()[-1]
    # within a job (nearly always: it is signalled while it holds one), or between jobs, had that
    # job finished before the signal came
    within = re.match(r"interrupted: [01] of 1 init views done, kept in ", last)
    assert within or last.startswith("interrupted between runs: "), last
    assert last.endswith("; run the same command to resume") and "Traceback" not in interrupted.stderr
    # the last rerun skips every finished job and computes each of the others once
    done = len(killed_sweep.kept)
    assert finished.stdout.count("already complete") == done
    assert finished.stdout.count("run directory:") == 4 - done


def test_a_failing_job_does_not_stop_the_others(tmp_path: Path) -> None:
    result = _sweep(tmp_path, "attack.budget_passes=6,-1", "scene.seed=0")
    assert result.returncode != 0
    failures = json.loads((tmp_path / "sweep" / "failures.json").read_text())
    assert len(failures) == 1
    assert "attack.budget_passes=-1" in failures[0]["overrides"] and "attack.budget_passes" in failures[0]["error"]
    assert len(_summaries(tmp_path)) == 1 and "attack.budget_passes=6" in _summaries(tmp_path)[0].parent.name
    fixed = _sweep(tmp_path, "attack.budget_passes=6,7", "scene.seed=0")  # a clean rerun clears the record
    assert fixed.returncode == 0 and not (tmp_path / "sweep" / "failures.json").exists()


def test_kadv_report_writes_the_tables_and_a_page_chromium_renders(killed_sweep: KilledSweep, tmp_path: Path) -> None:
    cwd = killed_sweep.cwd
    assert killed_sweep.finished.returncode == 0
    result = subprocess.run(
        [str(BIN / "kadv-report"), "sweep", "--no-progress"], cwd=cwd, capture_output=True, text=True, timeout=600
    )
    assert result.returncode == 0, result.stderr[-2000:]
    out = cwd / "sweep" / "report"
    for method in ("gradient", "random"):  # the study's tables for each method in the sweep
        table2 = (out / f"table2_{method}.md").read_text()
        assert "| kadv_tiny |" in table2 and "box_room_0 L_depth" in table2 and "Avg delta1" in table2
        assert "delta1 after scale_shift alignment in disparity space)" in table2  # its fit, named
        assert (out / f"table3_{method}.csv").read_text().startswith("model,box_room_0 dL_depth,")
    methods = (out / "methods.csv").read_text().splitlines()
    assert len(methods) == 5 and {"gradient", "random"} <= {line.split(",")[2] for line in methods[1:]}
    transfer = (out / "transfer_delta1.csv").read_text().splitlines()
    assert transfer[0] == "views of \\ scored by,kadv_tiny" and len(transfer) == 2
    assert "; fitted kadv_tiny: scale_shift in disparity" in (out / "transfer_delta1.md").read_text()
    dom = rendered_dom(out / "report.html", tmp_path / "chromium")
    assert dom.count("<table") == 7  # tables 2 and 3 of each method, methods, transfer delta1 and L_depth
    assert dom.count("<tr>") == 4 * 3 + 5 + 2 * 2  # tables 2 and 3: header, model, Avg; methods; transfer
    images = int(dom.split('data-images="')[1].split('"')[0])
    assert images == 1 + 2 * 2 and f'data-images-loaded="{images}"' in dom  # curves, gallery, maps
    assert 'href="box_room_0' not in dom and dom.count('<a href="') >= 4


def test_kadv_report_names_a_missing_directory(tmp_path: Path) -> None:
    result = call_main(report_main, ["kadv-report", str(tmp_path / "nothing")])
    assert result.returncode == 2 and result.stderr.strip().count("\n") == 0 and "nothing" in result.stderr
