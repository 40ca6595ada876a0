"""The rendering commands set the process up before torch loads; the training command leaves it."""

from __future__ import annotations

import os
import subprocess
import sys

PROBE = """
import sys
import kadv.cli
assert "torch" not in sys.modules, "kadv.cli loaded torch before configuring the process"
import os
import kadv.cli.attack
print(os.environ["OMP_WAIT_POLICY"], "torch" in sys.modules)
"""


def _probe(code: str) -> subprocess.CompletedProcess:
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    return subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, timeout=120, env=env, check=False
    )


def test_commands_configure_the_process_before_torch_loads() -> None:
    result = _probe(PROBE)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["PASSIVE", "True"]
    assert result.stderr == ""  # nothing printed on import (no warnings from the model modules)


def test_training_keeps_the_default_wait_policy() -> None:
    result = _probe("import os, kadv.cli.train_tiny; print(os.environ.get('OMP_WAIT_POLICY'))")
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["None"]
