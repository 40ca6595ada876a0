"""The commands set the process up before torch loads (kadv.cli imports kadv.runtime first)."""
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


def test_commands_configure_the_process_before_torch_loads() -> None:
    env = {key: value for key, value in os.environ.items() if key != "OMP_WAIT_POLICY"}
    result = subprocess.run([sys.executable, "-c", PROBE], capture_output=True, text=True, timeout=120, env=env,
                            check=False)
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == ["PASSIVE", "True"]
    assert result.stderr == ""  # nothing printed on import (no warnings from the model modules)
