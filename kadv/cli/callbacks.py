"""Hydra callbacks of the kadv commands."""

from __future__ import annotations

import json
import sys
import time
from pathlib import Path
from typing import Any

from hydra.experimental.callback import Callback
from omegaconf import DictConfig

from kadv.cli.common import FAILURE
from kadv.io import write_json

__all__ = ["SweepFailures"]

FAILURES = "failures.json"


class SweepFailures(Callback):
    """After a multirun, gather this sweep's ``failure.json`` files (those its jobs wrote; a job
    clears its own at start) into the sweep's ``failures.json``, and exit non-zero if any job failed
    (the other jobs have finished by then)."""

    def __init__(self) -> None:
        self.started_ns = 0

    def on_multirun_start(self, config: DictConfig, **kwargs: Any) -> None:
        self.started_ns = time.time_ns()

    def on_multirun_end(self, config: DictConfig, **kwargs: Any) -> None:
        sweep_dir = Path(config.hydra.sweep.dir)
        failures = [
            json.loads(path.read_text())
            for path in sorted(sweep_dir.glob(f"*/{FAILURE}"))
            if path.stat().st_mtime_ns >= self.started_ns
        ]
        summary = sweep_dir / FAILURES
        if not failures:
            summary.unlink(missing_ok=True)
            return
        write_json(summary, failures)
        print(f"{len(failures)} job(s) failed; see {summary}", file=sys.stderr)
        sys.exit(1)
