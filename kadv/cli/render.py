"""``kadv-render``: render one view of a scene into the run directory.

Writes ``rgb.png``, ``depth.npy`` (float32 z-depth in metres, 0 where no surface), ``mask.png``
(white where a ray hit a surface), ``depth_vis.png`` (the depth colour-mapped with a colour bar;
grey: no surface) and ``render.json`` (pose, K, depth range, hit fraction, the view's validity).
A view that is not valid (the eye inside an object, outside the scene, or on a surface) is refused
unless ``camera.allow_invalid=true``; a file camera nearer to a surface than ``penalty.margin`` is
first moved along its optical axis until it is clear, as the attack's init views are.
"""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import json
import logging
from pathlib import Path

import hydra
import numpy as np
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig, OmegaConf

from kadv.attack import PenaltyConfig, clear_file_camera
from kadv.cli.common import (
    camera_from_config,
    check_render_config,
    checks_overrides,
    frame_note,
    reports_user_errors,
    scene_from_config,
    study_settings,
)
from kadv.geometry import intrinsics_from_fov
from kadv.io import atomic_write
from kadv.penalties import view_validity
from kadv.report import save_depth_png, save_rgb_png

log = logging.getLogger(__name__)


@checks_overrides("kadv-render")
@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_render")
@reports_user_errors("kadv-render")
def main(cfg: DictConfig) -> None:
    """Render the configured scene from the configured camera."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    scene = scene_from_config(cfg.scene)
    if (note := frame_note(scene)) is not None:
        log.info(note)
    world_T_cam, fov = camera_from_config(cfg.camera, scene)
    height, width, supersample = check_render_config(cfg.render)
    penalty = PenaltyConfig(**OmegaConf.to_container(cfg.penalty, resolve=True))
    renderer = study_settings(scene, cfg.render).exact_renderer(scene)
    note = "as given"
    if cfg.camera.world_T_cam is None and cfg.camera.eye is None:
        world_T_cam, moved = clear_file_camera(renderer, world_T_cam, penalty.margin)
        note = f"file camera {int(cfg.camera.index)}" + (
            f", moved {moved:+.3f} m along its optical axis to clear {penalty.margin} m" if moved else ""
        )
    K = intrinsics_from_fov(fov, height, width)
    out = renderer.render(world_T_cam, K, height, width, supersample=supersample).to("cpu")
    validity = view_validity(renderer, world_T_cam, K, height, width, render=out, **penalty.validity_options())
    verdict, reason = validity.verdicts[0], validity.reasons[0]
    if verdict != "valid" and not cfg.camera.allow_invalid:
        raise ValueError(
            f"camera: the view is {verdict} ({reason}); "
            "move the camera, or render it anyway with camera.allow_invalid=true"
        )
    depth = out.depth[0, 0].numpy()
    mask = out.mask[0, 0].numpy()
    save_rgb_png(out_dir / "rgb.png", out.rgb[0])
    atomic_write(out_dir / "depth.npy", lambda tmp: np.save(tmp, depth, allow_pickle=False))
    save_rgb_png(out_dir / "mask.png", out.mask[0].float().expand(3, -1, -1))
    save_depth_png(out_dir / "depth_vis.png", out.depth[0], out.mask[0], label="depth [m], grey: no surface")
    summary = {
        "scene": scene.name,
        "triangles": scene.num_triangles,
        "world_T_cam": world_T_cam.tolist(),
        "world_T_file": scene.world_T_file.tolist(),
        "camera": note,
        "K": K.tolist(),
        "fov_x_deg": fov,
        "height": height,
        "width": width,
        "supersample": supersample,
        "lighting": renderer.shading.lighting,
        "hit_fraction": float(mask.mean()),
        "depth_range_m": [float(depth[mask].min()), float(depth[mask].max())] if mask.any() else None,
        "validity": {"verdict": verdict, "reason": reason},
    }
    text = json.dumps(summary, indent=2)
    atomic_write(out_dir / "render.json", lambda tmp: tmp.write_text(text))
    print(f"view: {verdict} ({reason}); camera: {note}")
    log.info(
        "rendered %s (%d triangles, %.3f of pixels hit) to %s",
        scene.name,
        scene.num_triangles,
        summary["hit_fraction"],
        out_dir,
    )


if __name__ == "__main__":
    main()
