"""Gradient attack against random search and CMA-ES at an equal time budget per init view.

kadv-tiny with SSIM on the box room and the three ../shared scenes, from the file camera plus 2
sampled init views each. Random search and CMA-ES keep sampling until they have used the seconds
the gradient run took from that init view. A method's gain is the mean over init views of
(best adversarial L_depth - init L_depth); gain_vs_X is the gradient's gain over X's.

Run: .venv/bin/python benchmarks/attack_vs_baselines.py
"""
from __future__ import annotations

import dataclasses
import statistics

from common import REAL_SCENES, load_bench_scene

from kadv.attack import (
    AttackConfig,
    InitViewConfig,
    Objective,
    PenaltyConfig,
    attack,
    file_init_views,
    sample_init_views,
)
from kadv.losses import depth_loss
from kadv.models import load_model
from kadv.render import DiffRenderConfig, DifferentiableRenderer, ExactRenderer

HEIGHT, WIDTH = 96, 128
GRADIENT = AttackConfig(steps=20, restarts=3)


def gain(view) -> float:
    return (view.top[0].l_depth if view.top else view.init_record.l_depth) - view.init_record.l_depth


def main() -> None:
    model, loss, penalty = load_model("kadv_tiny"), depth_loss("ssim"), PenaltyConfig()
    gains: dict[str, list[float]] = {"gradient": [], "random": [], "cma": []}
    print(f"{'scene':<20} {'init view':<10} {'method':<9} {'init L':>7} {'best L':>7} {'gain':>7} {'evals':>6} {'s':>6}")
    for name in ("box_room", *REAL_SCENES):
        renderer = ExactRenderer(load_bench_scene(name))
        objective = Objective(model, loss, renderer, penalty)
        differentiable = DifferentiableRenderer(renderer, DiffRenderConfig())
        views = file_init_views(renderer, penalty.margin)[:1]
        views += sample_init_views(renderer, model, 2, 0, InitViewConfig(), penalty, HEIGHT, WIDTH)
        for view in views:
            run = lambda config: attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0,  # noqa: E731
                                        progress=False).views[0]
            results = {"gradient": run(GRADIENT)}
            seconds = results["gradient"].budget.seconds
            for method in ("random", "cma"):
                results[method] = run(dataclasses.replace(GRADIENT, method=method, budget_seconds=seconds,
                                                          budget_evaluations=10**6))
            for method, result in results.items():
                gains[method].append(gain(result))
                print(f"{name:<20} {view.name:<10} {method:<9} {result.init_record.l_depth:>7.4f} "
                      f"{result.init_record.l_depth + gain(result):>7.4f} {gain(result):>7.4f} "
                      f"{result.budget.forward:>6} {result.budget.seconds:>6.1f}", flush=True)
    mean = {method: statistics.mean(values) for method, values in gains.items()}
    print(f"\nmean gain: gradient {mean['gradient']:.4f}, random {mean['random']:.4f}, cma {mean['cma']:.4f}")
    print(f"attack_vs_baselines gain_vs_random={mean['gradient'] / mean['random']:.2f} "
          f"gain_vs_cma={mean['gradient'] / mean['cma']:.2f}")


if __name__ == "__main__":
    main()
