"""Every search method with every loss on one anytime scale: the incumbent (best valid view by the
pair's own loss) against wall seconds, scored on the same measures for all: its delta1 drop (the
failure users report), AbsRel rise and L_depth gain (SSIM) over the init view.

Setup (each an option, so a user reruns it for their own model, losses, size, scenes and device):
kadv-tiny at 96x128 under the commands' default lighting on the box room and the three ../shared
scenes, from the file camera plus --sampled sampled init views each (drawn with --seed, which also
seeds the searches). Every method+loss pair gets --seconds per init view. Writes
search_anytime.png (mean delta1 drop and L_depth gain against seconds, 95% bootstrap bands over
init views), search_anytime.md (the table at 10/25/50/100% of the budget, and the screening rate at
each hybrid screen scale) and search_anytime.json (every curve) to --out. A method written
``hybrid@0.5`` is hybrid with attack.hybrid.screen_scale=0.5.

The last line names the pair with the largest delta1 drop at the full budget and its ratios: on
delta1 drop against the strongest baseline (random, cma, nevergrad) with the study's SSIM loss, and
against the strongest baseline with the pair's own loss; on L_depth gain against the strongest
SSIM baseline.

Run: .venv/bin/python benchmarks/search_anytime.py [--seconds 10] [--losses ssim,absrel,delta1] [--seed 0]
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

from common import REAL_SCENES, default_lighting, load_bench_scene

import matplotlib.pyplot as plt
import numpy as np

from kadv.attack import (
    AttackConfig,
    GradientSettings,
    HybridSettings,
    InitViewConfig,
    Objective,
    PenaltyConfig,
    SearchContext,
    Study,
    StudySettings,
    attack,
    best_so_far,
    file_init_views,
    get_method,
    sample_init_views,
)
from kadv.device import resolve_device
from kadv.losses import LossConfig
from kadv.models import load_model
from kadv.render import Shading

BASELINES = ("random", "cma", "nevergrad")
FRACTIONS = (0.1, 0.25, 0.5, 1.0)
GRID = 101


def step_curve(points: list[tuple[float, float]], grid: np.ndarray) -> np.ndarray:
    """A best-so-far curve given at its rises (x, value) read on ``grid`` (the value held since)."""
    xs = np.array([p[0] for p in points])
    values = np.array([p[1] for p in points])
    index = np.searchsorted(xs, grid, side="right") - 1
    return values[np.clip(index, 0, None)]


def bootstrap_band(samples: np.ndarray, rng: np.random.Generator, draws: int = 1000) -> tuple[np.ndarray, np.ndarray]:
    """95% bootstrap band (2.5%, 97.5%) of the mean over the first axis of (views, grid)."""
    picks = rng.integers(0, len(samples), size=(draws, len(samples)))
    means = samples[picks].mean(axis=1)
    return np.percentile(means, 2.5, axis=0), np.percentile(means, 97.5, axis=0)


def method_settings(label: str) -> tuple[str, object | None]:
    """``hybrid@0.5`` -> ("hybrid", HybridSettings(screen_scale=0.5)); any other label names a method
    (the gradient's steps unbounded, so that the seconds end it)."""
    name, _, scale = label.partition("@")
    get_method(name)
    if name == "gradient":
        return name, GradientSettings(steps=2**31)
    if not scale:
        return name, None
    if name != "hybrid":
        raise ValueError(f"--methods: only hybrid takes @<screen scale>, got {label!r}")
    return name, HybridSettings(screen_scale=float(scale))


def screening_rate(objective: Objective, differentiable, view, height: int, width: int, scale: float) -> float:
    """Views per second that hybrid's screening evaluates at ``scale`` (batches of 8, after one
    warm-up; the first call also warms the forward passes up for the timed searches)."""
    context = SearchContext(
        objective, differentiable, view, height, width, AttackConfig(budget_passes=None, budget_seconds=60.0)
    )
    params = context.space.sample(np.random.default_rng(0).random((8, 6)))
    context.evaluate(1, params, scale=scale)
    started = time.perf_counter()
    for _ in range(3):
        context.evaluate(1, params, scale=scale)
    return 24 / (time.perf_counter() - started)


def run(args: argparse.Namespace) -> dict:
    device = resolve_device(args.device)
    model, penalty = load_model(args.model), PenaltyConfig()
    losses = args.losses.split(",")
    methods = args.methods.split(",")
    curves: dict = {"budget_seconds": args.seconds, "views": [], "screening": {}}
    for name in args.scenes.split(","):
        settings = StudySettings(shading=Shading(lighting=args.lighting), penalty=penalty, device=device)
        study = Study.build(load_bench_scene(name), model, settings)
        renderer, differentiable = study.renderer, study.differentiable
        objectives = {loss: study.variant(loss=LossConfig(kind=loss)).objective for loss in losses}
        views = file_init_views(renderer, penalty.margin)[:1]
        views += sample_init_views(
            renderer, model, args.sampled, args.seed, InitViewConfig(), penalty, args.height, args.width
        )
        if not curves["screening"]:
            first = next(iter(objectives.values()))
            curves["screening"] = {
                str(scale): screening_rate(first, differentiable, views[0], args.height, args.width, scale)
                for scale in sorted({1.0} | {float(m.partition("@")[2]) for m in methods if "@" in m}, reverse=True)
            }
            print("screening views/s: " + ", ".join(f"scale {k}: {v:.1f}" for k, v in curves["screening"].items()))
            warm_up = AttackConfig("gradient", GradientSettings(steps=1), budget_passes=None)
            attack(first, differentiable, views[:1], args.height, args.width, warm_up, args.seed, progress=False)
        for view in views:
            entry = {"scene": name, "view": view.name, "pairs": {}}
            for loss, objective in objectives.items():
                for label in methods:
                    method, settings = method_settings(label)
                    config = AttackConfig(method, settings, budget_passes=None, budget_seconds=args.seconds)
                    if method == "gradient":
                        config = AttackConfig(
                            method,
                            get_method(method).settings(steps=2**31),
                            budget_passes=None,
                            budget_seconds=args.seconds,
                        )
                    result = attack(
                        objective, differentiable, [view], args.height, args.width, config, args.seed, progress=False
                    ).views[0]
                    init = result.init_record
                    curve = best_so_far(result.records)
                    entry["pairs"][f"{label}+{loss}"] = {
                        "init": [init.l_depth, init.delta1, init.abs_rel],
                        "curve": curve,
                        "passes": result.budget.passes,
                        "uninformative_chosen": sum(r.verdict == "uninformative" for r in result.top),
                    }
                    best = curve[-1]
                    print(
                        f"{name:<20} {view.name:<9} {label + '+' + loss:<22} delta1 {init.delta1:.3f} -> {best[3]:.3f} "
                        f"AbsRel {init.abs_rel:.3f} -> {best[4]:.3f} L_depth {init.l_depth:.4f} -> {best[2]:.4f} "
                        f"{result.budget.passes:>5} model passes",
                        flush=True,
                    )
            curves["views"].append(entry)
    return curves


# per measure: its index in a curve point and in "init", and its sign (a drop counts init - value)
MEASURES = {"delta1 drop": (3, 1, -1.0), "AbsRel rise": (4, 2, 1.0), "L_depth gain": (2, 0, 1.0)}


def measure_curves(curves: dict, pair: str, measure: str, seconds: np.ndarray) -> np.ndarray:
    """(init views, grid) of one measure of one pair's incumbent against seconds."""
    point, initial, sign = MEASURES[measure]
    rows = []
    for view in curves["views"]:
        entry = view["pairs"][pair]
        rows.append(step_curve([(c[1], sign * (c[point] - entry["init"][initial])) for c in entry["curve"]], seconds))
    return np.array(rows)


LOSS_STYLES = {"delta1": "-", "absrel": "--", "ssim": ":", "perceptual": "-."}


def final_measures(curves: dict) -> dict[str, dict[str, float]]:
    """Each pair's mean of every measure at the full budget."""
    seconds = np.linspace(0.0, curves["budget_seconds"], GRID)
    pairs = list(curves["views"][0]["pairs"])
    return {p: {m: float(measure_curves(curves, p, m, seconds)[:, -1].mean()) for m in MEASURES} for p in pairs}


def ratios(final: dict[str, dict[str, float]], default: str) -> dict[str, float]:
    """``default``'s delta1 drop against the strongest SSIM baseline and the strongest baseline with
    its own loss, and its L_depth gain against the strongest SSIM baseline."""
    loss = default.split("+")[1]
    baselines = [p for p in final if p.split("+")[0] in BASELINES]
    ssim = [p for p in baselines if p.endswith("+ssim")]
    same = [p for p in baselines if p.endswith(f"+{loss}")]
    return {
        "delta1_drop_vs_best_baseline": final[default]["delta1 drop"] / max(final[p]["delta1 drop"] for p in ssim),
        "delta1_drop_vs_same_loss_baseline": final[default]["delta1 drop"] / max(final[p]["delta1 drop"] for p in same),
        "gain_vs_best_baseline": final[default]["L_depth gain"] / max(final[p]["L_depth gain"] for p in ssim),
    }


def plot(curves: dict, path: Path, banded: list[str]) -> None:
    """delta1 drop and L_depth gain against seconds for every pair: a colour per method, a line
    style per loss; 95% bootstrap bands for the ``banded`` pairs."""
    seconds = np.linspace(0.0, curves["budget_seconds"], GRID)
    pairs = list(curves["views"][0]["pairs"])
    methods = sorted({p.split("+")[0] for p in pairs})
    rng = np.random.default_rng(0)
    figure, axes = plt.subplots(1, 2, figsize=(13, 5))
    for pair in pairs:
        method, loss = pair.split("+")
        colour = plt.get_cmap("tab10")(methods.index(method))
        for axis, measure in zip(axes, ("delta1 drop", "L_depth gain")):
            samples = measure_curves(curves, pair, measure, seconds)
            axis.plot(seconds, samples.mean(axis=0), LOSS_STYLES.get(loss, "-"), color=colour, label=pair, lw=1.3)
            if pair in banded:
                axis.fill_between(seconds, *bootstrap_band(samples, rng), color=colour, alpha=0.12)
    for axis, measure in zip(axes, ("delta1 drop", "L_depth gain")):
        axis.set_xlabel("seconds per init view")
        axis.set_ylabel(f"mean {measure} of the incumbent")
    axes[0].legend(fontsize=6, ncol=3)
    figure.suptitle(
        f"Anytime search, {len(curves['views'])} init views; line style: loss (solid delta1, dashed absrel, "
        f"dotted ssim); bands: 95% bootstrap of {', '.join(banded)}",
        fontsize=9,
    )
    figure.tight_layout()
    figure.savefig(path, dpi=90)
    plt.close(figure)


def summarise(curves: dict, out: Path) -> str:
    budget = curves["budget_seconds"]
    pairs = list(curves["views"][0]["pairs"])
    seconds = np.linspace(0.0, budget, GRID)
    final = final_measures(curves)
    default = max(pairs, key=lambda p: final[p]["delta1 drop"])
    ssim = [p for p in pairs if p.split("+")[0] in BASELINES and p.endswith("+ssim")]
    plot(curves, out / "search_anytime.png", [default, max(ssim, key=lambda p: final[p]["delta1 drop"])])
    columns = [round(f * (GRID - 1)) for f in FRACTIONS]
    lines = [
        "| method+loss | "
        + " | ".join(f"delta1 drop {f:.0%}" for f in FRACTIONS)
        + " | AbsRel rise | L_depth gain | model passes |",
        "|---" * (4 + len(FRACTIONS)) + "|",
    ]
    for pair in sorted(pairs, key=lambda p: -final[p]["delta1 drop"]):
        drop = measure_curves(curves, pair, "delta1 drop", seconds).mean(axis=0)
        views = np.mean([v["pairs"][pair]["passes"] for v in curves["views"]])
        lines.append(
            f"| {pair} | "
            + " | ".join(f"{drop[c]:.3f}" for c in columns)
            + f" | {final[pair]['AbsRel rise']:.3f} | {final[pair]['L_depth gain']:.4f} | {views:.0f} |"
        )
    rates = ", ".join(f"scale {k}: {v:.1f} views/s" for k, v in curves["screening"].items())
    uninformative = sum(p["uninformative_chosen"] for v in curves["views"] for p in v["pairs"].values())
    table = "\n".join(lines) + "\n"
    (out / "search_anytime.md").write_text(
        f"Budget {budget:.1f} s per init view, {len(curves['views'])} init views. Screening: {rates}. "
        f"Uninformative views chosen: {uninformative}.\n\n{table}"
    )
    print(table)
    measured = " ".join(f"{k}={v:.2f}" for k, v in ratios(final, default).items())
    return f"search_anytime default={default} {measured} uninformative_chosen={uninformative}"


def across_seeds(runs: list[dict], out: Path) -> str:
    """The pairs every run holds, their delta1 drop at the full budget per run, and the leader's
    ratios with their range over the runs (seeds)."""
    finals = [final_measures(curves) for curves in runs]
    pairs = [p for p in finals[0] if all(p in f for f in finals)]
    mean = {p: float(np.mean([f[p]["delta1 drop"] for f in finals])) for p in pairs}
    lines = ["| method+loss | mean delta1 drop | min | max |", "|---|---|---|---|"]
    for pair in sorted(pairs, key=lambda p: -mean[p]):
        drops = [f[pair]["delta1 drop"] for f in finals]
        lines.append(f"| {pair} | {mean[pair]:.3f} | {min(drops):.3f} | {max(drops):.3f} |")
    table = "\n".join(lines) + "\n"
    (out / "search_anytime_seeds.md").write_text(
        f"{len(runs)} runs (seeds), delta1 drop at the full budget.\n\n{table}"
    )
    print(table)
    default = max(pairs, key=lambda p: mean[p])
    per_seed = [ratios({p: f[p] for p in pairs}, default) for f in finals]
    parts = []
    for key in per_seed[0]:
        values = [r[key] for r in per_seed]
        parts.append(f"{key}={np.mean(values):.2f} {key}_min={min(values):.2f} {key}_max={max(values):.2f}")
    return f"search_anytime seeds={len(runs)} default={default} " + " ".join(parts)


def main() -> None:
    parser = argparse.ArgumentParser(description="Anytime comparison of kadv's search methods and losses.")
    parser.add_argument("--model", default="kadv_tiny")
    parser.add_argument("--losses", default="ssim,absrel,delta1")
    parser.add_argument("--height", type=int, default=96)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--scenes", default=",".join(("box_room", *REAL_SCENES)))
    parser.add_argument("--sampled", type=int, default=1, help="sampled init views per scene (beside the file camera)")
    parser.add_argument("--seconds", type=float, default=10.0, help="the budget per init view and pair")
    parser.add_argument("--methods", default="halving,gradient,random,cma,nevergrad,hybrid,hybrid@0.5")
    parser.add_argument("--lighting", default=default_lighting(), choices=["direct", "baked"])
    parser.add_argument("--seed", type=int, default=0, help="seeds the sampled init views and the searches")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default="search_anytime_out")
    parser.add_argument(
        "--from-json",
        help="summarise earlier runs' search_anytime.json instead of running; several (comma-separated, "
        "e.g. one per seed) also give each ratio's range over them",
    )
    args = parser.parse_args()
    try:
        for label in args.methods.split(","):
            method_settings(label)
        for loss in args.losses.split(","):
            LossConfig(kind=loss).loss()
        if not set(BASELINES) & {m.partition("@")[0] for m in args.methods.split(",")}:
            raise ValueError(f"--methods must include one of {', '.join(BASELINES)} to compare against")
        if "ssim" not in args.losses.split(","):
            raise ValueError("--losses must include ssim, the study's loss the ratios compare against")
        resolve_device(args.device)
    except ValueError as error:
        print(f"search_anytime: error: {error}", file=sys.stderr)
        sys.exit(2)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.from_json and "," in args.from_json:
        runs = [json.loads(Path(p).read_text()) for p in args.from_json.split(",")]
        for index, curves in enumerate(runs):
            (out / f"run{index}").mkdir(exist_ok=True)
            print(summarise(curves, out / f"run{index}"))
        print(across_seeds(runs, out))
        return
    curves = json.loads(Path(args.from_json).read_text()) if args.from_json else run(args)
    (out / "search_anytime.json").write_text(json.dumps(curves))
    print(summarise(curves, out))


if __name__ == "__main__":
    main()
