"""Suites, entries, their check and the leaderboard, on a suite of two small box rooms."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import pytest
import torch

from kadv.attack import METHODS
from kadv.bench import (
    BenchError,
    Entry,
    Protocol,
    SceneSpec,
    Suite,
    freeze_suite,
    leaderboard,
    load_suite,
    pool_units,
    pooled_worst,
    run_suite,
    shipped_specs,
    suite_score,
    unit_path,
    unit_search_seed,
    verify_entry,
)
from kadv.bench.board import DIVERGENT_VERSIONS
from kadv.datasets import HELD_OUT_SEED
from kadv.geometry import perturb_world_T_cam
from kadv.models import count_passes, load_model
from kadv.penalties import get_envelope
from kadv.render import ExactRenderer, Shading
from kadv.training import TinyTrainConfig

PROTOCOL = Protocol(radius_passes=(6, 6, 8), min_seeds=2, size=(24, 32), lighting="direct")
SPECS = [SceneSpec(f"box{k}", {"kind": "box_room", "seed": k}) for k in (0, 1)]


@pytest.fixture(scope="module")
def suite() -> Suite:
    return freeze_suite("boxes", SPECS, PROTOCOL, views_per_scene=2, seed=0)


@pytest.fixture(scope="module")
def model():
    return load_model("kadv_tiny")


@pytest.fixture(scope="module")
def run(suite, model, tmp_path_factory) -> tuple[Entry, Path]:
    out = tmp_path_factory.mktemp("entry")
    return run_suite(suite, model, (0, 1), out, progress=False), out


def _without_seconds(entry: Entry) -> list:
    return [
        dataclasses.replace(u, cells=tuple(dataclasses.replace(c, seconds=0.0) for c in u.cells)) for u in entry.units
    ]


def test_a_suite_is_frozen_by_a_model_free_rule_and_read_back_with_its_hash(suite, tmp_path) -> None:
    again = freeze_suite("boxes", SPECS, PROTOCOL, views_per_scene=2, seed=0)
    assert again.hash == suite.hash  # the rule is deterministic, and reads no model
    path = suite.save(tmp_path / "suite.json")
    assert load_suite(path) == suite
    envelope = get_envelope(PROTOCOL.envelope)
    for frozen in suite.scenes:
        renderer = ExactRenderer(frozen.load(), Shading(lighting="direct"), progress=False)
        poses = torch.stack([torch.tensor(v.world_T_cam, dtype=torch.float64) for v in frozen.views])
        assert envelope.figures(renderer, poses).reasons() == [None, None]
        assert len({tuple(v.world_T_cam[i][3] for i in range(3)) for v in frozen.views}) == 2
    data = json.loads(path.read_text())
    data["protocol"]["radius_passes"] = [6, 6, 9]  # a changed protocol is a new suite
    path.write_text(json.dumps(data))
    with pytest.raises(BenchError, match="hash"):
        load_suite(path)


def test_a_scene_whose_content_changed_is_refused_naming_it(suite) -> None:
    moved = dataclasses.replace(suite.scenes[0], node={"kind": "box_room", "seed": 5})
    with pytest.raises(BenchError, match=r"scene 'box0'.*content digest"):
        moved.load()


def test_the_shipped_offline_suite_holds_held_out_rooms_and_the_probes() -> None:
    suite = load_suite("offline-v1")
    assert suite.protocol.passes_per_view == 288 and suite.protocol.min_seeds == 3
    config = TinyTrainConfig()
    trained = {seed * 100_003 + i for seed in (config.seed, config.val_seed) for i in range(100_003)}
    seeds = [s.node["seed"] for s in suite.scenes]
    assert not trained & set(seeds) and all(s // 100_003 == HELD_OUT_SEED for s in seeds)
    assert {s.node["name"] for s in suite.scenes if s.node["kind"] == "probe"} == {
        spec.node["name"] for spec in shipped_specs("offline-v1") if spec.node["kind"] == "probe"
    }
    room = suite.scenes[0]
    assert room.load().num_triangles > 100  # generated again from its seed, its digest checked


def test_an_entry_records_every_unit_within_its_budget(run, suite) -> None:
    entry, _ = run
    assert [u.key for u in entry.units] == [(s, v, seed) for s in (0, 1) for v in (0, 1) for seed in (0, 1)]
    for unit in entry.units:
        # the passes an entry records are the passes the model ran, within the protocol's
        assert unit.model_passes == sum(c.passes for c in unit.cells) <= PROTOCOL.passes_per_view
        worst = [c.delta1 for c in unit.cells]
        assert worst == sorted(worst, reverse=True) and worst[0] <= unit.delta1_init  # nested radii
        # one run a search (protocol.restarts): each worst found by that run alone
        assert all(c.agreement == [1, 1, 1] for c in unit.cells)
    assert entry.suite == {"name": "boxes", "hash": suite.hash} and entry.model["output_kind"] == "disparity"
    assert len(entry.model["weights"]) == 64 and entry.environment["device"] == "cpu"


@pytest.mark.parametrize("method", sorted(METHODS))
def test_every_method_s_entry_records_no_more_passes_than_the_model_ran_or_the_budget_allows(method, model, tmp_path):
    protocol = dataclasses.replace(PROTOCOL, method=method, radius_passes=(10, 10, 12), min_seeds=1)
    one = Suite("one", protocol, (freeze_suite("x", SPECS[:1], protocol, 1).scenes[0],), "0", 0)
    with count_passes(model) as count:
        entry = run_suite(one, model, (0,), tmp_path, progress=False)
    (unit,) = entry.units
    assert count.passes == unit.model_passes == sum(c.passes for c in unit.cells) <= protocol.passes_per_view
    assert all(c.passes <= budget for c, budget in zip(unit.cells, protocol.radius_passes))


def test_a_run_resumes_and_shards_give_the_same_entry(run, suite, model, tmp_path) -> None:
    entry, out = run
    unit_path(out, (1, 0, 1)).unlink()
    with count_passes(model) as count:
        resumed = run_suite(suite, model, (0, 1), out, progress=False)
    assert count.passes == entry.unit((1, 0, 1)).model_passes  # only the missing unit ran again
    assert _without_seconds(resumed) == _without_seconds(entry)
    assert run_suite(suite, model, (0, 1), tmp_path, shard=(1, 2), progress=False) is None  # half the units
    sharded = run_suite(suite, model, (0, 1), tmp_path, shard=(0, 2), progress=False)
    assert _without_seconds(sharded) == _without_seconds(entry)
    with pytest.raises(BenchError, match="2 distinct seeds"):
        run_suite(suite, model, (0,), tmp_path)


def test_a_run_folder_never_resumes_from_another_suite_s_or_model_s_units(run, suite, model) -> None:
    _, out = run
    other = dataclasses.replace(suite, protocol=dataclasses.replace(PROTOCOL, radius_passes=(6, 6, 9)))
    with pytest.raises(BenchError, match=r"holds the run of another suite \(suite [0-9a-f]{16}, this run's"):
        run_suite(other, model, (0, 1), out, progress=False)
    dpt = load_model("kadv_tiny_dpt")
    with pytest.raises(BenchError, match="holds the run of another model"):
        run_suite(suite, dpt, (0, 1), out, progress=False)


def test_an_entry_verifies_and_a_forged_one_is_refused_naming_the_cell_and_field(run, suite, model) -> None:
    entry, _ = run
    checked = verify_entry(entry, suite, model)
    assert checked.cells == 8 * 3 and checked.largest_pixels <= checked.tolerance_pixels

    def forged(change) -> Entry:
        units = list(entry.units)
        cells = list(units[0].cells)
        cells[2] = change(cells[2])
        units[0] = dataclasses.replace(units[0], cells=tuple(cells))
        return dataclasses.replace(entry, units=tuple(units))

    better = forged(lambda c: dataclasses.replace(c, delta1=c.delta1 - 0.01))
    with pytest.raises(BenchError, match=r"scene 'box0', view 0, seed 0, radius 2: delta1"):
        verify_entry(better, suite, model)
    moved = forged(lambda c: dataclasses.replace(c, params=[c.params[0] + 0.01, *c.params[1:]]))  # turned 0.6°
    with pytest.raises(BenchError, match="radius 2: world_T_cam is not the pose its params give"):
        verify_entry(moved, suite, model)

    def far(cell):  # a consistent pose 1.5 m away: outside the 1 m radius
        params = [*cell.params[:3], 1.5, 0.0, 0.0]
        init = torch.tensor(suite.scenes[0].views[0].world_T_cam, dtype=torch.float64)[None]
        pose = perturb_world_T_cam(
            init, torch.tensor([params[:3]], dtype=torch.float64), torch.tensor([params[3:]], dtype=torch.float64)
        )[0]
        return dataclasses.replace(cell, params=params, world_T_cam=pose.tolist())

    with pytest.raises(BenchError, match="outside the radius 45°, 1 m"):
        verify_entry(forged(far), suite, model)
    with pytest.raises(BenchError, match="misses the cell of scene 'box1', view 1, seed 1"):
        verify_entry(dataclasses.replace(entry, units=entry.units[:-1]), suite, model)
    with pytest.raises(BenchError, match=r"suite.hash"):
        verify_entry(dataclasses.replace(entry, suite={"name": "boxes", "hash": "0" * 64}), suite, model)
    with pytest.raises(BenchError, match=r"model.weights"):
        verify_entry(entry, suite, load_model("kadv_tiny_dpt"))


def _relabelled(entry: Entry, seeds: dict[int, int]) -> Entry:
    units = tuple(dataclasses.replace(u, seed=seeds[u.seed]) for u in entry.units)
    return dataclasses.replace(entry, seeds=tuple(seeds[s] for s in entry.seeds), units=units)


def test_the_leaderboard_pools_disjoint_seeds_and_refuses_mixed_entries(run, suite, monkeypatch) -> None:
    entry, _ = run
    other = _relabelled(entry, {0: 2, 1: 3})
    board = leaderboard(suite, {"a.json": entry, "b.json": other})
    (row,) = board.rows
    assert row.score.seeds == (0, 1, 2, 3) and row.files == ["a.json", "b.json"]
    assert row.score.overall == pytest.approx(leaderboard(suite, {"a.json": entry}).rows[0].score.overall)
    assert row.best[0] <= row.score.overall and not board.warnings
    with pytest.raises(BenchError, match=r"entry b.json: seeds \[0, 1\] also in a.json"):
        leaderboard(suite, {"a.json": entry, "b.json": entry})
    renamed = dataclasses.replace(other, model=entry.model | {"weights": "f" * 64})
    with pytest.raises(BenchError, match=r"entry b.json: model.weights: 'kadv_tiny' has another identity in a.json"):
        leaderboard(suite, {"a.json": entry, "b.json": renamed})
    with pytest.raises(BenchError, match=r"entry b.json: misses the cell"):
        leaderboard(suite, {"a.json": entry, "b.json": dataclasses.replace(other, units=other.units[1:])})
    with pytest.raises(BenchError, match=r"entry b.json: bake_version 0 lights the scenes otherwise"):
        leaderboard(suite, {"a.json": entry, "b.json": dataclasses.replace(other, bake_version=0)})
    monkeypatch.setitem(DIVERGENT_VERSIONS, entry.kadv_version, "a fixed bug")
    with pytest.raises(BenchError, match=r"kadv_version .* gives other figures"):
        leaderboard(suite, {"a.json": entry})
    monkeypatch.undo()
    elsewhere = dataclasses.replace(other, environment=other.environment | {"device": "cuda:0"})
    assert "cuda:0" in leaderboard(suite, {"a.json": entry, "b.json": elsewhere}).warnings[0]


def test_two_labs_entries_merged_give_the_table_of_one_lab_that_ran_both(run, suite, model, tmp_path) -> None:
    lab_a, _ = run
    lab_b = run_suite(suite, model, (2, 3), tmp_path / "b", progress=False)
    both = run_suite(suite, model, (0, 1, 2, 3), tmp_path / "both", progress=False)
    merged = leaderboard(suite, {"a.json": lab_a, "b.json": lab_b})
    assert merged.markdown() == leaderboard(suite, {"both.json": both}).markdown()
    assert math.isfinite(merged.rows[0].score.overall_se) and "kadv_tiny" in merged.markdown()


def test_the_pooled_worst_case_scores_each_model_at_the_others_worst_poses(run, suite, model, tmp_path) -> None:
    entry, _ = run
    # a twin of kadv-tiny whose entry holds kadv-tiny's own poses: scored there, it finds nothing lower
    twin = dataclasses.replace(entry, model=entry.model | {"name": "twin"})
    same = pooled_worst(suite, {"a": entry, "b": twin}, {"kadv_tiny": model, "twin": model})
    own = suite_score(suite, pool_units(suite, [entry]))
    assert same["kadv_tiny"][0] == pytest.approx(own.overall, abs=2 / 768)  # a pixel or two of 24 x 32
    dpt = load_model("kadv_tiny_dpt")
    other = run_suite(suite, dpt, (0, 1), tmp_path, progress=False)
    pooled = pooled_worst(suite, {"a": entry, "b": other}, {"kadv_tiny": model, "kadv_tiny_dpt": dpt})
    assert pooled["kadv_tiny"][0] <= own.overall + 1e-12 and all(
        p <= s + 1e-12 for p, s in zip(pooled["kadv_tiny"][1], own.per_radius)
    )
    board = leaderboard(suite, {"a": entry, "b": other}, pooled)
    assert "pooled worst" in board.markdown() and board.to_dict()["models"][0]["pooled_worst"]["overall"] <= 1
    with pytest.raises(BenchError, match="two models or more"):
        pooled_worst(suite, {"a": entry}, {"kadv_tiny": model})


def test_the_cells_of_one_seed_search_independently(suite, model, tmp_path) -> None:
    # one init view twice: under the seed alone both would search the same design and find the same
    scene = dataclasses.replace(suite.scenes[0], views=(suite.scenes[0].views[0],) * 2)
    twice = dataclasses.replace(suite, scenes=(scene,), protocol=dataclasses.replace(PROTOCOL, min_seeds=1))
    entry = run_suite(twice, model, (0,), tmp_path, progress=False)
    first, second = entry.units
    assert first.delta1_init == second.delta1_init
    assert [c.params for c in first.cells] != [c.params for c in second.cells]
    assert unit_search_seed((0, 0, 0)) == unit_search_seed((0, 0, 0)) != unit_search_seed((0, 0, 1))
