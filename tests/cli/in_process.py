"""A command's ``main`` called as its console script would call it, but in the test's own process:
for the tests where a process's start (seconds of imports) proves nothing more."""

from __future__ import annotations

import contextlib
import io
import subprocess
import sys
from collections.abc import Callable
from pathlib import Path

import pytest

__all__ = ["call_main"]


def call_main(
    main: Callable[[], object], argv: list[str], cwd: Path | None = None, env: dict[str, str] | None = None
) -> subprocess.CompletedProcess:
    """Run ``main`` with ``sys.argv = argv`` (in ``cwd``, with ``env`` added to the environment):
    its exit status, stdout and stderr, as :func:`subprocess.run` would give them."""
    stdout, stderr = io.StringIO(), io.StringIO()
    with pytest.MonkeyPatch.context() as patch:
        if cwd is not None:
            patch.chdir(cwd)
        for name, value in (env or {}).items():
            patch.setenv(name, value)
        patch.setattr(sys, "argv", argv)
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr):
            try:
                main()
                code = 0
            except SystemExit as exit_:
                code = exit_.code or 0
    return subprocess.CompletedProcess(argv, code, stdout.getvalue(), stderr.getvalue())
