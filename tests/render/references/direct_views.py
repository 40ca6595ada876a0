"""The three views whose direct-lighting renders are kept as regression references.

Written against the API kadv has had since 0.1 (main at 3787428, before light could be baked), so
that the same file renders them with that checkout or with today's: ``remake.py`` beside it.
"""

from __future__ import annotations

import inspect
from pathlib import Path

import numpy as np

from kadv.geometry import intrinsics_from_fov
from kadv.render import ExactRenderer, Shading
from kadv.scenes import box_room, load_scene, procedural_room

__all__ = ["HEIGHT", "REFERENCE", "WIDTH", "render_direct_views"]

HEIGHT, WIDTH = 48, 64
REFERENCE = Path(__file__).with_name("direct_lighting.npz")


def render_direct_views(scenes_root: Path) -> dict[str, np.ndarray]:
    """``{scene name: (1, 3, H, W) float32 RGB}`` from each scene's first camera, supersample 2."""
    # kadv 0.1's Shading had no `lighting`: its only lighting was what "direct" names today
    shading = Shading(lighting="direct") if "lighting" in inspect.signature(Shading).parameters else Shading()
    renders = {}
    for scene in (box_room(0), procedural_room(3), load_scene(scenes_root / "modern_hall" / "scene.xml")):
        camera = scene.cameras[0]
        K = intrinsics_from_fov(camera.fov_x_deg, HEIGHT, WIDTH)
        out = ExactRenderer(scene, shading).render(camera.world_T_cam, K, HEIGHT, WIDTH, supersample=2)
        renders[scene.name] = out.rgb.numpy()
    return renders
