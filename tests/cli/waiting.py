"""Waiting on another process's progress by the condition itself, never by a time that then acts."""

from __future__ import annotations

import subprocess
import time
from collections.abc import Callable

import pytest

__all__ = ["wait_for"]

# far above what a loaded machine takes: it only turns a hang into a failure that names it
PATIENCE_S = 1800


def wait_for(condition: Callable[[], bool], process: subprocess.Popen, what: str, poll_s: float = 0.02) -> None:
    """Poll ``condition`` while ``process`` runs; fail the test, naming ``what``, if the process
    exits first or the condition never comes."""
    deadline = time.monotonic() + PATIENCE_S
    while not condition():
        if process.poll() is not None:
            pytest.fail(f"the process exited ({process.returncode}) before {what}")
        if time.monotonic() > deadline:
            process.kill()
            pytest.fail(f"no sign, after {PATIENCE_S} s, that {what}")
        time.sleep(poll_s)
