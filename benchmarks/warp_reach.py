"""How far a gradient attack's views stray from the warp preset's anchor, and what its reach costs.

Whole gradient attacks (kadv-tiny + SSIM, GradientSettings' steps and restarts, Adam at its default
rates) from grey_white_room's file view at 240x320, under ``render=exact``, ``render=warp`` and
``render=warp`` without a reach, in alternating rounds (the machine is noisy): per preset the time
of a call of the differentiable renderer within the whole step (networks, loss, penalty, guard and
validity included), and the refreshes. Without the reach, each warped view's distance from its
anchor: how far the gradient would have to hold (``benchmarks/gradcheck.py`` checks it at the reach).
``--picture`` draws each call's distance from its anchor under both warp presets against the reach.

Run: .venv/bin/python benchmarks/warp_reach.py [--rounds N] [--picture docs/warp_reach.png]
     [--device cpu|cuda|auto] [--backend ...]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import time
from pathlib import Path

from common import device_and_backend, load_bench_scene, render_preset

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from kadv.attack import AttackConfig, GradientSettings, Study, StudySettings, attack, file_init_views
from kadv.io import save_figure
from kadv.losses import LossConfig
from kadv.models import load_model
from kadv.render import DifferentiableRenderer, DiffRenderConfig

HEIGHT, WIDTH = 240, 320
UNBOUNDED = {"anchor_reach_deg": math.inf, "anchor_reach_m": math.inf}


def presets() -> dict[str, DiffRenderConfig]:
    warp = render_preset("warp")
    return {"exact": render_preset("exact"), "warp": warp, "unreached": dataclasses.replace(warp, **UNBOUNDED)}


class Recorder:
    """Wraps :meth:`DifferentiableRenderer.forward` for the run: counts refreshes, and records each
    call's largest distance (degrees, metres) of a view from the anchor it was rendered with (0
    where it rendered a new one) and whether it was warped."""

    def __init__(self) -> None:
        self.refreshes = 0
        self.trace: list[tuple[float, float, bool]] = []
        self._forward = DifferentiableRenderer.forward

    def __enter__(self) -> Recorder:
        recorder, forward = self, self._forward

        def recorded(renderer: DifferentiableRenderer, *args):
            out = forward(renderer, *args)
            recorder.refreshes += out.refreshed
            turned, moved = renderer.anchor_distance(out.world_T_cam)
            recorder.trace.append((math.degrees(float(turned.max())), float(moved.max()), out.warped))
            return out

        DifferentiableRenderer.forward = recorded
        return self

    def __exit__(self, *exc) -> None:
        DifferentiableRenderer.forward = self._forward


def picture(path: Path, traces: dict[str, list[tuple[float, float, bool]]], reach: DiffRenderConfig) -> None:
    """Each call's distance from its anchor, in degrees and in metres, per preset, the reach dashed."""
    figure, axes = plt.subplots(1, 2, figsize=(11, 3.4))
    for name, trace in traces.items():
        degrees, metres, _ = zip(*trace, strict=True)
        label = "render=warp" if name == "warp" else "render=warp without its reach"
        for axis, values in zip(axes, (degrees, metres), strict=True):
            axis.plot(values, marker="o", markersize=3, label=label)
    for axis, bound, unit in zip(
        axes, (reach.anchor_reach_deg, reach.anchor_reach_m), ("degrees", "metres"), strict=True
    ):
        axis.axhline(bound, color="black", linestyle="--", linewidth=1, label="reach (the gradient check's)")
        axis.set_xlabel("call (Adam step)")
        axis.set_ylabel(f"distance from the anchor ({unit})")
    axes[0].legend(fontsize=8)
    figure.suptitle("a gradient attack's views and their anchor (0: a new anchor), grey_white_room, kadv-tiny + SSIM")
    save_figure(path, figure)


def main() -> None:
    parser = argparse.ArgumentParser(description="How far a gradient attack strays from the warp's anchor.")
    parser.add_argument("--rounds", type=int, default=2, help="alternating rounds of the three presets")
    parser.add_argument("--picture", type=Path, default=None, help="a PNG of each call's distance from its anchor")
    device, backend, args = device_and_backend(parser.description, parser)
    if args.rounds < 1:
        parser.exit(2, f"{parser.prog}: error: --rounds must be at least 1, got {args.rounds}\n")
    settings = StudySettings(size=(HEIGHT, WIDTH), backend=backend, loss=LossConfig(kind="ssim"), device=device)
    study = Study.build(load_bench_scene("grey_white_room"), load_model("kadv_tiny"), settings)
    view = file_init_views(study.renderer, settings.penalty.margin)[0]
    config = AttackConfig("gradient", GradientSettings(), budget_passes=None)
    configs = presets()
    milliseconds: dict[str, list[float]] = {name: [] for name in configs}
    refreshes: dict[str, int] = {}
    traces: dict[str, list[tuple[float, float, bool]]] = {}
    print(f"whole gradient attacks, grey_white_room {HEIGHT}x{WIDTH}, kadv-tiny + SSIM, on {device} (ms a call)")
    for round_ in range(args.rounds):
        for name, render in configs.items():
            variant = study.variant(render=render)
            with Recorder() as recorder:
                started = time.perf_counter()
                attack(variant.objective, variant.differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)
                seconds = time.perf_counter() - started
            calls = len(recorder.trace)
            milliseconds[name].append(seconds / calls * 1e3)
            refreshes[name] = recorder.refreshes
            traces[name] = recorder.trace
            print(
                f"  round {round_} {name:<10} {milliseconds[name][-1]:7.0f}  "
                f"({calls} calls, {recorder.refreshes} refreshes)"
            )
    reached = [(degrees, metres) for degrees, metres, warped in traces["unreached"] if warped]
    degrees, metres = zip(*reached, strict=True) if reached else ((0.0,), (0.0,))
    print(
        "\nwithout the reach, a warped view's distance from its anchor: "
        f"median {statistics.median(degrees):.2f} deg / {statistics.median(metres):.3f} m, "
        f"most {max(degrees):.2f} deg / {max(metres):.3f} m over {len(reached)} warped calls"
    )
    if args.picture is not None:
        picture(args.picture, {name: traces[name] for name in ("warp", "unreached")}, configs["warp"])
    median = {name: statistics.median(values) for name, values in milliseconds.items()}
    print(
        f"warp_reach exact_ms={median['exact']:.0f} warp_ms={median['warp']:.0f} "
        f"unreached_ms={median['unreached']:.0f} refreshes={refreshes['warp']} "
        f"unreached_refreshes={refreshes['unreached']} drift_deg_max={max(degrees):.2f} "
        f"drift_m_max={max(metres):.3f} drift_deg_median={statistics.median(degrees):.2f} device={device.type}"
    )


if __name__ == "__main__":
    main()
