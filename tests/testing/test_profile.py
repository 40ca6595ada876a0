"""Robustness profiles: worst and typical delta1 against the radius of the camera's move, the score,
and the checks that use them."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from kadv.testing import Profile, RobustnessInputError, assert_viewpoint_robust, robustness_profile, scene
from kadv.testing.options import check_radii
from kadv.testing.plugin import _summary_line
from kadv.testing.session import settings

# two small radii, one init view, few views: the profile's arithmetic is the same at any budget
QUICK = {
    "radii": ((5.0, 0.1), (30.0, 0.6)),
    "budget_passes": 6,
    "typical_views": 4,
    "init_count": 1,
    "size": (24, 32),
    "lighting": "direct",
}


def _profile(**changes) -> Profile:
    fields = {
        "model": "m",
        "scene": "s",
        "envelope": "upright",
        "radii": ((5.0, 0.1), (15.0, 0.3), (45.0, 1.0)),
        "seeds": (0, 1),
        "delta1_init": [0.9, 0.8],
        "worst_by_seed": [[0.7, 0.5, 0.1], [0.8, 0.4, 0.0]],
        "typical_by_seed": [[0.9, 0.8, 0.7], [0.8, 0.8, 0.6]],
        "failure_by_seed": [[0.0, 0.1, 0.2], [0.0, 0.0, 0.4]],
        "draws": [[0.9, 0.8, 0.9, 0.8], [0.8, 0.8, 0.9, 0.7], [0.7, 0.4, 0.8, 0.6]],
        "fail_below": 0.5,
        "pictures": [],
    }
    return Profile(**(fields | changes))


def test_the_score_is_the_mean_trapezoid_under_the_typical_curve_from_the_init_views() -> None:
    profile = _profile()
    # seed 0: (0.9+0.9)/2, (0.9+0.8)/2, (0.8+0.7)/2 -> 2.5/3; seed 1: 0.8, 0.8, 0.7 -> 2.3/3
    assert profile.scores == pytest.approx([2.5 / 3, 2.3 / 3])
    assert profile.score == pytest.approx(0.8) and profile.score_spread == pytest.approx(0.2 / 3)
    # the worst curve's area: seed 0: (0.9+0.7)/2, (0.7+0.5)/2, (0.5+0.1)/2 -> 1.7/3; seed 1: 1.6/3
    assert profile.worst_score == pytest.approx(0.55)
    assert profile.worst == pytest.approx([0.75, 0.45, 0.05]) and profile.failure_rate == pytest.approx([0, 0.05, 0.3])
    perfect = _profile(delta1_init=[1.0, 1.0], typical_by_seed=[[1.0] * 3] * 2)
    assert perfect.score == 1.0 and perfect.score_spread == 0.0
    # the resilience: the worst-case area over the init views' delta1, per seed, mean
    assert profile.worst_scores == pytest.approx([1.7 / 3, 1.6 / 3])
    assert profile.resilience == pytest.approx(((1.7 / 3) / 0.9 + (1.6 / 3) / 0.8) / 2)
    table = profile.markdown()
    # the draws' intervals: 0.8 ± 1.96 * 0.0816 / 2; Wilson's for 0 of 4 and 1 of 4 failed
    assert "| 15°, 0.3 m | 0.450 | - | 0.800 (0.720-0.880) | 5% (0%-49%) |" in table  # no agreement recorded
    assert "seeds [0, 1], delta1 after scale_shift alignment in disparity space: 0.850 at the init views" in table
    assert profile.failure_interval[2] == pytest.approx((0.0456, 0.6994), abs=1e-4)
    merged = Profile.merge([profile, profile])
    assert merged.seeds == (0, 1, 0, 1) and merged.score == pytest.approx(profile.score)
    assert len(merged.draws[0]) == 8
    assert table.endswith(
        "worst-case area 0.550 ± 0.033, resilience 0.648 (worst-case area / init delta1)\n"
        "score 0.800 ± 0.067 (typical area; spread over seeds)\n"
        "search noise not measured (search_seeds=1; 3 or more measure it); init views' spread "
        "(worst-case area over seeds): 0.033"
    )
    assert profile.to_dict()["score"] == pytest.approx(profile.score)


def test_a_profile_never_rises_with_the_radius_and_repeats_for_its_seed(tmp_path: Path) -> None:
    room = scene("box_room", seed=3)
    first = robustness_profile("kadv_tiny", room, artifacts=tmp_path / "a", **QUICK)
    again = robustness_profile("kadv_tiny", room, artifacts=tmp_path / "b", **QUICK)

    def comparable(profile: Profile) -> dict:  # what the seed fixes: not the pictures' paths, not the seconds
        costs = [{k: v for k, v in c.items() if k != "search_seconds"} for c in profile.cost_by_seed]
        return {**profile.to_dict(), "pictures": [], "cost_by_seed": costs}

    assert comparable(first) == comparable(again)
    # what it cost per init view: the search's passes over the radii within their budget, the draws'
    cost = first.cost_by_seed[0]
    assert 0 < cost["search_passes"] <= len(first.radii) * QUICK["budget_passes"] and cost["search_seconds"] > 0
    assert cost["draw_passes"] == len(first.radii) * QUICK["typical_views"] and "cost per init view" in first.markdown()
    worst = first.worst_by_seed[0]
    assert worst[1] <= worst[0] <= first.delta1_init[0]  # nested radii: the larger holds the smaller's worst
    assert all(0 <= v <= 1 for v in [*first.typical, *first.failure_rate]) and 0 <= first.score <= 1
    assert first.envelope == "upright" and len(first.pictures) == 2 and Path(first.pictures[1]).is_file()
    assert first.save_png(tmp_path / "profile.png").stat().st_size > 0


def test_search_noise_is_the_spread_of_the_worst_over_search_seeds_from_the_same_init_views(tmp_path: Path) -> None:
    room = scene("box_room", seed=3)
    one = robustness_profile("kadv_tiny", room, artifacts=tmp_path / "a", **QUICK)
    three = robustness_profile("kadv_tiny", room, artifacts=tmp_path / "b", search_seeds=3, **QUICK)
    # the first search is the seed's own: the profile's figures are those of one search
    assert three.worst_by_seed == one.worst_by_seed and three.delta1_init == one.delta1_init
    (noise,) = three.search_noise_by_seed
    assert len(noise) == len(three.radii) and all(v >= 0 for v in noise) and three.search_noise == noise
    assert one.search_noise_by_seed == [[]] and all(math.isnan(v) for v in one.search_noise)
    assert "search noise (sd of the worst over search seeds, init views fixed)" in three.markdown()
    with pytest.raises(RobustnessInputError, match="search_seeds must be an integer >= 1, got 0"):
        robustness_profile("kadv_tiny", room, search_seeds=0, **QUICK)


def test_each_radius_is_searched_from_the_worst_views_of_the_smaller_ones() -> None:
    from kadv.attack import AttackConfig
    from kadv.testing.options import CheckOptions, setup
    from kadv.testing.profile import search_radii, worst_views

    built = setup("kadv_tiny", "box_room", CheckOptions(init_count=1, size=(24, 32), lighting="direct"))
    config = AttackConfig(budget_passes=8, envelope="upright")
    radii = ((5.0, 0.1), (15.0, 0.3), (30.0, 0.6))
    results = search_radii(built.study, built.views, config, radii, seed=0)
    for k in (1, 2):
        smaller = [r for result in results[:k] for r in result.views[0].records]
        expected = [r.params for r in worst_views(smaller, 2, config.min_separation, config.min_separation_deg)]
        started = [r.params for r in results[k].views[0].records if r.step == 1]  # evaluated right after the init view
        np.testing.assert_allclose(started, expected)
        assert all(r.rankable or not r.valid for r in results[k].views[0].records if r.step == 1)
    # the worst views: rankable, lowest delta1 first
    chosen = worst_views(results[0].views[0].records, 3, 0.0, 0.0)
    rankable = sorted(r.delta1 for r in results[0].views[0].records if r.rankable)
    assert [r.delta1 for r in chosen] == rankable[:3]


@pytest.mark.parametrize(
    "radii, message",
    [
        (((15, 0.3), (5, 0.1)), r"radii must increase \(each holds the one before\), got \(15, 0.3\) then \(5, 0.1\)"),
        (((5, -0.1),), r"radii: each radius must be positive, got \(5, -0.1\)"),
        ((), "radii is empty"),
        ((5, 0.1), r"radii must be \(degrees, metres\) pairs"),
    ],
)
def test_radii_that_are_not_nested_and_positive_are_refused(radii, message: str) -> None:
    with pytest.raises(RobustnessInputError, match=message):
        check_radii(radii)


@pytest.mark.parametrize(
    "options, message",
    [
        ({"seeds": ()}, r"seeds must be one or more integers >= 0, got \[\]"),
        ({"envelope": "drone"}, "envelope 'drone' is not a preset"),
        ({"radius": (5, 0.1)}, "robustness_profile takes radii and seeds, not radius"),
        ({"colour": "red"}, "robustness_profile takes no option colour"),
    ],
)
def test_bad_profile_settings_are_refused_in_one_line(options: dict, message: str) -> None:
    with pytest.raises(RobustnessInputError, match=message):
        robustness_profile("kadv_tiny", "box_room", **{**QUICK, **options})


def test_the_assertion_checks_one_radius_and_envelope_or_the_score(tmp_path: Path) -> None:
    quick = {k: v for k, v in QUICK.items() if k not in ("radii", "typical_views")}
    with pytest.raises(AssertionError) as failure:
        assert_viewpoint_robust(
            "kadv_tiny", "box_room", min_delta1=1.0, radius=(5, 0.1), envelope="robot", artifacts=tmp_path, **quick
        )
    assert "within 5°, 0.1 m (envelope robot) (wanted delta1 >= 1.0)" in str(failure.value)
    reports = []
    below = r"score on box_room_0 is 0\.\d{3} .*below min_score 1.0 \(radii 5°/0.1 m"
    with settings(observer=lambda result, passed: reports.append((result, passed))):
        with pytest.raises(AssertionError, match=below):
            assert_viewpoint_robust("kadv_tiny", "box_room", min_score=1.0, artifacts=tmp_path, **QUICK)
    # the plugin's session summary gets the score check too
    ((profile, passed),) = reports
    assert isinstance(profile, Profile) and not passed
    assert _summary_line(profile) == (
        f"kadv_tiny x box_room_0: score {profile.score:.3f} ± 0.000 (radii 5°/0.1 m, 30°/0.6 m, envelope upright)"
    )


def test_the_ranking_compares_models_by_their_paired_difference() -> None:
    from kadv.testing import Scorecard

    # per seed (typical areas): high 0.967, 0.917; near 0.900, 0.967; low 0.833, 0.767
    high = _profile(typical_by_seed=[[1.0, 1.0, 0.9], [1.0, 0.9, 0.9]])
    near = _profile(typical_by_seed=[[0.9, 0.9, 0.9], [1.0, 1.0, 1.0]])  # ahead of high on seed 1, behind on seed 0
    low = _profile()  # below high and near on both seeds, though its band overlaps near's
    card = Scorecard(["near", "low", "high"], ["p", "q"], {p: {"near": near, "low": low, "high": high} for p in "pq"})
    assert card.ranking() == (
        "ranking (typical area): high (0.942) = near (0.933) > low (0.800); "
        "'=': the paired difference's 95% interval holds 0 (tied)"
    )
    difference = card.difference("near", "low")
    assert difference.mean == pytest.approx(0.1333, abs=1e-4) and difference.low > 0 and difference.units == 4
    # the worst-case areas are the same for all three: tied, by a difference of exactly 0
    assert card.ranking("worst").startswith("ranking (worst-case area): ") and " > " not in card.ranking("worst")
    lines = card.differences("typical")
    interval = f"95% {difference.low:+.3f} to {difference.high:+.3f}"
    expected = f"near - low (typical area): +0.133 ({interval}, 4 probe-seed pairs); apart on 2 of 2 probes"
    assert expected in lines
    table = card.markdown()
    assert "| worst-case area | resilience | typical area |" in table.splitlines()[0]
    assert f"| {low.worst_score:.3f} ± {np.ptp(low.worst_scores):.3f} | {low.resilience:.3f} |" in table


def test_a_paired_difference_separates_only_when_its_bootstrap_interval_excludes_zero() -> None:
    from kadv.testing.card import paired_difference

    always = paired_difference([0.9, 0.8, 0.7, 0.6], [0.85, 0.7, 0.65, 0.5])  # a ahead on every unit
    assert always.separated and always.low > 0 and always.mean == pytest.approx(0.075)
    mixed = paired_difference([0.9, 0.6, 0.8], [0.7, 0.8, 0.75])
    assert not mixed.separated and mixed.low < 0 < mixed.high
    assert paired_difference([0.9, float("nan")], [0.5, 0.4]).units == 1  # a unit without a value is left out
    assert paired_difference([0.9, 0.6, 0.8], [0.7, 0.8, 0.75]) == mixed  # deterministic
    with pytest.raises(RobustnessInputError, match="paired_difference: 2 units against 3"):
        paired_difference([0.1, 0.2], [0.1, 0.2, 0.3])


def test_a_stratified_difference_leaves_the_strata_s_own_spread_out() -> None:
    from kadv.testing.card import paired_difference

    # two probes: a ahead by about 0.1 on one and behind by about 0.015 on the other, each seed alike
    a, b = [0.90, 0.91, 0.58, 0.59], [0.80, 0.80, 0.60, 0.60]
    pooled = paired_difference(a, b)
    assert pooled.low < 0 < pooled.high  # over all units, the probes' gap is the spread: tied
    stratified = paired_difference(a, b, strata=["p", "p", "q", "q"])
    # with the probes fixed, only the seeds' spread within each moves the mean: 0.045, each
    # probe's two differences 0.005 from their mean, spread by sqrt(2) for two units
    assert stratified.mean == pytest.approx(0.045) and stratified.separated
    assert 0.045 - 0.005 * 2**0.5 - 1e-9 <= stratified.low < stratified.high <= 0.045 + 0.005 * 2**0.5 + 1e-9
    # a probe with a single unit cannot say how much its seeds spread: all units together, as without strata
    assert paired_difference(a[:3], b[:3], strata=["p", "p", "q"]) == paired_difference(a[:3], b[:3])
    with pytest.raises(RobustnessInputError, match="4 units against 4 and 3 strata labels"):
        paired_difference(a, b, strata=["p", "p", "q"])


def test_a_seed_without_valid_draws_leaves_the_others_mean() -> None:
    nan = float("nan")
    profile = _profile(typical_by_seed=[[0.9, nan, 0.7], [0.8, nan, nan]], failure_by_seed=[[0.0, nan, 0.2]] * 2)
    typical = profile.typical
    assert typical[0] == pytest.approx(0.85) and typical[2] == pytest.approx(0.7) and typical[1] != typical[1]
    assert profile.failure_rate[2] == pytest.approx(0.2)


def test_the_agreement_per_radius_sums_the_runs_over_seeds_and_init_views() -> None:
    # per seed and radius: [runs that reached their worst, runs made, init views whose worst one run alone found]
    rows = [[[1, 1, 1], [2, 3, 0], [1, 3, 1]], [[1, 1, 1], [2, 2, 0], [3, 3, 0]]]
    profile = _profile(agreement_by_seed=rows)
    assert [profile.agreement_text(k) for k in range(3)] == ["2/2 (2 alone)", "4/5", "4/6 (1 alone)"]
    assert "| 15°, 0.3 m | 0.450 | 4/5 | 0.800" in profile.markdown()
    assert Profile.from_dict(profile.to_dict()).agreement_by_seed == rows
    assert Profile.merge([profile, profile]).agreement_text(1) == "8/10"


def test_a_profile_with_restarts_records_each_radius_agreement(tmp_path: Path) -> None:
    room = scene("box_room", seed=3)
    budget = {**QUICK, "budget_passes": 2 * QUICK["budget_passes"]}
    profile = robustness_profile("kadv_tiny", room, artifacts=tmp_path, restarts=2, **budget)
    ((first, second),) = profile.agreement_by_seed
    # two runs a search: both made (they agree or the second was the last), summed over the init views
    views = budget.get("init_count", 2)
    assert first[1] == second[1] == 2 * views and views <= first[0] <= 2 * views
    assert profile.agreement_text(1) in profile.markdown()
    with pytest.raises(RobustnessInputError, match=r"attack\.restarts must be an integer >= 1, got 0"):
        robustness_profile("kadv_tiny", room, restarts=0, **QUICK)
