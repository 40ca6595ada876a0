"""kadv-attack under what clusters and people do to runs: a second process on the run directory,
Ctrl-C and SIGTERM, a full disk and a read-only folder. Each ends in one line and its exit status,
and a rerun resumes."""

from __future__ import annotations

import errno
import json
import os
import signal
import socket
import subprocess
import time
from pathlib import Path
from unittest import mock

import pytest

from kadv.cli.attack import main as attack_main
from tests.cli.in_process import call_main
from tests.cli.test_attack_cli import _command, _run_in_process
from tests.cli.waiting import wait_for

# slow enough per init view to be caught between two, with direct light (no bake)
RUN = [
    "render.height=48",
    "render.width=64",
    "render.lighting=direct",
    "attack=gradient",
    "attack.gradient.steps=40",
    "attack.gradient.restarts=1",
    "init.count=3",
    "init.candidates=8",
    "attack.top_n=1",  # two pictures per init view: pictures cost more than these searches
    "progress=false",
    "video=false",
]


def _with(overrides: list[str], *changes: str) -> list[str]:
    """``overrides`` with the keys of ``changes`` set to their values."""
    keys = {change.partition("=")[0] for change in changes}
    return [o for o in overrides if o.partition("=")[0] not in keys] + list(changes)


def _start(run_dir: Path) -> subprocess.Popen:
    process = subprocess.Popen(
        _command("kadv-attack", run_dir, *RUN), stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
    )
    wait_for((run_dir / "partial" / "init0.json").exists, process, "the run finished its first init view")
    return process


def _text(path: Path) -> str:
    return path.read_text() if path.is_file() else ""


def _interrupt(process: subprocess.Popen, signum: int, run_dir: Path) -> int:
    """Send ``signum``; check the run's last line and that nothing half-written is left; the init
    views it had done."""
    process.send_signal(signum)
    _, stderr = process.communicate(timeout=120)
    assert process.returncode == 128 + signum, stderr[-2000:]
    done = len(list((run_dir / "partial").glob("init*.json")))
    assert stderr.splitlines()[-1] == (
        f"interrupted: {done} of 3 init views done, kept in {run_dir}; run the same command to resume"
    )
    assert "Traceback" not in stderr and not list(run_dir.rglob(".*.kadv-tmp-*"))
    return done


def test_a_second_run_is_refused_and_interrupted_runs_say_what_they_kept_and_resume(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    process = _start(run_dir)
    second = _run_in_process("kadv-attack", run_dir, *RUN)
    assert second.returncode == 2
    assert second.stderr == (
        f"kadv-attack: error: run directory {run_dir} is in use by another kadv run (PID {process.pid} on "
        f"{socket.gethostname()} since {json.loads((run_dir / '.kadv.lock.json').read_text())['started']}); "
        "wait for it to finish, or stop it first\n"
    )
    done = _interrupt(process, signal.SIGINT, run_dir)  # Ctrl-C: status 130
    assert 1 <= done < 3
    # SIGTERM (Slurm's, a scheduler's) once the resumed run has read what was kept: it keeps that,
    # and the init view it finished too, should it finish one before the signal comes
    resumed = subprocess.Popen(_command("kadv-attack", run_dir, *RUN), stderr=subprocess.PIPE, text=True)
    log = run_dir / "attack.log"  # Hydra's log of the job
    wait_for(lambda: "resuming" in _text(log), resumed, "the resumed run read what was kept")
    kept = _interrupt(resumed, signal.SIGTERM, run_dir)  # status 143
    assert done <= kept < 3
    finished = _run_in_process("kadv-attack", run_dir, *RUN)
    assert finished.returncode == 0, finished.stderr
    assert json.loads((run_dir / "summary.json").read_text())["resumed_init_views"] == list(range(kept))


def _full_disk(path: Path):
    """os.replace as a full disk answers it, for the summary only: everything before is written."""
    real = os.replace

    def replace(source, destination):
        if str(destination).endswith("summary.json"):
            raise OSError(errno.ENOSPC, os.strerror(errno.ENOSPC))
        return real(source, destination)

    return mock.patch("kadv.io.os.replace", replace)


def test_a_full_disk_is_one_line_exit_status_1_and_the_rerun_resumes(tmp_path: Path) -> None:
    run_dir = tmp_path / "run"
    small = _with(RUN, "attack.gradient.steps=3")
    with _full_disk(run_dir):
        result = _run_in_process("kadv-attack", run_dir, *small)
    assert result.returncode == 1
    assert result.stderr == f"kadv-attack: error: cannot write {run_dir / 'summary.json'}: No space left on device\n"
    assert len(list((run_dir / "partial").glob("init*.json"))) == 3 and (run_dir / "trajectory.csv").is_file()
    assert not list(run_dir.glob(".summary*")), "no temporary file is left"
    again = _run_in_process("kadv-attack", run_dir, *small)
    assert again.returncode == 0, again.stderr
    assert json.loads((run_dir / "summary.json").read_text())["resumed_init_views"] == [0, 1, 2]


def _mount_tmpfs(folder: Path, *options: str) -> None:
    folder.mkdir(parents=True, exist_ok=True)
    command = ["mount", "-t", "tmpfs", "-o", ",".join(["size=200k", *options]), "tmpfs", str(folder)]
    mounted = subprocess.run(command, capture_output=True, text=True)
    if mounted.returncode != 0:
        pytest.fail(f"this test mounts a small tmpfs and needs root with mount(8): {mounted.stderr.strip()}")


@pytest.mark.parametrize("options", [(), ("ro",)], ids=["full", "read-only"])
def test_a_small_or_read_only_filesystem_ends_the_run_in_one_line(tmp_path: Path, options: tuple) -> None:
    # the run's pictures go to a 200 KiB tmpfs, or to a read-only one (Hydra's own files, written
    # before kadv runs, go to the run directory)
    run_dir = tmp_path / "run"
    _mount_tmpfs(run_dir / "views", *options)
    try:
        result = _run_in_process("kadv-attack", run_dir, *_with(RUN, "init.count=1", "attack.gradient.steps=2"))
    finally:
        subprocess.run(["umount", "-l", str(run_dir / "views")], check=True)
    reason = "Read-only file system" if options else "No space left on device"
    assert result.returncode == 1, result.stderr
    line = result.stderr.splitlines()[-1]
    assert line.startswith(f"kadv-attack: error: cannot write {run_dir / 'views'}/init0") and line.endswith(reason)
    assert "Traceback" not in result.stderr and (run_dir / "partial" / "init0.json").is_file()


@pytest.mark.parametrize("where", ["run", "cwd"], ids=["run directory", "working directory"])
def test_a_read_only_run_directory_is_one_line_before_hydra_writes_there(tmp_path: Path, where: str) -> None:
    # Hydra makes the run directory and its log before kadv runs: it is checked before Hydra starts
    read_only = tmp_path / "read_only"
    _mount_tmpfs(read_only, "ro")
    try:
        if where == "run":
            result = _run_in_process("kadv-attack", read_only / "run", *RUN)
        else:  # the default run directory, outputs/attack/..., under a read-only working directory
            result = call_main(attack_main, ["kadv-attack", *RUN], cwd=read_only)
    finally:
        subprocess.run(["umount", "-l", str(read_only)], check=True)
    folder = read_only / ("run" if where == "run" else "outputs")
    assert result.returncode == 1
    assert result.stderr == f"kadv-attack: error: cannot write {folder}: Read-only file system\n"


@pytest.mark.parametrize("signum, status", [(signal.SIGINT, 130), (signal.SIGTERM, 143)])
def test_a_signal_outside_a_run_ends_the_command_in_one_line(signum: int, status: int, capsys) -> None:
    """Between a sweep's jobs, or while Hydra starts, no run holds the signal: the command does."""
    from kadv.cli.attack import _interruptible_throughout

    def between_jobs() -> None:
        os.kill(os.getpid(), signum)
        time.sleep(60)  # the handler raises within this sleep

    previous = signal.getsignal(signum)
    with pytest.raises(SystemExit) as exit_:
        _interruptible_throughout(between_jobs)()
    assert exit_.value.code == status and signal.getsignal(signum) is previous
    assert capsys.readouterr().err.splitlines() == [
        "interrupted between runs: each finished run is kept; run the same command to resume"
    ]
