"""The rendering commands and the benchmark scripts set the process up before torch loads; the
training command leaves it."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

PROBE = """
import sys
import kadv.cli
assert "torch" not in sys.modules, "kadv.cli loaded torch before configuring the process"
import os
import kadv.cli.attack
print(os.environ["OMP_WAIT_POLICY"], "torch" in sys.modules)
"""


def _probe(code: str, *arguments: str) -> subprocess.CompletedProcess:
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    return subprocess.run(
        [sys.executable, "-c", code, *arguments], capture_output=True, text=True, timeout=120, env=env, check=False
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


BENCHMARKS = Path(__file__).resolve().parents[2] / "benchmarks"

# imports each benchmark script in turn, stopping it where anything first asks for torch, and prints
# the wait policy set by then ("no-torch" for a script that imports none)
IMPORT_UNTIL_TORCH = """
import importlib, importlib.abc, os, sys

class TorchRequested(Exception):
    pass

class Stop(importlib.abc.MetaPathFinder):
    def find_spec(self, name, path=None, target=None):
        if name == "torch":
            raise TorchRequested(os.environ.get("OMP_WAIT_POLICY"))
        return None

sys.meta_path.insert(0, Stop())
sys.path.insert(0, sys.argv[1])
for script in sys.argv[2:]:
    os.environ.pop("OMP_WAIT_POLICY", None)
    for name in ("common", "profile_step", script):
        sys.modules.pop(name, None)
    try:
        importlib.import_module(script)
        print(script, "no-torch")
    except TorchRequested as policy:
        print(script, policy)
"""


def test_benchmarks_configure_the_process_before_torch_loads() -> None:
    """Each script's figures are taken under the wait policy the commands run with
    (docs/performance.md's contract): ``common`` comes before torch (the linter's import order)."""
    scripts = sorted(path.stem for path in BENCHMARKS.glob("*.py") if path.stem != "common")
    result = _probe(IMPORT_UNTIL_TORCH, str(BENCHMARKS), *scripts)
    assert result.returncode == 0, result.stderr
    policies = dict(line.split() for line in result.stdout.splitlines())
    assert sorted(policies) == scripts
    assert {script: policy for script, policy in policies.items() if policy not in ("PASSIVE", "no-torch")} == {}
    assert policies["profile_step"] == policies["worst_case"] == "PASSIVE"
