"""A suite's init views on one sheet: every frozen view rendered, a row a scene."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import torch

from kadv.bench.suite import Suite
from kadv.io import save_figure
from kadv.render import ExactRenderer, Shading

__all__ = ["save_suite_sheet"]


def save_suite_sheet(suite: Suite, path: str | Path, root: str | Path | None = None) -> Path:
    """Render each scene's init views as the protocol lights them, a row a scene, into a PNG."""
    import matplotlib.pyplot as plt

    columns = max(len(scene.views) for scene in suite.scenes)
    figure, axes = plt.subplots(
        len(suite.scenes), columns, figsize=(1.7 * columns, 1.45 * len(suite.scenes)), squeeze=False
    )
    for row, scene in enumerate(suite.scenes):
        renderer = ExactRenderer(scene.load(root), Shading(lighting=suite.protocol.lighting), progress=False)
        poses = torch.tensor([view.world_T_cam for view in scene.views], dtype=torch.float64)
        K = torch.tensor([view.K for view in scene.views], dtype=torch.float64)
        rgb = renderer.render(poses, K, *suite.protocol.size).rgb.permute(0, 2, 3, 1).cpu().numpy()
        for column, axis in enumerate(axes[row]):
            axis.set_axis_off()
            if column < len(scene.views):
                axis.imshow(np.clip(rgb[column], 0.0, 1.0))
                axis.set_title(f"{scene.name} {scene.views[column].name}", fontsize=6)
    figure.suptitle(f"suite {suite.name} ({suite.hash[:12]}): the init views", fontsize=8)
    figure.tight_layout()
    return save_figure(Path(path), figure)
