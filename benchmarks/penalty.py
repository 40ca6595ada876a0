"""Median times of distance_to_surface (+ gradient) for 1 and 16 centres and of view_validity, grey_white_room.

Run: .venv/bin/python benchmarks/penalty.py
"""

from __future__ import annotations

from common import median_seconds, scenes_root

import numpy as np
import torch

from kadv.penalties import distance_to_surface, step_guard, view_validity
from kadv.render import ExactRenderer
from kadv.scenes import load_scene


def main() -> None:
    scene = load_scene(scenes_root() / "grey_white_room" / "scene.xml")
    renderer = ExactRenderer(scene)
    camera = scene.cameras[0]
    lo, hi = scene.bounds
    rng = np.random.default_rng(0)
    summary = {}
    for count in (1, 16):
        centres = torch.tensor(rng.uniform(lo, hi, size=(count, 3)), requires_grad=True)

        def distance_with_grad() -> None:
            distance_to_surface(renderer, centres).sum().backward()

        summary[f"distance_grad_{count}_ms"] = median_seconds(distance_with_grad, 21) * 1e3
        print(f"distance_to_surface+grad  centres={count:<3} median {summary[f'distance_grad_{count}_ms']:8.3f} ms")
    old = torch.tensor(rng.uniform(lo, hi, size=(16, 3)))
    new = old + 0.1 * torch.randn(16, 3, dtype=torch.float64)
    summary["step_guard_16_ms"] = median_seconds(lambda: step_guard(renderer, old, new), 21) * 1e3
    print(f"step_guard                centres=16  median {summary['step_guard_16_ms']:8.3f} ms")
    for height, width in ((60, 80), (240, 320)):
        K = camera.intrinsics(height, width)
        seconds = median_seconds(lambda: view_validity(renderer, camera.world_T_cam, K, height, width), 11)
        summary[f"validity_{height}x{width}_ms"] = seconds * 1e3
        print(f"view_validity one camera  {height}x{width:<4}    median {seconds * 1e3:8.3f} ms (512 enclosure rays)")
    print("penalty " + " ".join(f"{key}={value:.3f}" for key, value in summary.items()))


if __name__ == "__main__":
    main()
