"""delta1 (after scale-and-shift alignment) of the embedded models on held-out generated rooms and
on real scenes, which no training run ever sees (the three shared scenes, or ``--scenes``); the
metric kadv-tiny-metric also unaligned (``none``: its depth in metres as predicted).

- Generated: 200 views of furnished rooms and 200 of box rooms from seed 7 (``HELD_OUT_SEED``, which
  ``kadv-train-tiny`` refuses to train or validate on), at 240 x 320; with ``--lighting baked`` every
  room is lit by its baked global illumination (``TRAINING_BAKE``), else by random direct shading.
- Real scenes (``--scenes``: shared scenes' names or paths to any scene file, comma-separated; the
  three shared scenes by default): each scene's file camera plus 20 valid views drawn as the attack draws init-view
  candidates (``sample_valid_views``, unranked: seed 0, then seeds 1, 2, ... while fewer than 20
  are found, as in the Japanese classroom, whose 220 m ground puts most candidates outside), at
  180 x 320, under ``--lighting`` (default: the renderer's); the mean is over all their views (63
  for the shared scenes).

Run: .venv/bin/python benchmarks/tiny_accuracy.py [--models kadv_tiny kadv_tiny_dpt kadv_tiny_metric]
[--kadv-tiny FILE] [--kadv-tiny-dpt DIR] [--kadv-tiny-metric FILE] [--lighting direct|baked]
[--scenes NAME_OR_PATH,...] (other weights than the shipped ones, e.g. a training run's; other scenes, e.g.
rooms of your own).
"""

from __future__ import annotations

import argparse
import statistics
from pathlib import Path

from common import REAL_SCENES, default_lighting, scene_file, timings

import torch

from kadv.attack import InitViewConfig, sample_valid_views
from kadv.datasets import HELD_OUT_SEED, RoomMix, ViewBatch, render_procedural_views
from kadv.geometry import intrinsics_from_fov
from kadv.losses import depth_metrics
from kadv.models import load_model
from kadv.models.tiny import TINY_METRIC_WEIGHTS, TINY_WEIGHTS
from kadv.models.tiny_dpt import TINY_DPT_DIR
from kadv.penalties import PenaltyConfig
from kadv.render import ExactRenderer, Shading
from kadv.scenes import load_scene

SAMPLED_VIEWS = 20
SAMPLING_SEEDS = 10
HEIGHT, WIDTH = 180, 320


def real_scene_views(path: Path, lighting: str) -> ViewBatch:
    """The file camera and ``SAMPLED_VIEWS`` sampled valid views of the scene at ``path``, lit by ``lighting``."""
    scene = load_scene(path)
    renderer = ExactRenderer(scene, Shading(lighting=lighting))
    config = InitViewConfig()
    camera = scene.cameras[0]
    sampled = torch.zeros(0, 4, 4, dtype=torch.float64)
    for seed in range(SAMPLING_SEEDS):
        if len(sampled) == SAMPLED_VIEWS:
            break
        more = sample_valid_views(renderer, SAMPLED_VIEWS - len(sampled), seed, config, PenaltyConfig(), HEIGHT, WIDTH)
        sampled = torch.cat([sampled, more])
    if len(sampled) < SAMPLED_VIEWS:
        raise SystemExit(f"{path}: {len(sampled)} valid views from {SAMPLING_SEEDS} seeds, not {SAMPLED_VIEWS}")
    outputs = [
        renderer.render(camera.world_T_cam, camera.intrinsics(HEIGHT, WIDTH), HEIGHT, WIDTH, supersample=2),
        renderer.render(sampled, intrinsics_from_fov(config.fov_x_deg, HEIGHT, WIDTH), HEIGHT, WIDTH, supersample=2),
    ]
    return ViewBatch(*(torch.cat([getattr(out, key) for out in outputs]) for key in ("rgb", "depth", "mask")))


def _label(name: str, path: Path) -> str:
    """A scene's column name: its shared name, else its file's folder (scene.xml) or stem."""
    return name if name in REAL_SCENES else (path.parent.name if path.stem == "scene" else path.stem)


def per_view_delta1(model: torch.nn.Module, views: ViewBatch, alignment: str = "scale_shift") -> torch.Tensor:
    with torch.no_grad():
        return torch.cat(
            [
                depth_metrics(
                    model(views.rgb[i : i + 16]),
                    views.depth[i : i + 16],
                    views.mask[i : i + 16],
                    model.output_kind,
                    alignment=alignment,
                )["delta1"]
                for i in range(0, len(views.rgb), 16)
            ]
        )


def weights_megabytes(path: Path) -> float:
    return sum(f.stat().st_size for f in ([path] if path.is_file() else path.iterdir())) / 1e6


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--kadv-tiny", default=None, help="kadv-tiny weights file (default: the shipped one)")
    parser.add_argument("--kadv-tiny-dpt", default=None, help="kadv-tiny-dpt directory (default: the shipped one)")
    parser.add_argument("--kadv-tiny-metric", default=None, help="kadv-tiny-metric weights file (default: shipped)")
    embedded = ["kadv_tiny", "kadv_tiny_dpt", "kadv_tiny_metric"]
    parser.add_argument("--models", nargs="+", default=embedded, choices=embedded)
    parser.add_argument("--lighting", default=default_lighting(), choices=["direct", "baked"])
    parser.add_argument(
        "--scenes", default=",".join(REAL_SCENES), help="comma-separated shared scenes' names or scene files' paths"
    )
    args = parser.parse_args()
    paths = {name: scene_file(name) for name in args.scenes.split(",")}
    for name, path in paths.items():
        if not path.is_file():
            parser.error(f"--scenes: {name!r} is neither a shared scene's name nor a scene file")
    weights = {
        "kadv_tiny": args.kadv_tiny,
        "kadv_tiny_dpt": args.kadv_tiny_dpt,
        "kadv_tiny_metric": args.kadv_tiny_metric,
    }
    models = {name: load_model(name, weights=weights[name]) for name in args.models}
    baked_share = 1.0 if args.lighting == "baked" else 0.0
    held_out = {
        label: render_procedural_views(
            200, HELD_OUT_SEED, 240, 320, RoomMix(furnished_share=share, baked_share=baked_share)
        )
        for label, share in (("furnished", 1.0), ("box rooms", 0.0))
    }
    shared = {_label(name, path): real_scene_views(path, args.lighting) for name, path in paths.items()}
    print(f"lighting: {args.lighting}")
    columns = [*held_out, *(f"{name} file" for name in shared), *(f"{name} sampled" for name in shared), "real mean"]
    print("| model | " + " | ".join(columns) + " |")
    print("|---" * (len(columns) + 1) + "|")
    results = {}
    rows = [(name, "scale_shift") for name in models] + [
        (n, "none") for n, m in models.items() if m.output_kind == "depth"
    ]
    for name, alignment in rows:
        model = models[name]
        label = name if alignment == "scale_shift" else f"{name}_none"
        generated = {key: float(per_view_delta1(model, views, alignment).mean()) for key, views in held_out.items()}
        scores = {scene: per_view_delta1(model, views, alignment) for scene, views in shared.items()}
        real = float(torch.cat(list(scores.values())).mean())
        cells = [
            *generated.values(),
            *(float(s[0]) for s in scores.values()),
            *(float(s[1:].mean()) for s in scores.values()),
            real,
        ]
        print(f"| {label} ({alignment}) | " + " | ".join(f"{value:.3f}" for value in cells) + " |")
        results[label] = (real, generated["furnished"])
    print()
    print("| model | weights | forward at 240x320 (median of 20, batch 1) |")
    print("|---|---|---|")
    shipped = {
        "kadv_tiny": args.kadv_tiny or TINY_WEIGHTS,
        "kadv_tiny_dpt": args.kadv_tiny_dpt or TINY_DPT_DIR,
        "kadv_tiny_metric": args.kadv_tiny_metric or TINY_METRIC_WEIGHTS,
    }
    image = torch.rand(1, 3, 240, 320)
    for label, model in models.items():
        with torch.no_grad():
            milliseconds = 1000 * statistics.median(timings(lambda model=model: model(image), repeats=20, warmup=3))
        print(f"| {label} | {weights_megabytes(Path(shipped[label])):.1f} MB | {milliseconds:.1f} ms |")
    print(
        "tiny_accuracy "
        + " ".join(
            [f"{label}_real={real:.3f}" for label, (real, _) in results.items()]
            + [f"{label}_procedural={procedural:.3f}" for label, (_, procedural) in results.items()]
        )
    )


if __name__ == "__main__":
    main()
