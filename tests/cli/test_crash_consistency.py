"""Crash-consistency, tested by killing (as SQLite tests itself): a seeded run is killed with SIGKILL
at ten instants, some while a file is being written, and resumed each time; it ends where one
uninterrupted run ends, and leaves no temporary file behind.

The runs are forked from a server process that has imported kadv once (multiprocessing's
forkserver), so that each costs its work and not a second of imports.
"""

from __future__ import annotations

import json
import multiprocessing
import os
import signal
import sys
import time
from pathlib import Path

import numpy as np
import pytest

RUN = [
    "render.height=48",
    "render.width=64",
    "render.lighting=direct",
    "attack=gradient",
    "attack.gradient.steps=3",
    "attack.gradient.restarts=2",
    "init.count=2",
    "init.candidates=4",
    "attack.top_n=1",  # two pictures per init view: a picture costs more than the search here
    "progress=false",
    "video=false",
]
KILLS = 10


def _attack(run_dir: str, kill_at_write: int) -> None:
    """kadv-attack in this (forked) process; with ``kill_at_write`` > 0, SIGKILL itself once that
    many files are written to their temporaries, before the last is renamed into place."""
    from unittest import mock

    import kadv.io
    from kadv.cli.attack import main

    real, written = os.replace, []

    def replace(source, destination):
        written.append(destination)
        if len(written) == kill_at_write:
            os.kill(os.getpid(), signal.SIGKILL)
        return real(source, destination)

    sys.argv = ["kadv-attack", f"hydra.run.dir={run_dir}", *RUN]
    with mock.patch.object(kadv.io.os, "replace", replace):
        try:
            main()
        finally:
            Path(run_dir, "writes.txt").write_text(str(len(written)))


def _comparable(summary: dict) -> dict:
    """A summary without what differs between runs: the seconds things took, and which init views
    a resumed run read rather than computed."""
    if isinstance(summary, dict):
        return {k: _comparable(v) for k, v in summary.items() if k not in ("seconds", "resumed_init_views")}
    if isinstance(summary, list):
        return [_comparable(v) for v in summary]
    return summary


@pytest.fixture(scope="module")
def server() -> multiprocessing.context.BaseContext:
    context = multiprocessing.get_context("forkserver")
    context.set_forkserver_preload(["kadv.cli.attack", "kadv.io"])
    return context


def _run(server, run_dir: Path, kill_at_write: int = 0, kill_after: float | None = None) -> int:
    process = server.Process(target=_attack, args=(str(run_dir), kill_at_write))
    process.start()
    process.join(kill_after)
    if process.is_alive():
        process.kill()
        process.join()
    return process.exitcode


def _kill_and_resume(server, run_dir: Path, kill: tuple[str, float]) -> tuple[list[int] | None, list[int]]:
    """Kill a run as ``kill`` says, then resume it to the end: the init views whose partial results
    the kill left (None where it left a finished run), and those the resumed run read."""
    if kill[0] == "write":
        assert _run(server, run_dir, kill_at_write=int(kill[1])) == -signal.SIGKILL
        assert list(run_dir.rglob(".*.kadv-tmp-*")), "killed between a write and its rename"
    else:
        _run(server, run_dir, kill_after=kill[1])
    left = sorted(int(p.stem.removeprefix("init")) for p in run_dir.glob("partial/init*.json"))
    left = None if (run_dir / "summary.json").exists() else left
    assert _run(server, run_dir) == 0, kill
    return left, json.loads((run_dir / "summary.json").read_text())["resumed_init_views"]


def test_a_run_killed_at_ten_instants_resumes_to_the_same_end(server, tmp_path: Path) -> None:
    reference = tmp_path / "reference"
    start = time.monotonic()
    assert _run(server, reference) == 0
    duration = time.monotonic() - start
    writes = int((reference / "writes.txt").read_text())
    rng = np.random.default_rng(51)
    # half the kills right after a file's temporary is written, half at a moment of the run
    at_writes = sorted(rng.choice(np.arange(1, writes + 1), KILLS // 2, replace=False).tolist())
    at_seconds = sorted(rng.uniform(0.1, 0.9, KILLS - KILLS // 2) * duration)
    trajectory = (reference / "trajectory.csv").read_bytes()
    summary = _comparable(json.loads((reference / "summary.json").read_text()))
    kills = [("write", n) for n in at_writes] + [("seconds", s) for s in at_seconds]
    resumed_any = False
    for kill in kills:
        run_dir = tmp_path / f"{kill[0]}{kill[1]:.2f}"
        left, resumed = _kill_and_resume(server, run_dir, kill)
        # a resumed run reads every init view a killed one finished, and computes none of them again
        assert left is None or resumed == left, kill
        resumed_any |= bool(resumed)
        assert (run_dir / "trajectory.csv").read_bytes() == trajectory, kill
        assert _comparable(json.loads((run_dir / "summary.json").read_text())) == summary, kill
        assert not list(run_dir.rglob(".*.kadv-tmp-*")) and not (run_dir / "partial").exists(), kill
    assert resumed_any, "no kill came after an init view was finished"
