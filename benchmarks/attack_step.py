"""Time of one gradient attack step, broken into its parts, for two configurations at 240x320 on
grey_white_room: the Depth Anything V2 Small architecture (random weights) with the perceptual loss
(random VGG-16 weights), and kadv-tiny with SSIM.

Every part is timed in this one run. A step is the time between the ends of two consecutive steps
of a gradient run (differentiable render, objective, records, backward, update, step guard; on
CUDA a replay of the captured step, :class:`~kadv.attack.capture.StepGraph`), the device's queued
work included (a step on a GPU waits for nothing, so the end of each waits for it). The
networks are the model's and the loss's forward passes and one backward pass through both, as a step
runs them, timed as one call (as two separate forward+backward pairs they take about 3% less: a
step's graph holds both networks' activations at once, and that memory comes as fresh pages). The
machine's speed drifts by up to a third within minutes, so the two are measured side by side: the
end of each step times one networks call, and every step is compared with the mean of the
calls just before and just after it (the second step, which captures, is one of them: the median
leaves it aside). overhead = the median over REPEATS x STEPS steps of
(step - networks) / networks, for the first configuration; overhead_tiny the same for the second.
The same ratio for runs whose render is replaced by one fixed output shows what the attack's own
bookkeeping (objective terms, penalty, guard, records, optimiser) adds beside the render.
The table's other parts are the fastest of several tries (noise only ever adds time). Then the time
per restart-step for batches of B = 1, 2, 4, 8 restarts (the fastest of two steps). Last, what a
black-box search is paced by: evaluations per second (evals_per_s) of an exact render (supersample 2)
of EVAL_BATCH nearby views plus one forward pass of kadv-tiny on them, the fastest of three batches.

Run: .venv/bin/python benchmarks/attack_step.py [--device cpu|cuda|auto] [--backend auto|open3d|warp]
     [--edge-search auto|compact|every_pair] [--cuda-graphs on|off]
"""

from __future__ import annotations

import argparse
import dataclasses
import math
import statistics
import tempfile
import time
from collections.abc import Callable

from common import device_and_backend, fastest_seconds, load_bench_scene, timings

import torch
from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

from kadv.attack import AttackConfig, GradientSettings, Objective, Study, StudySettings, attack, file_init_views
from kadv.attack.capture import StepGraph
from kadv.geometry import intrinsics_from_fov, perturb_world_T_cam, pixel_rays
from kadv.losses import LossConfig, vgg16_features
from kadv.models import DepthModel, load_model
from kadv.penalties import distance_to_surface, shortcut_penalty, step_guard, view_validity
from kadv.render import DifferentiableRenderer, DiffRenderConfig, DiffRenderOutput, ExactRenderer

HEIGHT, WIDTH = 240, 320
STEPS = 5
REPEATS = 5
BATCHES = (1, 2, 4, 8)
EVAL_BATCH = 8


def depth_anything_v2_small(folder: str) -> DepthModel:
    """The Depth Anything V2 Small architecture with random weights, loaded as a user's checkpoint is."""
    torch.manual_seed(0)
    dino = Dinov2Config(
        hidden_size=384,
        num_hidden_layers=12,
        num_attention_heads=6,
        intermediate_size=1536,
        image_size=518,
        patch_size=14,
        out_indices=[3, 6, 9, 12],
        apply_layernorm=True,
        reshape_hidden_states=False,
    )
    network = DepthAnythingForDepthEstimation(
        DepthAnythingConfig(
            backbone_config=dino,
            reassemble_hidden_size=384,
            patch_size=14,
            neck_hidden_sizes=[48, 96, 192, 384],
            fusion_hidden_size=64,
            head_hidden_size=32,
            depth_estimation_type="relative",
        )
    )
    network.save_pretrained(folder)
    return load_model(folder)


def random_vgg16_weights(folder: str) -> str:
    """A torchvision-layout VGG-16 checkpoint of random weights (seed 0) in ``folder``: the
    perceptual loss's cost without its ImageNet download."""
    torch.manual_seed(0)
    path = f"{folder}/vgg16-random.pth"
    torch.save({f"features.{k}": v for k, v in vgg16_features().state_dict().items()}, path)
    return path


def synchronised(fn: Callable[[], object], device: torch.device) -> Callable[[], None]:
    """``fn`` followed by a wait for the device, so that its kernels are inside the timing."""

    def run() -> None:
        fn()
        if device.type == "cuda":
            torch.cuda.synchronize(device)

    return run


def step_seconds(
    objective: Objective,
    differentiable: DifferentiableRenderer,
    view,
    steps: int,
    restarts: int,
    between: Callable[[], float] | None = None,
) -> tuple[list[float], list[float]]:
    """Seconds of each step but the first of a gradient run of ``steps`` steps of ``restarts`` batched
    restarts from ``view`` (the times between the ends of consecutive steps, less what the timing
    spent), and the seconds ``between()`` reports when called at the end of each step."""
    updates, resumes, inside = [], [], []
    run_step = StepGraph.__call__

    def timed_step(graph: StepGraph):
        outputs = run_step(graph)
        # a step queues its work on a GPU without waiting for it: the step ends when that work has run
        if torch.cuda.is_initialized():
            torch.cuda.synchronize()
        updates.append(time.perf_counter())
        if between is not None:
            inside.append(between())
        resumes.append(time.perf_counter())
        return outputs

    StepGraph.__call__ = timed_step  # each step of the run (all but its last evaluation) is a call
    try:
        config = AttackConfig("gradient", GradientSettings(steps=steps, restarts=restarts), budget_passes=None)
        attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)
    finally:
        StepGraph.__call__ = run_step
    return [update - resume for resume, update in zip(resumes, updates[1:])], inside


class FixedRender:
    """Stands in for the differentiable renderer with one render's output at every pose (its values,
    and a zero-valued dependence on the pose for the gradient), so that a run with it times
    everything a step does but the render."""

    def __init__(self, differentiable: DifferentiableRenderer, output: DiffRenderOutput) -> None:
        self.renderer, self.config, self.output = differentiable.renderer, differentiable.config, output
        self.device = differentiable.device

    def reset(self) -> None:
        """Nothing to forget (the attack calls it before each init view)."""

    def validate_next(self) -> None:
        """Nothing to validate: every call gives the one render's output (the attack calls it before
        the views a run ends on)."""

    def __call__(
        self, params: torch.Tensor, base: torch.Tensor, K: torch.Tensor, height: int, width: int
    ) -> DiffRenderOutput:
        world_T_cam = perturb_world_T_cam(
            torch.as_tensor(base, dtype=torch.float64).reshape(-1, 4, 4), params[:, :3].double(), params[:, 3:].double()
        )
        zero = (0 * params.sum()).float()
        return dataclasses.replace(
            self.output,
            rgb=self.output.rgb.detach() + zero,
            depth=self.output.depth.detach() + zero,
            world_T_cam=world_T_cam,
        )


def paired_overheads(
    objective: Objective, differentiable, view, networks: Callable[[], float], rounds: int
) -> tuple[list[float], list[float], list[float]]:
    """Steps of ``rounds`` gradient runs of 1 + STEPS steps with a ``networks()`` call timed after every
    step: the steps' and the calls' seconds, and each step's (step - networks) /
    networks against the mean of the calls just before and just after it."""
    steps, calls, own = [], [], []
    for _ in range(rounds):
        run_steps, run_calls = step_seconds(objective, differentiable, view, 1 + STEPS, 1, networks)
        own += [
            step / (0.5 * (before + after)) - 1.0 for step, before, after in zip(run_steps, run_calls, run_calls[1:])
        ]
        steps, calls = steps + run_steps, calls + run_calls
    return steps, calls, own


def kernel_share(objective: Objective, differentiable: DifferentiableRenderer, view) -> float:
    """The share of a CUDA gradient run's wall time (STEPS steps of one restart, after a warm-up
    run) that the GPU spends in kernels, from torch's profiler: 1 means the device never waits
    for the host."""
    config = AttackConfig("gradient", GradientSettings(steps=STEPS, restarts=1), budget_passes=None)
    attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)
    activities = [torch.profiler.ProfilerActivity.CPU, torch.profiler.ProfilerActivity.CUDA]
    with torch.profiler.profile(activities=activities) as profile:
        started = time.perf_counter()
        attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)
        torch.cuda.synchronize()
        wall = time.perf_counter() - started
    kernels = sum(event.self_device_time_total for event in profile.key_averages()) * 1e-6
    return kernels / wall


def per_restart_step(objective: Objective, differentiable: DifferentiableRenderer, view) -> dict[int, float]:
    """Seconds per restart per step of a gradient run, for batches of B restarts."""
    return {batch: min(step_seconds(objective, differentiable, view, 3, batch)[0]) / batch for batch in BATCHES}


def measure(
    label: str, objective: Objective, differentiable: DifferentiableRenderer, view
) -> tuple[dict[str, float], float, float]:
    renderer, device = objective.renderer, objective.device
    K = intrinsics_from_fov(view.fov_x_deg, HEIGHT, WIDTH)
    base = view.world_T_cam[None]
    params = torch.zeros(1, 6, dtype=torch.float64)
    penalty = objective.penalty

    def render_forward():
        return differentiable(params.clone().requires_grad_(True), base, K, HEIGHT, WIDTH)

    def render_forward_backward():
        out = render_forward()
        (out.rgb.sum() + out.depth.sum()).backward()

    out = render_forward()
    rgb = out.rgb.detach().float().requires_grad_(True)

    def model_step():
        objective.model(rgb).sum().backward()

    prediction = objective.model(rgb).detach()
    mask = out.mask
    gt = out.depth.detach()

    def loss_step():
        a = gt.clone().requires_grad_(True)
        b = prediction.double().clone().requires_grad_(True)
        objective.l_depth(a, b, mask).sum().backward()

    def networks_step():
        # as a step runs them: both forward passes, then one backward through both
        objective.l_depth(gt.clone().requires_grad_(True), objective.model(rgb), mask).sum().backward()

    def timed(fn: Callable[[], None]) -> float:
        return timings(synchronised(fn, device), 1, warmup=0)[0]

    step_seconds(objective, differentiable, view, 2, 1)  # warm-up: first calls allocate and pick kernels
    steps, networks, own = paired_overheads(objective, differentiable, view, lambda: timed(networks_step), REPEATS)
    # the same with the render's output fixed: what the attack's own bookkeeping adds to the networks
    _, _, own_fixed = paired_overheads(
        objective, FixedRender(differentiable, out), view, lambda: timed(networks_step), 1
    )
    parts = {
        "step": min(steps),
        "networks": min(networks),
        "model fwd+bwd": fastest_seconds(synchronised(model_step, device), REPEATS),
        "loss fwd+bwd": fastest_seconds(synchronised(loss_step, device), REPEATS),
    }
    parts["exact render (s=2, ring)"] = fastest_seconds(
        lambda: renderer.render(base, K, HEIGHT + 2, WIDTH + 2, supersample=differentiable.config.supersample), 3
    )
    parts["render fwd (exact+warp+silhouettes)"] = fastest_seconds(synchronised(render_forward, device), 3)
    parts["render fwd+bwd"] = fastest_seconds(synchronised(render_forward_backward, device), 3)
    centre = base[:, :3, 3].clone()

    def penalty_guard():
        c = centre.clone().requires_grad_(True)
        shortcut_penalty(distance_to_surface(renderer, c), penalty.d_th).sum().backward()
        step_guard(renderer, centre, centre + 0.01, penalty.margin)

    parts["penalty + guard"] = fastest_seconds(penalty_guard, 3)
    parts["view validity (on the step's render)"] = fastest_seconds(
        lambda: view_validity(renderer, base, K, HEIGHT, WIDTH, render=out.exact, **penalty.validity_options()), 3
    )
    accounted = (
        parts["render fwd+bwd"]
        + parts["networks"]
        + parts["penalty + guard"]
        + parts["view validity (on the step's render)"]
    )
    parts["optimiser, metrics, records, rest"] = parts["step"] - accounted
    overhead = statistics.median(own)
    print(f"\n{label} at {HEIGHT}x{WIDTH} on {device}, one restart (ms)")
    for name, seconds in parts.items():
        print(f"  {name:<40} {seconds * 1e3:>9.1f}")
    print(
        f"  (step - networks) / networks, median of {len(own)} steps against the calls beside them: "
        f"{overhead:.3f} (fastest step against fastest call: "
        f"{parts['step'] / parts['networks'] - 1.0:.3f})"
    )
    print(
        f"  the same with the render's output fixed (median of {len(own_fixed)} steps): "
        f"{statistics.median(own_fixed):.3f}"
    )
    share = kernel_share(objective, differentiable, view) if device.type == "cuda" else math.nan
    print(f"  the GPU's kernels, share of a run's wall time: {share:.2f}")
    scaling = per_restart_step(objective, differentiable, view)
    print(
        "  per restart-step with B restarts batched: "
        + ", ".join(f"B={b} {seconds * 1e3:.0f} ms" for b, seconds in scaling.items())
    )
    return parts, overhead, share


def evaluations_per_second(
    renderer: ExactRenderer, model: DepthModel, view, device: torch.device
) -> tuple[float, float]:
    """Black-box evaluations per second: exact renders of EVAL_BATCH views near ``view`` and one
    forward pass of ``model`` on them, the fastest of three batches; and the seconds of the batch's
    ray casts alone (pixel centres and sub-pixel rays, without shading), the fastest of three: the
    floor under a batch that keeps its exact depth and colour."""
    generator = torch.Generator().manual_seed(0)
    offsets = 0.05 * (2 * torch.rand(EVAL_BATCH, 6, generator=generator, dtype=torch.float64) - 1)
    poses = perturb_world_T_cam(view.world_T_cam.expand(EVAL_BATCH, 4, 4), offsets[:, :3], offsets[:, 3:])
    K = intrinsics_from_fov(view.fov_x_deg, HEIGHT, WIDTH)

    def evaluate() -> None:
        rgb = renderer.render(poses, K, HEIGHT, WIDTH, supersample=2).rgb.to(device)
        with torch.no_grad():
            model(rgb)

    rays = [pixel_rays(poses, K, HEIGHT, WIDTH, s, device=renderer.device) for s in (1, 2)]

    def cast() -> None:
        for origins, directions in rays:
            renderer.cast(origins.reshape(-1, 3), directions.reshape(-1, 3))

    return EVAL_BATCH / fastest_seconds(synchronised(evaluate, device), 3), fastest_seconds(
        synchronised(cast, renderer.device), 3
    )


def main() -> None:
    parser = argparse.ArgumentParser(description="Time one gradient attack step, part by part.")
    parser.add_argument("--edge-search", default="auto", choices=("auto", "compact", "every_pair"))
    parser.add_argument("--cuda-graphs", default="on", choices=("on", "off"), help="capture the step on CUDA")
    device, backend, args = device_and_backend(parser.description, parser)
    render_config = DiffRenderConfig(edge_search=args.edge_search, cuda_graphs=args.cuda_graphs == "on")
    settings = StudySettings(size=(HEIGHT, WIDTH), backend=backend, render=render_config, device=device)
    study = Study.build(load_bench_scene("grey_white_room"), load_model("kadv_tiny"), settings)
    renderer = study.renderer
    view = file_init_views(renderer, settings.penalty.margin)[0]
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        configurations = {
            "Depth Anything V2 Small (random) + perceptual (random VGG-16)": (
                depth_anything_v2_small(folder),
                LossConfig(kind="perceptual", vgg_weights=random_vgg16_weights(folder)),
            ),
            "kadv-tiny + SSIM": (study.model, LossConfig(kind="ssim")),
        }
        for label, (model, loss) in configurations.items():
            variant = study.variant(model=model, loss=loss)
            results[label] = measure(label, variant.objective, variant.differentiable, view)
    (parts, overhead, share), (_, overhead_tiny, share_tiny) = results.values()
    render, networks = parts["render fwd+bwd"], parts["networks"]
    evals_per_s, cast = evaluations_per_second(renderer, load_model("kadv_tiny").to(device), view, device)
    batch_ms = EVAL_BATCH / evals_per_s * 1e3
    print(f"\nblack-box batch of {EVAL_BATCH} views, s=2: {batch_ms:.0f} ms, its casts alone {cast * 1e3:.0f} ms")
    print(
        f"\nattack_step overhead={overhead:.2f} render_ms={render * 1e3:.0f} networks_ms={networks * 1e3:.0f} "
        f"overhead_tiny={overhead_tiny:.2f} evals_per_s={evals_per_s:.1f} eval_cast_ms={cast * 1e3:.0f} "
        f"kernel_share={share:.2f} kernel_share_tiny={share_tiny:.2f} "
        f"device={device.type} backend={backend} edge_search={args.edge_search} cuda_graphs={args.cuda_graphs}"
    )


if __name__ == "__main__":
    main()
