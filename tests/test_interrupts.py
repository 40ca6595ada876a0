"""kadv.interrupts: interruptions that wait for the file being written."""

from __future__ import annotations

import os
import signal
from pathlib import Path

import pytest

from kadv.interrupts import Interrupted, interruptible
from kadv.io import atomic_write


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
