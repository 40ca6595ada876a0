"""kadv's pytest plugin, driven by pytest's own pytester on generated test files."""

from __future__ import annotations

import json
import re
from pathlib import Path

import _pytest.pytester
import pytest

# a user's test file, as the README's section writes one (smaller, for speed)
USER_TESTS = """
from kadv.testing import assert_viewpoint_robust

SMALL = dict(budget_passes=8, init_count=1, size=(48, 64), lighting="direct")

def test_lenient(kadv_scene):
    assert_viewpoint_robust("kadv_tiny", kadv_scene("box_room", seed=3), min_delta1=0.0, **SMALL)

def test_strict(kadv_scene):
    assert_viewpoint_robust("kadv_tiny", kadv_scene("box_room", seed=3), min_delta1=1.0, **SMALL)

def test_without_kadv():
    assert True
"""


class _KeepingLibraries(_pytest.pytester.SysModulesSnapshot):
    """pytester's snapshot of ``sys.modules``, restored after each in-process run, that drops only
    the generated test files and conftests: dropping the libraries a run imported (pytester's
    default) made later imports of them in this process fail (matplotlib's layouts) or crash it
    with a segmentation fault (torch's, in whichever test of the worker came next)."""

    def __init__(self, preserve=None) -> None:
        super().__init__(preserve=lambda name: not name.startswith(("test_", "conftest")))


@pytest.fixture(autouse=True)
def _in_process_runs_keep_libraries(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(_pytest.pytester, "SysModulesSnapshot", _KeepingLibraries)


def _run(pytester: pytest.Pytester, *args: str) -> pytest.RunResult:
    pytester.makepyfile(test_user=USER_TESTS)
    return pytester.runpytest("-p", "no:cacheprovider", *args)


def test_a_user_file_passes_leniently_and_fails_strictly_naming_the_view_and_its_picture(
    pytester: pytest.Pytester,
) -> None:
    result = _run(pytester, "--kadv-keep", str(pytester.path / "kept"))
    result.assert_outcomes(passed=2, failed=1)
    output = result.stdout.str()
    failure = re.search(r"file0: delta1 (\d\.\d{3}) -> (\d\.\d{3}) at centre \(.*? deg; picture: (\S+\.png)", output)
    assert failure is not None, output
    picture = Path(failure.group(3))
    assert picture.is_file() and picture.is_relative_to(pytester.path / "kept")
    assert (
        "kadv_tiny is not viewpoint-robust on box_room_3 within 45°, 1 m (envelope free) (wanted delta1 >= 1.0)"
        in output
    )
    # the session's summary: one line per model x scene checked, with its verdict
    summary = output.split("kadv viewpoint robustness", 1)[1]
    lines = [line for line in summary.splitlines() if line.startswith("kadv_tiny x box_room_3")]
    assert len(lines) == 2 and lines[0].endswith(": pass") and lines[1].endswith(": FAIL")
    assert f"delta1 {failure.group(1)} -> {failure.group(2)}" in lines[1]


def test_the_kadv_marker_lets_a_run_skip_the_checks(pytester: pytest.Pytester) -> None:
    result = _run(pytester, "-m", "not kadv")
    result.assert_outcomes(passed=1, deselected=2)


def test_the_budget_option_scales_the_passes_and_one_seed_gives_one_verdict(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(
        test_budget="""
import json
from kadv.testing import viewpoint_robustness

def test_budget(kadv_scene, kadv_artifacts, request):
    runs = []
    for _ in range(2):  # one seed, twice
        result = viewpoint_robustness("kadv_tiny", kadv_scene("box_room", seed=3), budget_passes=8,
                                      init_count=1, size=(48, 64), lighting="direct")
        view = result.views[0]
        runs.append([result.budget_passes, view.passes, view.delta1_worst, list(view.centre)])
        assert result.views[0].picture.parent == kadv_artifacts
    out = request.config.rootpath / f"budget-{request.config.getoption('kadv_budget')}.json"
    out.write_text(json.dumps(runs))
"""
    )
    runs = {}
    for factor in ("1", "2"):
        pytester.runpytest("-p", "no:cacheprovider", "--kadv-budget", factor).assert_outcomes(passed=1)
        runs[factor] = json.loads((pytester.path / f"budget-{factor}.json").read_text())
    # the budget scaled, and spent but for what a batch of two refined lanes may leave
    assert runs["1"][0][0] == 8 and 8 - 1 <= runs["1"][0][1] <= 8
    assert runs["2"][0][0] == 16 and 16 - 1 <= runs["2"][0][1] <= 16
    assert runs["1"][0] == runs["1"][1] and runs["2"][0] == runs["2"][1], "the same seed gives the same delta1 twice"


@pytest.mark.parametrize(
    ("body", "message"),
    [
        ('kadv_scene("probe/nope")', "UsageError: no probe scene 'nope'; the probes are: photo_wall, grazing_floor"),
        (
            'assert_viewpoint_robust((WrongShape(), "depth"), kadv_scene("box_room"), min_delta1=0.5)',
            "UsageError: model 'WrongShape' must map rgb (B, 3, H, W) to (B, 1, H, W)",
        ),
        (
            'assert_viewpoint_robust("kadv_tiny", kadv_scene("box_room"))',
            "UsageError: assert_viewpoint_robust needs min_delta1, max_delta1_drop or min_score (all are unset)",
        ),
    ],
)
def test_bad_input_is_a_one_line_usage_error(pytester: pytest.Pytester, body: str, message: str) -> None:
    pytester.makepyfile(
        test_bad=f"""
import torch
from kadv.testing import assert_viewpoint_robust

class WrongShape(torch.nn.Module):
    def forward(self, rgb):
        return rgb

def test_bad(kadv_scene):
    {body}
"""
    )
    result = pytester.runpytest("-p", "no:cacheprovider")
    result.assert_outcomes(failed=1)
    output = result.stdout.str()
    assert message in output
    assert "Traceback" not in output and "def test_bad" not in output


def test_a_bad_budget_factor_is_refused_at_start(pytester: pytest.Pytester) -> None:
    pytester.makepyfile(test_nothing="def test_nothing():\n    pass\n")
    result = pytester.runpytest("-p", "no:cacheprovider", "--kadv-budget", "zero")
    assert result.ret == pytest.ExitCode.USAGE_ERROR
    assert "--kadv-budget must be a positive number, got 'zero'" in result.stderr.str()


def test_the_readme_test_file_runs_as_written(pytester: pytest.Pytester) -> None:
    readme = (Path(__file__).resolve().parents[2] / "README.md").read_text()
    section = readme.split("## Test your model's viewpoint robustness in CI", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    pytester.makepyfile(test_viewpoint=code)
    result = pytester.runpytest("-p", "no:cacheprovider", "--kadv-budget", "0.25")
    outcomes = result.parseoutcomes()
    assert outcomes.get("passed", 0) + outcomes.get("failed", 0) == 2 and "error" not in outcomes
    summary = result.stdout.str().split("kadv viewpoint robustness", 1)[1]
    assert "kadv_tiny x box_room_3: delta1" in summary and "kadv_tiny x probe_thin_structures_0: delta1" in summary
