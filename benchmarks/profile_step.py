"""Where the time of an attack goes, phase by phase: a black-box evaluation batch (exact render of
EVAL_BATCH nearby views at supersample 2 and one kadv-tiny forward pass) and a gradient step of
kadv-tiny + SSIM (one restart), on grey_white_room at 240x320.

Then the render presets' steps, in one process: PRESET_STEPS small moves rendered forward and
backward through the differentiable renderer under ``render=exact`` (the default) and
``render=warp`` (refreshes included; then its refreshes' steps and the steps between them apart,
medians), against one exact render at supersample 2 and the warp of a moved view with the cast it
needs (forward).

Each phase is a function of kadv wrapped for this run: the device is synchronised before and after
it, so that its time is its own (what the phases leave out is the rest of the step: the optimiser,
the records). Then torch's profiler lists the operators that took the most time in one more
gradient step (device time on CUDA, CPU time on the CPU).

Run: .venv/bin/python benchmarks/profile_step.py [--device cpu|cuda|auto] [--backend auto|open3d|warp]
     [--edge-search auto|compact|every_pair]
"""

from __future__ import annotations

import argparse
import statistics
import time
from collections import defaultdict
from collections.abc import Callable

from common import device_and_backend, load_bench_scene, median_seconds, render_preset

import torch
from torch.profiler import ProfilerActivity, profile

import kadv.attack.objective
import kadv.attack.search
import kadv.attack.space
import kadv.render.differentiable
from kadv.attack import AttackConfig, GradientSettings, Objective, Study, StudySettings, attack, file_init_views
from kadv.geometry import intrinsics_from_fov, perturb_world_T_cam
from kadv.losses import LossConfig
from kadv.models import load_model
from kadv.penalties import distance_to_surface
from kadv.render import DiffRenderConfig, ExactRenderer, render_anchor
from kadv.render.dibr import warp_boxed
from kadv.render.layers import camera_face_normals

HEIGHT, WIDTH = 240, 320
EVAL_BATCH = 8
STEPS = 6
PRESET_STEPS = 12
# (module, attribute, phase): the functions timed, where the step calls them from
PHASES = [
    (kadv.render.differentiable, "render_anchor", "anchor render"),
    (kadv.render.differentiable, "reproject", "warp of the anchor"),
    (kadv.render.differentiable, "find_edge_pairs", "silhouette search"),
    (kadv.render.differentiable, "silhouette_term", "silhouette term"),
    (kadv.attack.space, "step_guard", "step guard"),
    (kadv.attack.search, "view_validity", "view validity"),
    (kadv.attack.objective, "distance_to_surface", "penalty distance"),
]


def wrap_phases(around: Callable[[Callable, str], Callable]) -> Callable[[], None]:
    """Replace the PHASES' functions, and the exact render and the objective's model and loss, by
    ``around(function, phase)``; returns the function that puts them back."""
    targets = [*PHASES, (ExactRenderer, "render", "exact render"), (Objective, "forward", "model, loss, metrics")]
    restore = []
    for owner, name, phase in targets:
        original = getattr(owner, name)
        setattr(owner, name, around(original, phase))
        restore.append((owner, name, original))

    def put_back() -> None:
        for owner, name, original in restore:
            setattr(owner, name, original)

    return put_back


def synchronise(device: torch.device) -> None:
    """Wait for ``device``'s queued work (a GPU's), so that a clock read after it counts it."""
    if device.type == "cuda":
        torch.cuda.synchronize(device)


def timed_into(device: torch.device, seconds: dict[str, float]) -> Callable[[Callable, str], Callable]:
    """A :func:`wrap_phases` wrapper that adds each call's time to ``seconds[phase]``, the device
    synchronised before and after it, so that its time is its own."""

    def timed(fn: Callable, phase: str) -> Callable:
        def run(*args, **kwargs):
            synchronise(device)
            start = time.perf_counter()
            out = fn(*args, **kwargs)
            synchronise(device)
            seconds[phase] += time.perf_counter() - start
            return out

        return run

    return timed


def report(evaluation: dict[str, float], seconds: dict[str, float], total: float, device: torch.device) -> None:
    """Print the phases of the evaluation and of the gradient steps, in milliseconds."""
    print(f"\nblack-box evaluation of {EVAL_BATCH} views at {HEIGHT}x{WIDTH}, s=2, on {device} (ms)")
    for phase, spent in evaluation.items():
        print(f"  {phase:<28} {spent * 1e3:>8.1f}")
    # the attack evaluates its init view and each step's poses: STEPS + 1 passes through the step
    print(f"\ngradient step, kadv-tiny + SSIM, one restart, on {device} (ms per step, {STEPS + 1} passes)")
    for phase, spent in sorted(seconds.items(), key=lambda item: -item[1]):
        print(f"  {phase:<28} {spent / (STEPS + 1) * 1e3:>8.1f}")
    print(f"  {'whole step':<28} {total / (STEPS + 1) * 1e3:>8.1f}")


def tiny_attack(description: str) -> tuple[torch.device, str, argparse.Namespace, Study, object]:
    """The options (``--device --backend --edge-search``) and what a kadv-tiny + SSIM attack on
    grey_white_room's file view needs: the device, the backend, the options, the study, the view; a
    bad option ends the script in one line with exit status 2."""
    parser = argparse.ArgumentParser(description=description)
    parser.add_argument("--edge-search", default="auto", choices=("auto", "compact", "every_pair"))
    device, backend, args = device_and_backend(description, parser)
    settings = StudySettings(
        size=(HEIGHT, WIDTH),
        backend=backend,
        render=DiffRenderConfig(edge_search=args.edge_search),
        loss=LossConfig(kind="ssim"),
        device=device,
    )
    study = Study.build(load_bench_scene("grey_white_room"), load_model("kadv_tiny"), settings)
    view = file_init_views(study.renderer, settings.penalty.margin)[0]
    return device, backend, args, study, view


def preset_steps(study: Study, view, device: torch.device) -> dict[str, float]:
    """Milliseconds of a step through each render preset (its refreshes spread over the steps), of
    the warp preset's refresh steps and steps between refreshes (medians; and its refreshes in
    ``refreshes``), of one exact render at supersample 2, and of a moved view's reprojection with
    its cast."""
    renderer = study.renderer
    K = intrinsics_from_fov(view.fov_x_deg, HEIGHT, WIDTH)
    base = view.world_T_cam.double().reshape(1, 4, 4)
    # small moves along a line, about a centimetre and a few tenths of a degree a step (an Adam run's
    # scale), in the room's free space as a search's steps are (the step guard keeps them there)
    moves = [
        torch.tensor([[0.0, 0.004, 0.002, -0.01, -0.004, -0.006]], dtype=torch.float64) * i for i in range(PRESET_STEPS)
    ]
    path = torch.cat([perturb_world_T_cam(base, move[:, :3], move[:, 3:]) for move in moves])
    clearance = float(distance_to_surface(renderer, path[:, :3, 3]).min())
    if clearance < study.settings.penalty.margin:
        raise SystemExit(f"profile_step: the path of small moves comes within {clearance:.3f} m of a surface")
    weights = torch.linspace(-1.0, 1.0, 4 * HEIGHT * WIDTH, device=device).reshape(1, 4, HEIGHT, WIDTH)
    out = {}
    for name in ("exact", "warp"):
        differentiable = study.variant(render=render_preset(name)).differentiable
        runs: list[list[tuple[bool, float]]] = []  # per run, each step's (refreshed, seconds)

        def steps() -> None:
            differentiable.reset()
            runs.append([])
            for move in moves:
                start = time.perf_counter()
                params = move.to(device).requires_grad_(True)
                rendered = differentiable(params, base, K, HEIGHT, WIDTH)
                (torch.cat([rendered.rgb, rendered.depth], dim=1) * weights).sum().backward()
                synchronise(device)
                runs[-1].append((rendered.refreshed, time.perf_counter() - start))

        out[name] = median_seconds(steps, repeats=3) / PRESET_STEPS * 1e3
    # the warp preset's timed runs (the warm-up's left out), its refreshes apart from the steps between
    timed = [call for run in runs[1:] for call in run]
    for key, refreshed in (("warp refresh", True), ("warp between", False)):
        out[key] = statistics.median(seconds for kind, seconds in timed if kind == refreshed) * 1e3
    out["refreshes"] = sum(kind for kind, _ in runs[-1])
    moved = perturb_world_T_cam(base, moves[3][:, :3], moves[3][:, 3:])
    out["exact render"] = median_seconds(lambda: renderer.render(moved, K, HEIGHT, WIDTH, supersample=2)) * 1e3
    preset = render_preset("warp")
    anchor = render_anchor(renderer, base, K, HEIGHT, WIDTH, preset.layers, preset.guard_band, preset.supersample)
    boxed = anchor.to(device).boxed
    A_T_P = torch.linalg.inv(base) @ moved

    def reprojection() -> None:
        cast = renderer.render(moved, K, HEIGHT, WIDTH, colour=False)
        normals = camera_face_normals(renderer.surfaces, cast.triangle_ids[:, 0], moved).permute(0, 3, 1, 2)
        with torch.no_grad():
            warp_boxed(boxed, cast.depth.to(device), normals.to(device), A_T_P.to(device), K, preset.depth_tolerance)

    out["reprojection"] = median_seconds(reprojection) * 1e3
    print(f"\nrender presets on {device}, grey_white_room {HEIGHT}x{WIDTH} (ms; steps: forward and backward)")
    labels = {
        "exact": "render=exact step",
        "warp": "render=warp step",
        "warp refresh": f"  a refresh ({out['refreshes']} of {PRESET_STEPS})",
        "warp between": "  a step between refreshes",
        "exact render": "exact render, s=2",
        "reprojection": "reprojection of a moved view",
    }
    for key, label in labels.items():
        print(f"  {label:<30} {out[key]:>8.1f}")
    return out


def main() -> None:
    device, backend, args, study, view = tiny_attack("Time an attack's phases and list its costliest operators.")
    renderer, model = study.renderer, study.model

    def gradient(steps: int) -> None:
        config = AttackConfig("gradient", GradientSettings(steps=steps, restarts=1), budget_passes=None)
        attack(study.objective, study.differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)

    generator = torch.Generator().manual_seed(0)
    offsets = 0.05 * (2 * torch.rand(EVAL_BATCH, 6, generator=generator, dtype=torch.float64) - 1)
    poses = perturb_world_T_cam(view.world_T_cam.expand(EVAL_BATCH, 4, 4), offsets[:, :3], offsets[:, 3:])
    K = intrinsics_from_fov(view.fov_x_deg, HEIGHT, WIDTH)

    def evaluate() -> None:
        with torch.no_grad():
            rgb = renderer.render(poses, K, HEIGHT, WIDTH, supersample=2).rgb
            synchronise(device)
            start = time.perf_counter()
            model(rgb)
            synchronise(device)
            seconds["model forward"] += time.perf_counter() - start

    seconds: dict[str, float] = defaultdict(float)
    gradient(2)  # warm-up: kernels compiled, tables uploaded
    evaluate()
    seconds.clear()
    put_back = wrap_phases(timed_into(device, seconds))
    try:
        evaluate()
        evaluation = dict(seconds)
        seconds.clear()
        started = time.perf_counter()
        gradient(STEPS)
        total = time.perf_counter() - started
    finally:
        put_back()
    report(evaluation, seconds, total, device)
    activities = [ProfilerActivity.CPU] + ([ProfilerActivity.CUDA] if device.type == "cuda" else [])
    with profile(activities=activities) as profiler:
        gradient(1)
    sort = "self_cuda_time_total" if device.type == "cuda" else "self_cpu_time_total"
    print(f"\noperators of one gradient run (2 passes), by {sort}")
    print(profiler.key_averages().table(sort_by=sort, row_limit=15, max_name_column_width=36))
    presets = preset_steps(study, view, device)
    step = total / (STEPS + 1)
    render = evaluation.get("exact render", 0.0)
    print(
        f"profile_step default_ms={presets['exact']:.0f} warp_ms={presets['warp']:.0f} "
        f"exact_ms={presets['exact render']:.0f} reproject_ms={presets['reprojection']:.1f} "
        f"warp_refresh_ms={presets['warp refresh']:.0f} warp_between_ms={presets['warp between']:.0f} "
        f"refreshes={presets['refreshes']} "
        f"step_ms={step * 1e3:.0f} eval_render_ms={render * 1e3:.0f} "
        f"anchor_ms={seconds['anchor render'] / (STEPS + 1) * 1e3:.0f} "
        f"silhouette_ms={seconds['silhouette search'] / (STEPS + 1) * 1e3:.0f} device={device.type} backend={backend} "
        f"edge_search={args.edge_search}"
    )


if __name__ == "__main__":
    main()
