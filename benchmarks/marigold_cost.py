"""What one Marigold pass costs: a randomly initialised network of Marigold's size (Stable Diffusion
2's UNet with 8 input channels, its VAE; the weights do not change the cost), one 240x320 image,
one denoising step, at the default processing resolution (768) and at smaller ones: one forward
without a gradient (a black-box search's pass), and one forward with the backward to the image (a
gradient step's), with the peak resident memory of each.

Last line: ``marigold_cost unet_params= vae_params= forward_768= backward_768= peak_gib_768= ...``
(seconds, the fastest of ``--repeats``; ``backward_R`` is forward and backward together).

Run: .venv/bin/python benchmarks/marigold_cost.py [--resolutions 768,384] [--repeats 1]
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import common  # first: kadv's runtime settings, before torch starts its thread pool

import torch

from kadv.models import MarigoldDepthModel, MarigoldSettings

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # the tests' pipeline builder
from tests.models.tiny_marigold import FULL_UNET, FULL_VAE, marigold_pipeline

SIZE = (240, 320)


def peak_gib(reset: bool = False) -> float:
    """The process's peak resident memory in GiB since the last reset (Linux's VmHWM)."""
    if reset:
        Path("/proc/self/clear_refs").write_text("5")
    line = next(line for line in Path("/proc/self/status").read_text().splitlines() if line.startswith("VmHWM"))
    return int(line.split()[1]) / 2**20


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--resolutions", default="768,384", help="processing resolutions, comma-separated")
    parser.add_argument("--repeats", type=int, default=1, help="timed calls of each (the fastest counts)")
    args = parser.parse_args()
    resolutions = common.integer_list(parser, "--resolutions", args.resolutions, least=8)
    pipeline = marigold_pipeline(FULL_UNET, FULL_VAE, resolution=resolutions[0])
    count = lambda module: sum(parameter.numel() for parameter in module.parameters())
    fields = {"unet_params": count(pipeline.unet), "vae_params": count(pipeline.vae)}
    rgb = torch.rand(1, 3, *SIZE, generator=torch.Generator().manual_seed(0))
    print(
        f"image {SIZE[0]}x{SIZE[1]}, 1 step, {torch.get_num_threads()} threads; "
        f"UNet {fields['unet_params']:,} parameters"
    )
    for resolution in resolutions:
        model = MarigoldDepthModel(
            pipeline, "marigold (random)", MarigoldSettings(steps=1, processing_resolution=resolution)
        )

        def forward() -> None:
            with torch.no_grad():
                model(rgb)

        def backward() -> None:
            image = rgb.clone().requires_grad_(True)
            model(image).mean().backward()

        peak_gib(reset=True)
        fields[f"forward_{resolution}"] = round(common.fastest_seconds(forward, args.repeats, warmup=0), 1)
        fields[f"backward_{resolution}"] = round(common.fastest_seconds(backward, args.repeats, warmup=0), 1)
        fields[f"peak_gib_{resolution}"] = round(peak_gib(), 1)
    print("\n| processing resolution | forward | forward and backward | peak memory |\n|---|---|---|---|")
    for resolution in resolutions:
        print(
            f"| {resolution} | {fields[f'forward_{resolution}']} s | {fields[f'backward_{resolution}']} s "
            f"| {fields[f'peak_gib_{resolution}']} GiB |"
        )
    print(
        "marigold_cost "
        + " ".join(f"{key}={value}" for key, value in fields.items())
        + f" threads={torch.get_num_threads()}"
    )


if __name__ == "__main__":
    main()
