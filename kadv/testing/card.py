"""The probe scorecard: every model on every probe scene, as one table and one picture."""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.robustness import DEFAULT_BUDGET, RobustnessResult, viewpoint_robustness

__all__ = ["Scorecard", "scorecard"]


@dataclass(frozen=True)
class Scorecard:
    """Results by probe and model.

    Attributes:
        models: the models' names, one column each.
        probes: the probes' names, one row each.
        results: ``results[probe][model]``.
    """

    models: list[str]
    probes: list[str]
    results: dict[str, dict[str, RobustnessResult]]

    def markdown(self) -> str:
        """The table: per probe and model, mean delta1 at the init views -> the worst view's delta1."""
        lines = [
            "| probe | " + " | ".join(f"{model}: delta1 init -> worst" for model in self.models) + " |",
            "|---|" + "---|" * len(self.models),
        ]
        for probe in self.probes:
            cells = []
            for model in self.models:
                result = self.results[probe][model]
                cells.append(f"{result.delta1_init:.3f} -> {result.worst.delta1_worst:.3f}")
            lines.append(f"| {probe} | " + " | ".join(cells) + " |")
        means = [
            np.mean([self.results[probe][model].worst.delta1_worst for probe in self.probes]) for model in self.models
        ]
        lines.append("| **mean worst** | " + " | ".join(f"**{mean:.3f}**" for mean in means) + " |")
        return "\n".join(lines)

    def save_png(self, path: str | Path) -> Path:
        """One thumbnail of each probe's worst view per model (rows: probes, columns: models)."""
        import matplotlib.pyplot as plt
        from PIL import Image

        from kadv.report.figures import save_figure

        rows, columns = len(self.probes), len(self.models)
        # the pictures are four panels wide: tiles of their shape, titled above
        figure, axes = plt.subplots(rows, columns, figsize=(6.4 * columns, 2.3 * rows), squeeze=False)
        for r, probe in enumerate(self.probes):
            for c, model in enumerate(self.models):
                worst = self.results[probe][model].worst
                with Image.open(worst.picture) as picture:
                    axes[r, c].imshow(np.asarray(picture.convert("RGB")))
                axes[r, c].set_title(
                    f"{probe}, {model}\ndelta1 {worst.delta1_init:.2f} -> {worst.delta1_worst:.2f}", fontsize=9
                )
                axes[r, c].set_axis_off()
        figure.tight_layout()
        return save_figure(Path(path), figure)


def scorecard(
    models: list,
    probes: list[str] | None = None,
    *,
    seed: int = 0,
    budget_evaluations: int = DEFAULT_BUDGET,
    artifacts: str | Path | None = None,
    progress: bool = False,
    **options,
) -> Scorecard:
    """Run :func:`kadv.testing.viewpoint_robustness` for each model on each probe scene.

    Args:
        models: what :func:`kadv.testing.viewpoint_robustness` takes as a model, one per column.
        probes: probe names (:data:`kadv.probes.PROBES`); None: all of them.
        seed: the probes' and the searches' seed.
        budget_evaluations: evaluations per init view.
        artifacts: the folder for the worst views' pictures.
        progress: print a line per probe and model as each finishes.
        options: more of :func:`kadv.testing.viewpoint_robustness`'s arguments.

    Raises:
        RobustnessInputError: an unknown probe (listing the probes), or a bad model.
    """
    from kadv.models import DepthModel
    from kadv.scenes.probes import PROBES, probe_scene
    from kadv.testing.inputs import resolve_model

    probes = list(PROBES) if probes is None else list(probes)
    unknown = [name for name in probes if name not in PROBES]
    if unknown:
        raise RobustnessInputError(f"no probe scene {unknown[0]!r}; the probes are: {', '.join(PROBES)}")
    if not models:
        raise RobustnessInputError("scorecard needs at least one model")
    loaded: list[DepthModel] = [resolve_model(model) for model in models]
    names = [model.name for model in loaded]
    if len(set(names)) != len(names):
        raise RobustnessInputError(f"models: each must have its own name, got {names}")
    results: dict[str, dict[str, RobustnessResult]] = {}
    for probe in probes:
        built = probe_scene(probe, seed)
        results[probe] = {}
        for model in loaded:
            result = viewpoint_robustness(
                model, built, seed=seed, budget_evaluations=budget_evaluations, artifacts=artifacts, **options
            )
            results[probe][model.name] = result
            if progress:
                print(
                    f"{probe} x {model.name}: {result.delta1_init:.3f} -> {result.worst.delta1_worst:.3f}", flush=True
                )
    return Scorecard(names, probes, results)
