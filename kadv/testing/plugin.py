"""kadv's pytest plugin, registered through the ``pytest11`` entry point: installing kadv enables it.

- fixtures: ``kadv_scene`` (a factory: ``kadv_scene("box_room", seed=3)``,
  ``kadv_scene("probe/thin_structures")``, ``kadv_scene("path/to/room.glb")``) and
  ``kadv_artifacts`` (the folder where the worst views' pictures go: under ``tmp_path``, or
  ``--kadv-keep DIR``);
- the ``kadv`` marker on every test that uses them (``-m "not kadv"`` skips them);
- ``--kadv-budget FACTOR``, which scales every check's budget of model passes;
- a terminal summary: one line per model x scene checked, delta1 init -> worst, pass or fail.

A check's bad input (an unknown probe, a model of the wrong shape, no threshold) is reported as a
pytest ``UsageError`` in one line, not as a failing model. Nothing heavy is imported until a
fixture or check runs.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterator
from pathlib import Path

import pytest

__all__ = [
    "kadv_artifacts",
    "kadv_scene",
    "pytest_addoption",
    "pytest_collection_modifyitems",
    "pytest_configure",
    "pytest_runtest_call",
    "pytest_runtest_makereport",
    "pytest_terminal_summary",
    "pytest_unconfigure",
]

_FIXTURES = ("kadv_scene", "kadv_artifacts")
_CHECKS = pytest.StashKey[list]()
_SESSION = pytest.StashKey[object]()


def _positive_factor(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = float("nan")
    if not value > 0 or value == float("inf"):
        raise pytest.UsageError(f"--kadv-budget must be a positive number, got {text!r}")
    return value


def pytest_addoption(parser: pytest.Parser) -> None:
    group = parser.getgroup("kadv", "kadv: viewpoint robustness of depth models")
    group.addoption(
        "--kadv-budget",
        default="1",
        metavar="FACTOR",
        help="multiply every kadv check's budget of model passes by FACTOR (e.g. 0.5 on each push, 4 nightly)",
    )
    group.addoption(
        "--kadv-keep",
        default=None,
        metavar="DIR",
        help="keep the worst views' pictures in DIR (one folder per test) instead of under tmp_path",
    )


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line("markers", "kadv: checks a depth model's viewpoint robustness with kadv")
    from kadv.testing.session import settings

    checks: list = []
    config.stash[_CHECKS] = checks
    block = settings(
        budget_factor=_positive_factor(config.getoption("kadv_budget")),
        observer=lambda result, passed: checks.append((result, passed)),
    )
    block.__enter__()
    config.stash[_SESSION] = block


def pytest_unconfigure(config: pytest.Config) -> None:
    block = config.stash.get(_SESSION, None)
    if block is not None:
        block.__exit__(None, None, None)


def pytest_collection_modifyitems(items: list[pytest.Item]) -> None:
    for item in items:
        if any(name in getattr(item, "fixturenames", ()) for name in _FIXTURES):
            item.add_marker(pytest.mark.kadv)


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item) -> Iterator[None]:
    from kadv.testing.inputs import RobustnessInputError

    try:
        return (yield)
    except RobustnessInputError as error:
        raise pytest.UsageError(str(error)) from None


@pytest.hookimpl(wrapper=True)
def pytest_runtest_makereport(item: pytest.Item, call: pytest.CallInfo) -> Iterator[pytest.TestReport]:
    report = yield
    if call.excinfo is not None and call.excinfo.errisinstance(pytest.UsageError):
        report.longrepr = f"UsageError: {call.excinfo.value}"
    return report


def pytest_terminal_summary(terminalreporter, config: pytest.Config) -> None:
    checks = config.stash.get(_CHECKS, [])
    if not checks:
        return
    terminalreporter.section("kadv viewpoint robustness")
    for result, passed in checks:
        terminalreporter.write_line(f"{_summary_line(result)}: {'pass' if passed else 'FAIL'}")


def _summary_line(result) -> str:
    """One check's line in the session summary: a one-radius check's delta1 init -> worst, or a
    profile's score (``min_score``)."""
    from kadv.testing.profile import Profile

    if isinstance(result, Profile):
        return (
            f"{result.model} x {result.scene}: score {result.score:.3f} ± {result.score_spread:.3f} "
            f"(radii {result.radii_text}, envelope {result.envelope})"
        )
    return (
        f"{result.model} x {result.scene}: delta1 {result.delta1_init:.3f} -> {result.worst.delta1_worst:.3f} "
        f"(worst of {len(result.views)} init views, {result.budget_passes} model passes each)"
    )


@pytest.fixture
def kadv_artifacts(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[Path]:
    """The folder where this test's checks keep the worst views' pictures; every check in the test
    that names no folder of its own writes there."""
    from kadv.testing.session import settings

    keep = request.config.getoption("kadv_keep")
    folder = Path(keep) / re.sub(r"[^A-Za-z0-9._-]+", "_", request.node.nodeid) if keep else tmp_path / "kadv"
    folder.mkdir(parents=True, exist_ok=True)
    with settings(artifacts=folder):
        yield folder


@pytest.fixture
def kadv_scene(kadv_artifacts: Path) -> Callable:
    """A factory of scenes: ``kadv_scene("box_room", seed=3)``, ``kadv_scene("procedural", seed=1)``,
    ``kadv_scene("probe/thin_structures")`` or ``kadv_scene("path/to/room.glb")``."""
    from kadv.testing.inputs import scene

    return scene
