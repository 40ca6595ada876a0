"""How many search seeds and init views a suite's score needs, and whether its budget is deep
enough: one large run of a model (``--seeds`` search seeds at the protocol's budget, and
``--double-seeds`` at twice its passes at every radius; run, or resumed, with
kadv.bench.run_suite under ``--out``), then subsampled.

Per (seeds n, init views a scene v), the 95% half-width of the suite score over seeds, overall
and per radius, averaged over ``--draws`` random subsets of the seeds and of each scene's views;
the cheapest (n, v) whose half-width is at most ``--target`` everywhere. Per radius, how much
doubling the budget lowers the score (on the seeds both runs hold), against the protocol
budget's own half-width at the seeds the protocol asks for.

    python benchmarks/suite_design.py --suite offline-v1 --model kadv_tiny --seeds 0-8 --double-seeds 0-2

Last line: ``suite_design suite= model= seeds= views= half_width= doubling_drop_max= deep_enough=
unit_seconds=``.
"""

from __future__ import annotations

import argparse
import dataclasses
import itertools
import math
from pathlib import Path

import common  # noqa: F401  first: kadv's runtime settings, before torch starts its thread pool

import numpy as np

from kadv.bench import load_suite, pool_units, run_suite, suite_score
from kadv.bench.scores import Z95, Pooled
from kadv.models import load_model


def _seeds(text: str) -> tuple[int, ...]:
    first, _, last = text.partition("-")
    return tuple(range(int(first), int(last or first) + 1))


def _subsampled(suite, pooled: Pooled, seeds: int, views: int, draws: int, rng) -> np.ndarray:
    """The suite score's 95% half-widths over seeds, per radius then overall, averaged over
    ``draws`` subsets of ``seeds`` seeds and ``views`` views a scene."""
    rows = []
    for _ in range(draws):
        kept = np.concatenate(
            [rng.choice(np.flatnonzero(pooled.scene_of == s), views, replace=False) for s in range(len(suite.scenes))]
        )
        columns = rng.choice(len(pooled.seeds), seeds, replace=False)
        subset = Pooled(
            pooled.worst[kept][:, :, columns],
            pooled.init[kept][:, columns],
            pooled.abs_rel[kept][:, :, columns],
            pooled.scene_of[kept],
            tuple(pooled.seeds[c] for c in columns),
        )
        score = suite_score(suite, subset)
        rows.append(Z95 * np.array([*score.per_radius_se, score.overall_se]))
    return np.mean(rows, axis=0)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--suite", default="offline-v1")
    parser.add_argument("--model", default="kadv_tiny")
    parser.add_argument("--seeds", default="0-8", help="first-last search seeds at the protocol's budget")
    parser.add_argument("--double-seeds", default="0-2", help="first-last search seeds at twice the budget")
    parser.add_argument("--set-size", type=int, default=3, help="seeds an entry of the large run holds")
    parser.add_argument("--target", type=float, default=0.02, help="the largest 95%% half-width allowed")
    parser.add_argument("--draws", type=int, default=200)
    parser.add_argument("--out", default="outputs/suite_design")
    parser.add_argument("--scenes", default=None, help="the suite's scene files (default: $KADV_TEST_SCENES)")
    args = parser.parse_args()
    suite, model = load_suite(args.suite), load_model(args.model)
    doubled = dataclasses.replace(
        suite, protocol=dataclasses.replace(suite.protocol, radius_passes=[2 * p for p in suite.protocol.radius_passes])
    )
    folder = Path(args.out) / suite.name / model.name
    runs = {}
    for name, run_on, seeds in (
        ("protocol", suite, _seeds(args.seeds)),
        ("doubled", doubled, _seeds(args.double_seeds)),
    ):
        sets = [seeds[i : i + args.set_size] for i in range(0, len(seeds), args.set_size)]
        entries = []
        for chunk in sets:
            one = dataclasses.replace(run_on, protocol=dataclasses.replace(run_on.protocol, min_seeds=len(chunk)))
            out = folder / name / ("seeds" + "-".join(map(str, chunk)))
            entries.append(run_suite(one, model, chunk, out, root=args.scenes))
        runs[name] = (run_on, entries)
    pooled = pool_units(suite, runs["protocol"][1])
    views_a_scene = min(len(scene.views) for scene in suite.scenes)
    radii = [f"{d:g}°/{m:g} m" for d, m in suite.protocol.radii]
    rng = np.random.default_rng(0)
    print(f"suite {suite.name} ({suite.hash[:12]}), {model.name}: {len(pooled.seeds)} seeds at the protocol's budget\n")
    print("| seeds | views a scene | units | " + " | ".join(radii) + " | overall |")
    print("|---" * (len(radii) + 4) + "|")
    chosen = None
    for n, v in itertools.product(range(2, len(pooled.seeds) + 1), range(1, views_a_scene + 1)):
        halves = _subsampled(suite, pooled, n, v, args.draws, rng)
        units = n * v * len(suite.scenes)
        print(f"| {n} | {v} | {units} | " + " | ".join(f"±{h:.4f}" for h in halves) + " |")
        if halves.max() <= args.target and (chosen is None or units < chosen[2]):
            chosen = (n, v, units, halves.max())
    protocol_score = suite_score(suite, pool_units(suite, runs["protocol"][1][:1]))
    double_suite, double_entries = runs["doubled"]
    common_seeds = set(double_entries[0].seeds)
    same = [e for e in runs["protocol"][1] if set(e.seeds) == common_seeds]
    base = suite_score(suite, pool_units(suite, same or runs["protocol"][1][:1]))
    deep = suite_score(double_suite, pool_units(double_suite, double_entries))
    print("\n| radius | protocol | doubled | drop | protocol's half-width |")
    print("|---|---|---|---|---|")
    drops = []
    for k, name in enumerate([*radii, "overall"]):
        low = [*base.per_radius, base.overall][k]
        high = [*deep.per_radius, deep.overall][k]
        half = Z95 * [*protocol_score.per_radius_se, protocol_score.overall_se][k]
        drops.append((low - high, half))
        print(f"| {name} | {low:.4f} | {high:.4f} | {low - high:+.4f} | ±{half:.4f} |")
    seconds = [c.seconds for e in runs["protocol"][1] for u in e.units for c in u.cells]
    unit_seconds = sum(seconds) / sum(len(e.units) for e in runs["protocol"][1])
    deep_enough = all(drop <= half for drop, half in drops)
    n, v, _, half = chosen if chosen else (math.nan, math.nan, 0, math.nan)
    print(
        f"suite_design suite={suite.name} model={model.name} seeds={n} views={v} half_width={half:.4f} "
        f"doubling_drop_max={max(d for d, _ in drops):.4f} deep_enough={deep_enough} unit_seconds={unit_seconds:.1f}"
    )


if __name__ == "__main__":
    main()
