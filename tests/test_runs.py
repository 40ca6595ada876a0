"""kadv.runs: one live run per run directory, and interruptions that wait for the file being written."""

from __future__ import annotations

import logging
import os
import signal
import socket
import subprocess
import sys
from pathlib import Path

import pytest

from kadv.io import atomic_write
from kadv.runs import Interrupted, RunDirectoryBusy, interruptible, run_lock

HOLD = """import sys
from kadv.runs import run_lock
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
    with caplog.at_level(logging.WARNING, logger="kadv.runs"), run_lock(tmp_path / "run"):
        assert (tmp_path / "run" / ".kadv.lock.json").read_text().count(f'"pid": {os.getpid()}') == 1
    assert [r.getMessage() for r in caplog.records] == [
        f"run directory {tmp_path / 'run'}: taking over from a run that is gone (PID {process.pid} on "
        f"{socket.gethostname()} since " + caplog.records[0].getMessage().rsplit(" since ", 1)[1]
    ]
    assert not (tmp_path / "run" / ".kadv.lock.json").exists(), "a run that ends leaves no record"


def test_an_interruption_waits_for_the_file_being_written(tmp_path: Path) -> None:
    def write(tmp: Path) -> None:
        tmp.write_text("first half ")
        os.kill(os.getpid(), signal.SIGTERM)  # arrives mid-write
        with tmp.open("a") as handle:
            handle.write("second half")

    with pytest.raises(Interrupted) as interruption, interruptible():
        atomic_write(tmp_path / "file.txt", write)
    assert interruption.value.exit_status == 143
    assert (tmp_path / "file.txt").read_text() == "first half second half"
    assert [p.name for p in tmp_path.iterdir()] == ["file.txt"], "no temporary file is left"
    assert signal.getsignal(signal.SIGTERM) is signal.SIG_DFL, "the handlers in force before come back"


def test_sigint_between_files_raises_at_once(tmp_path: Path) -> None:
    with pytest.raises(Interrupted) as interruption, interruptible():
        os.kill(os.getpid(), signal.SIGINT)
        atomic_write(tmp_path / "never.txt", lambda tmp: tmp.write_text("x"))
    assert interruption.value.exit_status == 130 and not (tmp_path / "never.txt").exists()
