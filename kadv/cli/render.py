"""``kadv-render``: render a scene to ``rgb.png`` and ``depth.png`` in the run directory."""
from __future__ import annotations

import json
import logging
from pathlib import Path

import hydra
from hydra.core.hydra_config import HydraConfig
from omegaconf import DictConfig

from kadv.cli.common import (
    camera_from_config,
    check_render_config,
    reports_user_errors,
    scene_from_config,
    shading_from_config,
)
from kadv.geometry import intrinsics_from_fov
from kadv.render import ExactRenderer
from kadv.report import atomic_write, save_depth_png, save_rgb_png

log = logging.getLogger(__name__)


@hydra.main(version_base="1.3", config_path="../conf", config_name="kadv_render")
@reports_user_errors("kadv-render")
def main(cfg: DictConfig) -> None:
    """Render the configured scene from the configured camera."""
    out_dir = Path(HydraConfig.get().runtime.output_dir)
    scene = scene_from_config(cfg.scene)
    world_T_cam, fov = camera_from_config(cfg.camera, scene)
    height, width, supersample = check_render_config(cfg.render)
    renderer = ExactRenderer(scene, shading_from_config(cfg.render.shading))
    out = renderer.render(world_T_cam, intrinsics_from_fov(fov, height, width), height, width,
                          supersample=supersample)
    save_rgb_png(out_dir / "rgb.png", out.rgb[0])
    save_depth_png(out_dir / "depth.png", out.depth[0], out.mask[0])
    summary = {
        "scene": scene.name,
        "triangles": scene.num_triangles,
        "world_T_cam": world_T_cam.tolist(),
        "fov_x_deg": fov,
        "height": height,
        "width": width,
        "hit_fraction": float(out.mask.float().mean()),
    }
    atomic_write(out_dir / "render.json", lambda tmp: tmp.write_text(json.dumps(summary, indent=2)))
    log.info("rendered %s (%d triangles, %.3f of pixels hit) to %s", scene.name, scene.num_triangles,
             summary["hit_fraction"], out_dir)


if __name__ == "__main__":
    main()
