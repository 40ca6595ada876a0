"""Every search method on one anytime scale: the best valid L_depth found so far (and that view's
delta1) against wall seconds and against model forward passes, from the same init views.

Setup (each an option, so a user reruns it for their own model, loss, size, scenes and device):
kadv-tiny with SSIM at 96x128 on the box room and the three ../shared scenes, from the file camera
plus 2 sampled init views each. The budget per init view is the seconds that --gradient-steps steps
of the gradient attack with 3 restarts take from the first init view; every method then runs under
that seconds budget (the gradient with no step limit). A method's gain at time t is the mean over
init views of (best valid L_depth by t - init L_depth); its delta1 drop is the mean of (init
delta1 - delta1 of that view). Writes search_anytime.png (mean gain against seconds and against
forward passes, 95% bootstrap bands over init views), search_anytime.md (gain and delta1 drop at
10/25/50/100% of the budget) and search_anytime.json (every curve) to --out.

The last line names the method that leads at the full budget on both measures (else the one with
the largest delta1 drop, the failure users report) and its ratios against the strongest of
random, cma and nevergrad on each measure.

Run: .venv/bin/python benchmarks/search_anytime.py [--gradient-steps 100] [--methods ...] [--device cpu]
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np
from common import REAL_SCENES, load_bench_scene

from kadv.attack import (
    AttackConfig,
    GradientSettings,
    InitViewConfig,
    Objective,
    PenaltyConfig,
    attack,
    best_so_far,
    file_init_views,
    get_method,
    sample_init_views,
)
from kadv.device import resolve_device
from kadv.losses import depth_loss
from kadv.models import load_model
from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer

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


def run(args: argparse.Namespace) -> dict:
    device = resolve_device(args.device)
    model, loss, penalty = load_model(args.model), depth_loss(args.loss), PenaltyConfig()
    curves: dict = {"budget_seconds": None, "views": []}
    for name in args.scenes.split(","):
        renderer = ExactRenderer(load_bench_scene(name))
        objective = Objective(model, loss, renderer, penalty, device=device)
        differentiable = DifferentiableRenderer(renderer, DiffRenderConfig(), device)
        views = file_init_views(renderer, penalty.margin)[:1]
        views += sample_init_views(renderer, model, args.sampled, 0, InitViewConfig(), penalty, args.height, args.width)
        for view in views:

            def search(config: AttackConfig):
                return attack(
                    objective, differentiable, [view], args.height, args.width, config, 0, progress=False
                ).views[0]

            if curves["budget_seconds"] is None:
                timed = search(
                    AttackConfig(
                        "gradient", GradientSettings(steps=args.gradient_steps, restarts=3), budget_evaluations=None
                    )
                )
                curves["budget_seconds"] = timed.budget.seconds
                print(
                    f"budget: {args.gradient_steps} gradient steps x 3 restarts took {timed.budget.seconds:.1f} s",
                    flush=True,
                )
            entry = {"scene": name, "view": view.name, "methods": {}}
            for method in args.methods.split(","):
                settings = GradientSettings(steps=2**31) if method == "gradient" else None
                result = search(
                    AttackConfig(method, settings, budget_evaluations=None, budget_seconds=curves["budget_seconds"])
                )
                init = result.init_record
                entry["methods"][method] = {
                    "init_l_depth": init.l_depth,
                    "init_delta1": init.delta1,
                    "curve": best_so_far(result.records),
                    "evaluations": result.budget.forward,
                }
                best = entry["methods"][method]["curve"][-1]
                print(
                    f"{name:<20} {view.name:<9} {method:<10} init {init.l_depth:.4f} best {best[2]:.4f} "
                    f"(delta1 {init.delta1:.3f} -> {best[3]:.3f}) {result.budget.forward:>5} views",
                    flush=True,
                )
            curves["views"].append(entry)
    return curves


def summarise(curves: dict, out: Path) -> str:
    budget = curves["budget_seconds"]
    methods = list(curves["views"][0]["methods"])
    seconds = np.linspace(0.0, budget, GRID)
    most = max(m["evaluations"] for v in curves["views"] for m in v["methods"].values())
    evaluations = np.linspace(1, most, GRID)
    rng = np.random.default_rng(0)
    figure, axes = plt.subplots(1, 2, figsize=(11, 4))
    gain, drop = {}, {}
    for method in methods:
        by_time, by_count, drops = [], [], []
        for view in curves["views"]:
            entry = view["methods"][method]
            curve = entry["curve"]
            by_time.append(step_curve([(c[1], c[2] - entry["init_l_depth"]) for c in curve], seconds))
            by_count.append(step_curve([(c[0], c[2] - entry["init_l_depth"]) for c in curve], evaluations))
            drops.append(step_curve([(c[1], entry["init_delta1"] - c[3]) for c in curve], seconds))
        for axis, x, samples in ((axes[0], seconds, np.array(by_time)), (axes[1], evaluations, np.array(by_count))):
            (line,) = axis.plot(x, samples.mean(axis=0), label=method)
            axis.fill_between(x, *bootstrap_band(samples, rng), color=line.get_color(), alpha=0.2)
        gain[method], drop[method] = np.array(by_time).mean(axis=0), np.array(drops).mean(axis=0)
    axes[0].set_xlabel("seconds per init view")
    axes[1].set_xlabel("model forward passes per init view")
    for axis in axes:
        axis.set_ylabel("mean L_depth gain (best valid view so far)")
        axis.legend(fontsize=8)
    figure.suptitle(f"Anytime search, {len(curves['views'])} init views, 95% bootstrap bands")
    figure.tight_layout()
    figure.savefig(out / "search_anytime.png", dpi=90)
    plt.close(figure)
    columns = [round(f * (GRID - 1)) for f in FRACTIONS]
    lines = [
        "| method | "
        + " | ".join(f"gain {f:.0%}" for f in FRACTIONS)
        + " | "
        + " | ".join(f"delta1 drop {f:.0%}" for f in FRACTIONS)
        + " |",
        "|---" * (1 + 2 * len(FRACTIONS)) + "|",
    ]
    for method in methods:
        lines.append(
            f"| {method} | "
            + " | ".join(f"{gain[method][c]:.4f}" for c in columns)
            + " | "
            + " | ".join(f"{drop[method][c]:.3f}" for c in columns)
            + " |"
        )
    table = "\n".join(lines) + "\n"
    (out / "search_anytime.md").write_text(f"Budget {budget:.1f} s per init view.\n\n{table}")
    final = {m: (gain[m][-1], drop[m][-1]) for m in methods}
    leaders = [m for m in methods if all(final[m][0] >= final[o][0] and final[m][1] >= final[o][1] for o in methods)]
    default = leaders[0] if leaders else max(methods, key=lambda m: final[m][1])
    baselines = [m for m in BASELINES if m in methods]
    best_gain = max(final[m][0] for m in baselines)
    best_drop = max(final[m][1] for m in baselines)
    print(table)
    return (
        f"search_anytime default={default} gain_vs_best_baseline={final[default][0] / best_gain:.2f} "
        f"delta1_drop_vs_best_baseline={final[default][1] / best_drop:.2f}"
    )


def main() -> None:
    parser = argparse.ArgumentParser(description="Anytime comparison of kadv's search methods.")
    parser.add_argument("--model", default="kadv_tiny")
    parser.add_argument("--loss", default="ssim")
    parser.add_argument("--height", type=int, default=96)
    parser.add_argument("--width", type=int, default=128)
    parser.add_argument("--scenes", default=",".join(("box_room", *REAL_SCENES)))
    parser.add_argument("--sampled", type=int, default=2, help="sampled init views per scene (beside the file camera)")
    parser.add_argument(
        "--gradient-steps", type=int, default=100, help="the budget: this many gradient steps x 3 restarts"
    )
    parser.add_argument("--methods", default="gradient,random,cma,nevergrad,hybrid")
    parser.add_argument("--device", default="cpu")
    parser.add_argument("--out", default="search_anytime_out")
    parser.add_argument("--from-json", help="summarise an earlier run's search_anytime.json instead of running")
    args = parser.parse_args()
    try:
        for method in args.methods.split(","):
            get_method(method)
        if not set(BASELINES) & set(args.methods.split(",")):
            raise ValueError(f"--methods must include one of {', '.join(BASELINES)} to compare against")
        resolve_device(args.device)
    except ValueError as error:
        print(f"search_anytime: error: {error}", file=sys.stderr)
        sys.exit(2)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    curves = json.loads(Path(args.from_json).read_text()) if args.from_json else run(args)
    (out / "search_anytime.json").write_text(json.dumps(curves))
    print(summarise(curves, out))


if __name__ == "__main__":
    main()
