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
from kadv.testing.profile import seed_run

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


def test_pooling_scores_each_model_at_the_other_searches_worst_views_and_never_raises_its_worst() -> None:
    from kadv.catalogue import probe_scene
    from kadv.testing.profile import pool_worst_views, profile_settings, worst_views

    options = {"budget_passes": 6, "size": (24, 32), "lighting": "direct", "init_count": 2}
    settings = profile_settings(((5, 0.1), (30, 0.6)), "upright", 4, 0.6, options, "test")
    room = probe_scene("window", 0)
    runs = [seed_run(model, room, settings, 0) for model in ("kadv_tiny", (Constant(), "depth"))]
    before = [[[record.delta1 for _, record in row] for row in run.seeded.found] for run in runs]
    expected = {  # the views each run's model is scored at: the other's two worst per radius and init view
        id(run): [
            [[r.params for r in worst_views(other.seeded.results[k].views[i].records, 2, 0.05, 3.0)] for i in range(2)]
            for k in range(2)
        ]
        for run, other in ((runs[0], runs[1]), (runs[1], runs[0]))
    }
    scored = pool_worst_views(runs, settings.radii)
    assert scored == sum(len(views) for run in runs for row in expected[id(run)] for views in row)
    for run, old in zip(runs, before):
        for k, row in enumerate(run.seeded.found):
            for i, (_, record) in enumerate(row):
                assert record.delta1 <= old[k][i]  # pooling never raises a worst
                if record.delta1 < old[k][i]:  # and a lower one is one of the other search's views
                    assert any(np.allclose(record.params, p) for p in expected[id(run)][k][i])


def test_a_pooled_view_lowers_the_worst_at_its_radius_and_every_larger_one() -> None:
    from kadv.attack import ViewRecord
    from kadv.testing.profile import SeedProfile

    def record(delta1: float, verdict: str = "valid") -> ViewRecord:
        return ViewRecord(0, 0, [0.0] * 6, [0.0] * 3, [1.0, 1.5, 1.0], 0.1, 0.0, 0.1, delta1, 0.1, verdict)

    found = [[("a", record(0.8)), ("b", record(0.9))], [("a", record(0.7)), ("b", record(0.95))]]
    seeded = SeedProfile(0.95, [], [], [[], []], found, [])
    assert seeded.worst == pytest.approx([0.85, 0.8])  # nested: view b keeps 0.9 at the larger radius
    seeded.pool(0, 1, [record(0.5), record(0.1, "inside an object")])  # the invalid one is left out
    assert seeded.worst == pytest.approx([0.65, 0.6]) and seeded.worst_views[1][1].delta1 == 0.5
    seeded.pool(1, 0, [record(0.75)])  # not lower than that radius's own 0.7: nothing changes
    assert seeded.worst == pytest.approx([0.65, 0.6])
