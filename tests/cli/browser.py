"""A page as headless Chromium renders it: its DOM once its scripts have run."""

from __future__ import annotations

import subprocess
from pathlib import Path

__all__ = ["rendered_dom"]

CHROMIUM = "/usr/bin/chromium"


def rendered_dom(page: Path, profile: Path) -> str:
    """The DOM of the HTML file ``page`` after headless Chromium loaded it (``profile``: a fresh
    user-data folder); fails the test with the install command where Chromium is missing."""
    assert Path(CHROMIUM).exists(), "headless Chromium is missing: apt-get install -y chromium"
    return subprocess.run(
        [
            CHROMIUM,
            "--headless",
            "--no-sandbox",
            "--disable-gpu",
            "--disable-quic",
            "--no-first-run",
            "--disable-background-networking",
            "--disable-component-update",
            "--disable-sync",
            f"--user-data-dir={profile}",
            "--virtual-time-budget=5000",
            "--dump-dom",
            page.as_uri(),
        ],
        capture_output=True,
        text=True,
        timeout=120,
    ).stdout
