"""Time of one gradient attack step, broken into its parts, for two configurations at 240x320 on
grey_white_room: the Depth Anything V2 Small architecture (random weights) with the perceptual loss
(random VGG-16 weights), and kadv-tiny with SSIM.

Every part is timed in this one run. overhead = (step - networks) / networks for the first
configuration, networks = model forward+backward + loss forward+backward.

Run: .venv/bin/python benchmarks/attack_step.py
"""
from __future__ import annotations

import tempfile

import torch
from common import load_bench_scene, median_seconds
from transformers import DepthAnythingConfig, DepthAnythingForDepthEstimation, Dinov2Config

from kadv.attack import AttackConfig, Objective, PenaltyConfig, attack, file_init_views
from kadv.geometry import intrinsics_from_fov
from kadv.losses import VGG16_TAPS, PerceptualLoss, depth_loss, vgg16_features
from kadv.models import DepthModel, load_model
from kadv.penalties import distance_to_surface, shortcut_penalty, step_guard, view_validity
from kadv.render import DiffRenderConfig, DifferentiableRenderer, ExactRenderer

HEIGHT, WIDTH = 240, 320
STEPS = 3


def depth_anything_v2_small(folder: str) -> DepthModel:
    """The Depth Anything V2 Small architecture with random weights, loaded as a user's checkpoint is."""
    torch.manual_seed(0)
    dino = Dinov2Config(hidden_size=384, num_hidden_layers=12, num_attention_heads=6, intermediate_size=1536,
                        image_size=518, patch_size=14, out_indices=[3, 6, 9, 12], apply_layernorm=True,
                        reshape_hidden_states=False)
    network = DepthAnythingForDepthEstimation(DepthAnythingConfig(
        backbone_config=dino, reassemble_hidden_size=384, patch_size=14, neck_hidden_sizes=[48, 96, 192, 384],
        fusion_hidden_size=64, head_hidden_size=32, depth_estimation_type="relative"))
    network.save_pretrained(folder)
    return load_model(folder)


def random_perceptual_loss() -> PerceptualLoss:
    torch.manual_seed(0)
    return PerceptualLoss(vgg16_features(), VGG16_TAPS)


def measure(label: str, objective: Objective, differentiable: DifferentiableRenderer, view) -> dict[str, float]:
    renderer = objective.renderer
    K = intrinsics_from_fov(view.fov_x_deg, HEIGHT, WIDTH)
    base = view.world_T_cam[None]
    params = torch.zeros(1, 6, dtype=torch.float64)
    penalty = objective.penalty
    config = AttackConfig(steps=STEPS, restarts=1)
    attack(objective, differentiable, [view], HEIGHT, WIDTH, AttackConfig(steps=1, restarts=1), 0,
           progress=False)  # warm-up: first calls allocate and pick kernels
    run = attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)
    parts = {"step": run.views[0].budget.seconds / (STEPS + 1)}

    def render_forward():
        return differentiable(params.clone().requires_grad_(True), base, K, HEIGHT, WIDTH)

    def render_forward_backward():
        out = render_forward()
        (out.rgb.sum() + out.depth.sum()).backward()

    parts["exact render (s=2, ring)"] = median_seconds(
        lambda: renderer.render(base, K, HEIGHT + 2, WIDTH + 2, supersample=differentiable.config.supersample), 3)
    parts["render fwd (exact+warp+silhouettes)"] = median_seconds(render_forward, 3)
    parts["render fwd+bwd"] = median_seconds(render_forward_backward, 3)
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

    centre = base[:, :3, 3].clone()

    def penalty_guard():
        c = centre.clone().requires_grad_(True)
        shortcut_penalty(distance_to_surface(renderer, c), penalty.d_th).sum().backward()
        step_guard(renderer, centre, centre + 0.01, penalty.margin)

    parts["model fwd+bwd"] = median_seconds(model_step, 3)
    parts["loss fwd+bwd"] = median_seconds(loss_step, 3)
    parts["penalty + guard"] = median_seconds(penalty_guard, 3)
    parts["view validity"] = median_seconds(
        lambda: view_validity(renderer, base, K, HEIGHT, WIDTH, **penalty.validity_options()), 3)
    accounted = parts["render fwd+bwd"] + parts["model fwd+bwd"] + parts["loss fwd+bwd"] + parts["penalty + guard"] \
        + parts["view validity"]
    parts["optimiser, metrics, records, rest"] = parts["step"] - accounted
    print(f"\n{label} at {HEIGHT}x{WIDTH}, one restart (ms)")
    for name, seconds in parts.items():
        print(f"  {name:<40} {seconds * 1e3:>9.1f}")
    return parts


def main() -> None:
    scene = load_bench_scene("grey_white_room")
    renderer = ExactRenderer(scene)
    penalty = PenaltyConfig()
    view = file_init_views(renderer, penalty.margin)[0]
    results = {}
    with tempfile.TemporaryDirectory() as folder:
        configurations = {
            "Depth Anything V2 Small (random) + perceptual (random VGG-16)":
                (depth_anything_v2_small(folder), random_perceptual_loss()),
            "kadv-tiny + SSIM": (load_model("kadv_tiny"), depth_loss("ssim")),
        }
        for label, (model, loss) in configurations.items():
            objective = Objective(model, loss, renderer, penalty)
            results[label] = measure(label, objective, DifferentiableRenderer(renderer, DiffRenderConfig()), view)
    overheads = []
    for parts in results.values():
        networks = parts["model fwd+bwd"] + parts["loss fwd+bwd"]
        overheads.append(((parts["step"] - networks) / networks, parts["render fwd+bwd"], networks))
    (overhead, render, networks), (overhead_tiny, _, _) = overheads
    print(f"\nkadv-tiny + SSIM: overhead_tiny={overhead_tiny:.2f}")
    print(f"attack_step overhead={overhead:.2f} render_ms={render * 1e3:.0f} networks_ms={networks * 1e3:.0f}")


if __name__ == "__main__":
    main()
