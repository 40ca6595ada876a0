"""Whether a suite's score holds under any seed: entries of each model under disjoint seed sets
(run, or resumed, with kadv.bench.run_suite under ``--out``), then per entry the 95% interval of
the suite score over seeds at each radius, whether the entries of a model agree (any two within
1.96 x sqrt(2) x their pooled standard error, overall and at each radius), the paired verdict
between the first two models under each seed set, and what each entry cost.

    python benchmarks/suite_score.py --suite offline-v1 --models kadv_tiny,kadv_tiny_dpt \
        --seed-sets 0,1,2:3,4,5:6,7,8 --out outputs/suite_score

Last line: ``suite_score suite= half_width_max= agree= verdicts= minutes_max=``.
"""

from __future__ import annotations

import argparse
import itertools
import math
from pathlib import Path

import common  # noqa: F401  first: kadv's runtime settings, before torch starts its thread pool

from kadv.bench import leaderboard, load_suite, paired_difference, pool_units, run_suite, suite_score
from kadv.bench.scores import Z95
from kadv.models import load_model


def _seed_sets(text: str) -> list[tuple[int, ...]]:
    return [tuple(int(s) for s in part.split(",")) for part in text.split(":")]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--suite", default="offline-v1")
    parser.add_argument("--models", default="kadv_tiny,kadv_tiny_dpt")
    parser.add_argument("--seed-sets", default="0,1,2:3,4,5:6,7,8")
    parser.add_argument("--out", default="outputs/suite_score")
    parser.add_argument("--scenes", default=None, help="the suite's scene files (default: $KADV_TEST_SCENES)")
    args = parser.parse_args()
    suite = load_suite(args.suite)
    seed_sets = _seed_sets(args.seed_sets)
    entries: dict[str, list] = {}
    for name in args.models.split(","):
        model = load_model(name)
        for seeds in seed_sets:
            out = Path(args.out) / suite.name / name / ("seeds" + "-".join(map(str, seeds)))
            entries.setdefault(name, []).append(run_suite(suite, model, seeds, out, root=args.scenes))
    radii = [f"{d:g}°/{m:g} m" for d, m in suite.protocol.radii]
    print(f"suite {suite.name} ({suite.hash[:12]}), {len(suite.cells)} cells, seed sets {args.seed_sets}\n")
    print("| model | seeds | " + " | ".join(radii) + " | overall | over scenes | search minutes (sum over units) |")
    print("|---" * (len(radii) + 5) + "|")
    half_max, minutes_max = 0.0, 0.0
    for name, runs in entries.items():
        for entry in runs:
            score = suite_score(suite, pool_units(suite, [entry]))
            halves = [Z95 * se for se in [*score.per_radius_se, score.overall_se]]
            half_max = max(half_max, *halves)
            minutes = sum(c.seconds for u in entry.units for c in u.cells) / 60
            minutes_max = max(minutes_max, minutes)
            cells = " | ".join(f"{m:.3f} ± {h:.3f}" for m, h in zip(score.per_radius, halves))
            lo, hi = score.scenes_interval
            print(
                f"| {name} | {','.join(map(str, entry.seeds))} | {cells} | {score.overall:.3f} ± {halves[-1]:.3f} "
                f"| {lo:.3f}-{hi:.3f} | {minutes:.1f} |"
            )
    agree = True
    print()
    for name, runs in entries.items():
        for a, b in itertools.combinations(runs, 2):
            sa, sb = (suite_score(suite, pool_units(suite, [e])) for e in (a, b))
            pairs = [(sa.overall, sb.overall, sa.overall_se, sb.overall_se, "overall")]
            pairs += [
                (ma, mb, ea, eb, radius)
                for ma, mb, ea, eb, radius in zip(
                    sa.per_radius, sb.per_radius, sa.per_radius_se, sb.per_radius_se, radii
                )
            ]
            for ma, mb, ea, eb, where in pairs:
                bound = Z95 * math.sqrt(2) * math.sqrt((ea**2 + eb**2) / 2)
                ok = abs(ma - mb) <= bound
                agree &= ok
                print(f"{name}: seeds {a.seeds} against {b.seeds}, {where}: {ma - mb:+.4f} (bound {bound:.4f}) {ok}")
    verdicts = []
    names = list(entries)
    if len(names) >= 2:
        for k in range(len(seed_sets)):
            first, second = (pool_units(suite, [entries[n][k]]) for n in names[:2])
            mean, se, _ = paired_difference(first, second)
            verdict = ">" if mean > Z95 * se else "<" if mean < -Z95 * se else "~"
            verdicts.append(verdict)
            print(f"{names[0]} - {names[1]}, seeds {seed_sets[k]}: {mean:+.4f} ± {Z95 * se:.4f} ({verdict})")
        print(leaderboard(suite, {f"{n}/{k}": e for n, runs in entries.items() for k, e in enumerate(runs)}).markdown())
    opposite = {">", "<"} <= set(verdicts)
    print(
        f"suite_score suite={suite.name} half_width_max={half_max:.4f} agree={agree} "
        f"verdicts={''.join(verdicts) or '-'} opposite={opposite} minutes_max={minutes_max:.1f}"
    )


if __name__ == "__main__":
    main()
