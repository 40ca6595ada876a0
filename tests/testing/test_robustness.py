"""kadv.testing: viewpoint robustness as a value and as an assertion, and the probe scorecard."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from kadv.testing import (
    DEFAULT_BUDGET,
    RobustnessInputError,
    assert_viewpoint_robust,
    scene,
    scorecard,
    settings,
    viewpoint_robustness,
)

# small and quick: the checks' arithmetic is the same at any budget
QUICK = {"budget_passes": 8, "init_count": 1, "size": (48, 64), "lighting": "direct"}


class Constant(torch.nn.Module):
    """A model that sees nothing: the same depth everywhere (a gradient reaches the image, as kadv
    asks of every model, but the values never change)."""

    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return torch.ones_like(rgb[:, :1]) + (rgb - rgb.detach()).mean(dim=1, keepdim=True)


class WrongShape(torch.nn.Module):
    def forward(self, rgb: torch.Tensor) -> torch.Tensor:
        return rgb


def test_the_same_seed_gives_the_same_result_twice(tmp_path: Path) -> None:
    room = scene("box_room", seed=3)
    first = viewpoint_robustness("kadv_tiny", room, seed=5, artifacts=tmp_path / "a", **QUICK)
    again = viewpoint_robustness("kadv_tiny", room, seed=5, artifacts=tmp_path / "b", **QUICK)
    assert [replace(v, picture=None) for v in first.views] == [replace(v, picture=None) for v in again.views]
    view = first.views[0]
    assert view.delta1_worst <= view.delta1_init
    assert 8 - 3 <= view.passes <= 8  # a step of two refined lanes (a forward and a backward pass each) may not fit
    assert view.picture.is_file() and view.picture.parent == tmp_path / "a"
    assert "kadv_tiny on box_room_3" in first.summary() and f"{view.delta1_worst:.3f}" in first.summary()


def test_a_failing_assertion_names_each_failing_view_its_pose_and_picture(tmp_path: Path) -> None:
    with pytest.raises(AssertionError) as failure:
        assert_viewpoint_robust("kadv_tiny", "box_room", min_delta1=1.0, artifacts=tmp_path, **QUICK)
    message = str(failure.value)
    assert message.startswith(
        "kadv_tiny is not viewpoint-robust on box_room_0 within 45°, 1 m (envelope free) (wanted delta1 >= 1.0):"
    )
    assert "file0: delta1 " in message and " -> " in message and "centre (" in message and "yaw " in message
    picture = Path(message.rsplit("picture: ", 1)[1].strip())
    assert picture.is_file() and picture.parent == tmp_path
    passed = assert_viewpoint_robust("kadv_tiny", "box_room", max_delta1_drop=1.0, artifacts=tmp_path, **QUICK)
    assert passed.views[0].delta1_drop <= 1.0


@pytest.mark.parametrize(
    "probe", ["photo_wall", "grazing_floor", "thin_structures", "window", "textureless_close", "dim_lamp", "stairs"]
)
def test_a_model_that_outputs_a_constant_map_fails_every_probe(probe: str, tmp_path: Path) -> None:
    # at the default budget from both init views: a constant map's best chance of passing
    options = {**QUICK, "budget_passes": DEFAULT_BUDGET, "init_count": 2}
    with pytest.raises(AssertionError, match="is not viewpoint-robust"):
        assert_viewpoint_robust((Constant(), "depth"), f"probe/{probe}", min_delta1=0.5, artifacts=tmp_path, **options)


def test_the_budget_factor_in_force_scales_the_passes(tmp_path: Path) -> None:
    with settings(budget_factor=0.5):
        result = viewpoint_robustness("kadv_tiny", "box_room", artifacts=tmp_path, **{**QUICK, "budget_passes": 16})
    assert result.budget_passes == 8 and 8 - 3 <= result.views[0].passes <= 8


@pytest.mark.parametrize(
    ("call", "message"),
    [
        (lambda: assert_viewpoint_robust("kadv_tiny", "box_room"), "needs min_delta1, max_delta1_drop or min_score"),
        (lambda: viewpoint_robustness("kadv_tiny", "probe/nope"), "no probe scene 'nope'; the probes are: photo_wall"),
        (lambda: viewpoint_robustness((WrongShape(), "depth"), "box_room"), r"must map rgb \(B, 3, H, W\) to \(B, 1"),
        (lambda: viewpoint_robustness(Constant(), "box_room"), "needs its output kind"),
        (lambda: viewpoint_robustness("kadv_tiny", "attic"), "no scene 'attic'"),
        (lambda: scorecard(["kadv_tiny"], ["nope"]), "no probe scene 'nope'; the probes are"),
        (
            lambda: assert_viewpoint_robust("kadv_tiny", "box_room", min_delta1=2.0),
            r"min_delta1 must be a number in \[0, 1\]",
        ),
    ],
)
def test_bad_input_is_one_line_naming_it(call, message: str) -> None:
    with pytest.raises(RobustnessInputError, match=message) as error:
        call()
    assert "\n" not in str(error.value)


def test_the_scorecard_profiles_each_model_on_each_probe_and_ranks_them(tmp_path: Path) -> None:
    quick = {**QUICK, "budget_passes": 6, "size": (24, 32), "typical_views": 4, "radii": ((5, 0.1), (30, 0.6))}
    card = scorecard(
        ["kadv_tiny", (Constant(), "depth")], ["window", "stairs"], seeds=(0, 1), artifacts=tmp_path, **quick
    )
    table = card.markdown().splitlines()
    assert table[0] == (
        "| probe | model | worst delta1 5°/0.1 m | worst delta1 30°/0.6 m | agreement 30°/0.6 m | search noise "
        "30°/0.6 m | failure rate 30°/0.6 m | worst-case area | resilience | typical area |"
    )
    # one run a search: each seed's worst found by one run alone; one search seed: noise not measured
    assert all(row.split(" | ")[4:6] == ["2/2 (2 alone)", "n/a"] for row in table[2:6])
    assert any(line.startswith("cost of kadv_tiny per init view (mean over probes): ") for line in table)
    assert [row.split(" | ")[:2] for row in table[2:8]] == [
        ["| window", "kadv_tiny"],
        ["| window", "Constant"],
        ["| stairs", "kadv_tiny"],
        ["| stairs", "Constant"],
        ["| **mean**", "kadv_tiny"],
        ["| **mean**", "Constant"],
    ]
    profile = card.results["window"]["Constant"]
    assert profile.seeds == (0, 1) and f"{profile.score:.3f} ± {profile.score_spread:.3f}" in table[3]
    # a model that sees nothing scores below one that sees, paired probe by probe and seed by seed
    typical = next(line for line in table if line.startswith("ranking (typical area): "))
    assert typical.startswith("ranking (typical area): kadv_tiny (") and " > Constant (" in typical
    assert any(line.startswith("kadv_tiny - Constant (worst-case area): ") for line in table)
    png = card.save_png(tmp_path / "card.png")
    from PIL import Image

    with Image.open(png) as image:
        assert image.width > 2 * 200 and image.height > 150


def test_the_scorecard_is_a_suite_run_whose_entries_verify_and_resume(tmp_path: Path) -> None:
    from kadv.bench import load_entry, load_suite, verify_entry
    from kadv.models import load_model

    quick = {**QUICK, "budget_passes": 4, "size": (24, 32), "typical_views": 4, "radii": ((5, 0.1), (30, 0.6))}
    models = ["kadv_tiny", "kadv_tiny_dpt"]
    card = scorecard(models, ["stairs"], seeds=(0,), search_seeds=2, artifacts=tmp_path, **quick)
    (suite_file,) = tmp_path.glob("suite-*.json")
    suite = load_suite(suite_file)
    assert suite.hash == card.suite["hash"] and [s.name for s in suite.scenes] == ["probe/stairs/seed0"]
    assert sum(suite.protocol.radius_passes) == 2 * 4 and suite.protocol.min_seeds == 2  # 4 a radius on average
    entries = {}
    for name in models:
        (path,) = tmp_path.glob(f"entries/{name}-{suite.hash[:12]}/entry.json")
        entries[name] = load_entry(path)
        checked = verify_entry(entries[name], suite, load_model(name))  # another lab can check it
        assert checked.cells == 2 * 2 and checked.largest_pixels <= checked.tolerance_pixels
        # the profile's worst is the entry's cells, averaged over the init view's two search seeds
        cells = np.array([[c.delta1 for c in u.cells] for u in entries[name].units])
        assert card.results["stairs"][name].worst == pytest.approx(cells.mean(axis=0).tolist())
        score = card.suite_scores[name]
        assert score["per_radius"] == pytest.approx(cells.mean(axis=0).tolist())
        # the pooled worst, a column of its own: never above the model's own worst
        assert all(p <= o + 1e-12 for p, o in zip(card.pooled[name], [score["overall"], *score["per_radius"]]))
    table = card.markdown()
    assert "\nsuite score (suite probes " in table and "\n- kadv_tiny: " in table and "; pooled worst " in table
    # run again in the same folder: every unit is read back, none searched again
    stamps = {path: path.stat().st_mtime_ns for path in tmp_path.glob("entries/*/units/*.json")}
    again = scorecard(models, ["stairs"], seeds=(0,), search_seeds=2, artifacts=tmp_path, **quick)
    assert {path: path.stat().st_mtime_ns for path in stamps} == stamps
    assert again.markdown() == table
