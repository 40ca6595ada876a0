from __future__ import annotations

from dataclasses import replace

import pytest

from kadv.attack import AttackConfig, RandomSettings, Study, StudySettings
from kadv.attack.radii import radius_budgets, ramp_shares, search_radii


def test_radius_budgets_split_the_total_in_proportion_to_the_shares() -> None:
    assert radius_budgets(48, 3, None) == radius_budgets(48, 3, ramp_shares(3)) == [24, 48, 72]  # the default
    assert radius_budgets(48, 3, (1, 1, 1)) == [48, 48, 48]
    assert radius_budgets(10, 4, None) == [4, 8, 12, 16] and ramp_shares(2) == (1, 2)
    assert radius_budgets(48, 3, (1, 1, 2)) == [36, 36, 72]
    uneven = radius_budgets(7, 3, (1, 2, 3))  # 21 passes do not split evenly: rounding keeps the total
    assert sum(uneven) == 21 and uneven == sorted(uneven)
    assert radius_budgets(None, 3, (1, 2, 3)) == [None, None, None]  # no pass budget: none to split


def test_every_radius_keeps_two_passes_the_init_view_and_one_more_where_the_total_allows() -> None:
    budgets = radius_budgets(2, 3, (1, 100, 100))
    assert sum(budgets) == 6 and budgets[0] == 2
    assert radius_budgets(1, 3, None) == [1, 1, 1]


@pytest.mark.parametrize("shares", [(1, 2), (1, 0, 2), (1, -1, 2), (1, float("nan"), 2)])
def test_shares_that_are_not_one_positive_number_a_radius_are_refused_in_one_line(shares) -> None:
    with pytest.raises(ValueError, match=r"attack\.radius_shares must be 3 positive numbers, one a radius"):
        radius_budgets(48, 3, shares)


def test_a_search_across_radii_spends_each_radius_s_share(tiny_objective, file_view) -> None:
    study = Study.build(
        tiny_objective.renderer.scene, tiny_objective.model, StudySettings(size=(48, 64), progress=False)
    )
    config = AttackConfig("random", RandomSettings(4), budget_passes=12, radius_shares=(1, 1, 2))
    radii = ((5.0, 0.1), (15.0, 0.3), (45.0, 1.0))
    results = search_radii(study, [file_view], config, radii, 0)
    assert [result.views[0].budget.passes for result in results] == [9, 9, 18]
    equal = search_radii(study, [file_view], replace(config, radius_shares=(1, 1, 1)), radii, 0)
    assert [result.views[0].budget.passes for result in equal] == [12, 12, 12]
    ramp = search_radii(study, [file_view], replace(config, radius_shares=None), radii, 0)  # the default
    assert [result.views[0].budget.passes for result in ramp] == [6, 12, 18]


@pytest.mark.parametrize("shares", [(), (1, 0), [1, 2], (1, True), (1, float("inf"))])
def test_an_attack_config_refuses_shares_that_are_not_positive_numbers(shares) -> None:
    with pytest.raises(ValueError, match=r"attack\.radius_shares must be null or positive numbers, one a radius"):
        AttackConfig(radius_shares=shares)
