"""The changelog is for users: short, by release, and no diary of the work."""

from __future__ import annotations

import re
import tomllib
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
CHANGELOG = (ROOT / "CHANGELOG.md").read_text()
RELEASE = re.compile(r"^## \[(\d+\.\d+\.\d+)\] - (\d{4}-\d\d-\d\d)$", re.M)


def test_the_changelog_is_short_and_dated_only_by_its_releases() -> None:
    assert len(CHANGELOG.splitlines()) <= 300
    headings = re.findall(r"^## .*$", CHANGELOG, re.M)
    assert headings[0] == "## [Unreleased]" and all(RELEASE.match(h) for h in headings[1:]), headings
    undated = RELEASE.sub("", CHANGELOG)
    assert not re.search(r"\d{4}-\d\d-\d\d", undated), "a date outside a release heading"
    assert not re.search(r"\b(issue|session)s? \d", undated, re.I), "the work's own timeline"


def test_the_package_version_is_the_latest_release() -> None:
    version = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["version"]
    assert RELEASE.findall(CHANGELOG)[0][0] == version
