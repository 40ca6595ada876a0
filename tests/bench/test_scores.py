from __future__ import annotations

import math

import numpy as np
import pytest

from kadv.bench import Protocol, Suite, SuiteScene, best_known, paired_difference, suite_score
from kadv.bench.scores import Pooled

RADII = ((5.0, 0.1), (45.0, 1.0))


def _suite(scenes: int, views: int) -> Suite:
    frozen = tuple(SuiteScene(f"s{k}", {}, {}, "", "", (None,) * views) for k in range(scenes))
    return Suite("analytic", Protocol(radii=RADII, radius_passes=(4, 4), min_seeds=2), frozen, "0", 0)


def _pooled(worst: np.ndarray, views: int, seeds: tuple[int, ...]) -> Pooled:
    cells = worst.shape[0]
    return Pooled(worst, np.ones((cells, len(seeds))), worst / 2, np.arange(cells) // views, seeds)


def test_the_suite_score_is_the_mean_of_seed_averaged_cells_with_the_seeds_standard_error() -> None:
    # 2 scenes x 2 views, 2 radii, 3 seeds: each cell's seeds are its level -0.1, +0, +0.1 (sd 0.1)
    levels = np.array([[0.9, 0.5], [0.8, 0.4], [0.7, 0.3], [0.6, 0.2]])
    worst = levels[:, :, None] + np.array([-0.1, 0.0, 0.1])
    score = suite_score(_suite(2, 2), _pooled(worst, 2, (0, 1, 2)))
    assert score.per_radius == pytest.approx([0.75, 0.35])
    assert score.overall == pytest.approx(0.55)
    # each cell's mean has variance 0.1^2 / 3; the mean of 4 (8) cells divides by 4 (8)
    assert score.per_radius_se == pytest.approx([math.sqrt(4 * 0.01 / 3) / 4] * 2)
    assert score.overall_se == pytest.approx(math.sqrt(8 * 0.01 / 3) / 8)
    lo, hi = score.overall_interval
    assert hi - lo == pytest.approx(2 * 1.959964 * score.overall_se)
    # over scenes: the two scenes' means 0.65 and 0.45, t with one degree of freedom
    assert score.scenes_interval[0] == pytest.approx(0.55 - 12.7062 * 0.1, rel=1e-4)  # sd 0.141 / sqrt(2)
    assert score.init == 1.0 and score.drop == pytest.approx(0.45) and score.abs_rel == pytest.approx(0.275)
    assert score.per_scene == {"s0": pytest.approx([0.85, 0.45]), "s1": pytest.approx([0.65, 0.25])}


def test_best_known_takes_each_cell_s_lowest_seed_and_a_paired_difference_its_common_seeds() -> None:
    rng = np.random.default_rng(0)
    worst = rng.uniform(0.2, 0.9, size=(4, 2, 3))
    first = _pooled(worst, 2, (0, 1, 2))
    overall, per_radius = best_known(first)
    assert per_radius == pytest.approx(worst.min(axis=2).mean(axis=0).tolist())
    assert overall == pytest.approx(worst.min(axis=2).mean())
    # the second model is the first lowered by 0.05 everywhere, on seeds 1, 2 and 3
    second = _pooled(np.concatenate([worst[:, :, 1:] - 0.05, worst[:, :, :1]], axis=2), 2, (1, 2, 3))
    mean, se, common = paired_difference(first, second)
    assert (mean, common) == (pytest.approx(0.05), 2) and se == pytest.approx(0.0, abs=1e-12)
    with pytest.raises(ValueError, match="no seed"):
        paired_difference(first, _pooled(worst, 2, (7, 8, 9)))


def test_the_seeds_interval_covers_the_mean_of_a_known_noise_about_95_percent_of_the_time() -> None:
    rng = np.random.default_rng(1)
    truth = rng.uniform(0.2, 0.8, size=(30, 2))  # 30 cells' expected worst at two radii
    covered = 0
    for _ in range(400):
        worst = truth[:, :, None] + rng.normal(0.0, rng.uniform(0.02, 0.1, size=(30, 2, 1)), size=(30, 2, 3))
        lo, hi = suite_score(_suite(15, 2), _pooled(worst, 2, (0, 1, 2))).overall_interval
        covered += lo <= truth.mean() <= hi
    assert 0.90 <= covered / 400 <= 0.99
