"""kadv.report.store: one live run per run directory."""

from __future__ import annotations

import logging
import os
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from kadv.report.store import RunDirectoryBusy, check_same_settings, run_lock

HOLD = """import sys
from kadv.report.store import run_lock
with run_lock(sys.argv[1]):
    print("held", flush=True)
    sys.stdin.read()
"""


def _holder(run_dir: Path) -> subprocess.Popen:
    process = subprocess.Popen(
        [sys.executable, "-c", HOLD, str(run_dir)], stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True
    )
    assert process.stdout.readline().strip() == "held"
    return process


def test_a_live_holder_is_named_and_a_dead_one_is_taken_over(tmp_path: Path, caplog) -> None:
    process = _holder(tmp_path / "run")
    try:
        with pytest.raises(RunDirectoryBusy) as busy, run_lock(tmp_path / "run"):
            pass
        message = str(busy.value)
        assert f"PID {process.pid} on {socket.gethostname()} since 20" in message and "\n" not in message
    finally:
        process.kill()  # SIGKILL: the kernel frees its lock; its record stays behind
        process.wait()
    with caplog.at_level(logging.WARNING, logger="kadv.report.store"), run_lock(tmp_path / "run"):
        assert (tmp_path / "run" / ".kadv.lock.json").read_text().count(f'"pid": {os.getpid()}') == 1
    assert [r.getMessage() for r in caplog.records] == [
        f"run directory {tmp_path / 'run'}: taking over from a run that is gone (PID {process.pid} on "
        f"{socket.gethostname()} since " + caplog.records[0].getMessage().rsplit(" since ", 1)[1]
    ]
    assert not (tmp_path / "run" / ".kadv.lock.json").exists(), "a run that ends leaves no record"


def test_a_run_made_with_other_settings_is_refused_naming_the_keys_and_the_ignored_ones_are_not(
    tmp_path: Path,
) -> None:
    saved = {"attack": {"top_n": 5, "radii": [[5, 0.1]]}, "progress": True, "render": {"lighting": "baked"}}
    same = {"attack": {"top_n": 5, "radii": [[5, 0.1]]}, "progress": False, "render": {"lighting": "auto"}}
    check_same_settings(tmp_path, saved, same, frozenset({"progress"}), frozenset({"render.lighting"}))
    other = {"attack": {"top_n": 2, "radii": [[5, 0.1]], "seed": 1}, "progress": True, "render": {"lighting": "auto"}}
    with pytest.raises(ValueError) as refused:
        check_same_settings(tmp_path, saved, other, resolved=frozenset({"render.lighting"}))
    assert str(refused.value) == (
        f"{tmp_path} holds a run made with other settings (attack.seed: (unset) -> 1, attack.top_n: 5 -> 2): "
        "remove it to run again, or write to another folder"
    )
