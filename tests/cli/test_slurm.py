"""The cluster path on a real single-node Slurm: a sweep through Hydra's submitit_slurm launcher."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from tests.cli.slurm import INSTALL, missing_binaries, slurm_cluster
from tests.cli.test_sweeps import TINY
from tests.cli.waiting import PATIENCE_S, wait_for

BIN = Path(sys.executable).parent
LAUNCHER = [
    "hydra/launcher=submitit_slurm",
    "hydra.launcher.partition=debug",
    "hydra.launcher.timeout_min=10",
    "hydra.launcher.cpus_per_task=1",
    "hydra.launcher.mem_gb=1",
    "hydra.launcher.gpus_per_node=0",
]


@pytest.fixture(scope="module")
def cluster(tmp_path_factory) -> dict[str, str]:
    missing = missing_binaries()
    if missing:
        pytest.fail(f"Slurm is not installed ({', '.join(missing)} missing); install it with: {INSTALL}")
    if os.geteuid() != 0:
        pytest.fail("the Slurm test starts munged, slurmctld and slurmd and must run as root")
    with slurm_cluster(tmp_path_factory.mktemp("slurm")) as env:
        yield env


def _sweep(cluster: dict[str, str], cwd: Path, *overrides: str) -> subprocess.CompletedProcess:
    command = [str(BIN / "kadv-attack"), "-m", "hydra.sweep.dir=sweep", *LAUNCHER, *TINY, *overrides]
    return subprocess.run(command, cwd=cwd, env=cluster, capture_output=True, text=True, timeout=300)


def test_a_two_job_sweep_runs_on_slurm(cluster, tmp_path: Path) -> None:
    result = _sweep(cluster, tmp_path, "scene.seed=0,1")
    assert result.returncode == 0, result.stderr[-3000:]
    summaries = sorted((tmp_path / "sweep").glob("*/summary.json"))
    assert len(summaries) == 2
    scenes = sorted(json.loads(p.read_text())["scene"] for p in summaries)
    assert scenes == ["box_room_0", "box_room_1"]
    # the jobs ran through sbatch: submitit keeps their Slurm logs
    assert list((tmp_path / "sweep" / ".submitit").rglob("*_log.out"))


def test_a_job_that_fails_on_slurm_is_reported(cluster, tmp_path: Path) -> None:
    result = _sweep(cluster, tmp_path, "attack.budget_passes=6,-1")
    assert result.returncode != 0
    failures = json.loads((tmp_path / "sweep" / "failures.json").read_text())
    assert len(failures) == 1 and "attack.budget_passes=-1" in failures[0]["overrides"]
    assert len(list((tmp_path / "sweep").glob("*/summary.json"))) == 1


def test_a_job_signalled_as_at_its_time_limit_is_requeued_and_resumes(cluster, tmp_path: Path) -> None:
    """Slurm sends USR2 ahead of a job's time limit (and on preemption); submitit then requeues the
    job, which resumes from the init views it finished. The signal is sent by hand, at once, rather
    than waiting minutes for a real limit."""
    slow = ["attack=gradient", "attack.gradient.steps=30", "attack.gradient.restarts=1", "init.count=3"]
    command = [str(BIN / "kadv-attack"), "-m", "hydra.sweep.dir=sweep", *LAUNCHER, *TINY, *slow]
    command += ["render.lighting=direct", "hydra.launcher.max_num_timeout=3"]
    sweep = subprocess.Popen(command, cwd=tmp_path, env=cluster, stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    first = lambda: bool(list((tmp_path / "sweep").glob("*/partial/init0.json")))
    wait_for(first, sweep, "the job finished its first init view", poll_s=0.1)
    (job,) = subprocess.run(["squeue", "-h", "-o", "%i"], env=cluster, capture_output=True, text=True).stdout.split()
    subprocess.run(["scancel", "--signal=USR2", job], env=cluster, check=True)

    # Slurm holds a requeued job back for a while (its BeginTime); a test need not wait for all of it.
    # Not "now": slurmd refuses a credential issued in the second its job's last one was revoked
    # ("Job credential revoked"), and a start within that second failed the job
    def held_back() -> bool:
        state = subprocess.run(["squeue", "-h", "-j", job, "-o", "%T %r"], env=cluster, capture_output=True, text=True)
        return state.stdout.split()[:2] == ["PENDING", "BeginTime"]

    wait_for(lambda: sweep.poll() is not None or held_back(), sweep, "the requeued job was held back", poll_s=0.2)
    if sweep.poll() is None:
        subprocess.run(["scontrol", "update", f"JobId={job}", "StartTime=now+2"], env=cluster, check=True)
    _, stderr = sweep.communicate(timeout=PATIENCE_S)
    assert sweep.returncode == 0, stderr[-3000:]
    (summary,) = [json.loads(p.read_text()) for p in (tmp_path / "sweep").glob("*/summary.json")]
    done = summary["resumed_init_views"]
    # the requeued job read what the first run finished, and computed the rest, each init view once
    assert done and done == list(range(len(done))) and len(summary["init_views"]) == 3
    restarts = subprocess.run(["scontrol", "show", "job", job], env=cluster, capture_output=True, text=True).stdout
    assert "Restarts=1" in restarts


def test_a_suite_run_s_shards_run_as_slurm_jobs_and_merge_into_one_entry(cluster, tmp_path: Path) -> None:
    from kadv.bench import Protocol, SceneSpec, freeze_suite

    protocol = Protocol(radius_passes=(4, 4, 4), min_seeds=1, size=(24, 32), lighting="direct")
    suite = freeze_suite("boxes", [SceneSpec("box", {"kind": "box_room", "seed": 0})], protocol, views_per_scene=2)
    suite.save(tmp_path / "suite.json")
    out = tmp_path / "entry"
    command = [str(BIN / "kadv-bench"), "run", "-m", *LAUNCHER, f"suite={tmp_path / 'suite.json'}", "seeds=[0]"]
    command += [f"out={out}", "progress=false", "shard=0,1", "shards=2"]
    result = subprocess.run(command, cwd=tmp_path, env=cluster, capture_output=True, text=True, timeout=300)
    assert result.returncode == 0, result.stderr[-3000:]
    units = json.loads((out / "entry.json").read_text())["units"]
    assert [(u["view"], u["seed"]) for u in units] == [(0, 0), (1, 0)]
    assert len(list((out / "jobs" / ".submitit").rglob("*_log.out"))) == 2  # one Slurm job a shard
