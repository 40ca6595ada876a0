"""What every robustness check shares: its options, the objects it searches with, and the worst
record of a search. :mod:`kadv.testing.robustness` and :mod:`kadv.testing.profile` build on it."""

from __future__ import annotations

import itertools
import math
import tempfile
from dataclasses import dataclass, fields
from pathlib import Path

from kadv.attack.records import worst_record
from kadv.attack.search import DEFAULT_METHOD, RENAMED_BUDGET
from kadv.io import file_slug as slug
from kadv.testing.inputs import RobustnessInputError, resolve_model, resolve_scene
from kadv.testing.session import current

__all__ = ["DEFAULT_BUDGET", "CheckOptions", "Setup", "check_radii", "setup", "slug", "worst_record"]

DEFAULT_BUDGET = 48  # model passes per init view (and radius, in a profile), the init view's included


@dataclass(frozen=True)
class CheckOptions:
    """How a check searches (:func:`viewpoint_robustness`'s keyword arguments).

    Attributes:
        init_count: init views: the scene's cameras first, then sampled views the model gets right.
        budget_passes: model passes per init view, forward and backward, at any fidelity (scaled
            by ``--kadv-budget`` under pytest).
        seed: the seed of the init views and the search.
        loss: the attacked loss (``"delta1"``, ``"absrel"``, ``"ssim"``, ``"perceptual"``).
        size: (height, width) of the renders.
        method: the search method (:data:`kadv.attack.METHODS`).
        lighting: ``"baked"`` (the commands' default; baked once per scene and cached) or ``"direct"``.
        radius: (degrees, metres): how far the camera may turn and move from each init view.
        envelope: the poses the camera may take (:mod:`kadv.penalties.envelope`): a preset's name
            (``free``, ``upright``, ``handheld``, ``robot``) or an :class:`kadv.penalties.Envelope`.
        artifacts: the folder for the worst views' pictures; None: the pytest plugin's folder for
            this test, else a new temporary folder.
        progress: show progress bars.
        restarts: independent runs of the search per init view at most, each a share of the
            budget (``attack.restarts``; their agreement is reported beside the worst).
        alignment: how delta1 meets the ground truth (``loss.alignment``): ``scale_shift``,
            ``scale`` or ``none`` (metric depth as predicted; a relative model is refused); None:
            the model's output kind's own (:func:`kadv.losses.kind_fit`).
        radius_shares: a profile's split of its passes over its radii, one positive share a
            radius (``attack.radius_shares``; None: the k-th radius gets k shares).
    """

    init_count: int = 2
    budget_passes: int = DEFAULT_BUDGET
    seed: int = 0
    loss: str = "delta1"
    size: tuple[int, int] = (96, 128)
    method: str = DEFAULT_METHOD
    lighting: str = "baked"
    radius: tuple[float, float] = (45.0, 1.0)
    envelope: object = "free"
    artifacts: str | Path | None = None
    progress: bool = False
    restarts: int = 1
    alignment: str | None = None
    radius_shares: tuple[float, ...] | None = None

    @classmethod
    def of(cls, options: dict, taker: str) -> CheckOptions:
        """The options from keyword arguments, or :class:`RobustnessInputError` naming an unknown one."""
        if "budget_evaluations" in options:
            raise RobustnessInputError(f"{taker}: {RENAMED_BUDGET.replace('attack.', '')}")
        unknown = sorted(set(options) - {f.name for f in fields(cls)})
        if unknown:
            raise RobustnessInputError(f"{taker} takes no option {', '.join(unknown)}")
        return cls(**options)


@dataclass
class Setup:
    """What a robustness check searches with: its :class:`~kadv.attack.Study` (the scene's
    renderers, the objective), the init views, and where and how the worst views' pictures go."""

    model_name: str
    scene_name: str
    study: object
    views: list
    budget: int
    folder: Path
    stem: str
    render: object

    @property
    def size(self) -> tuple[int, int]:
        return self.study.settings.size

    @property
    def renderer(self):
        return self.study.renderer

    @property
    def differentiable(self):
        return self.study.differentiable

    @property
    def objective(self):
        return self.study.objective

    @property
    def penalty(self):
        return self.study.settings.penalty


def setup(model, scene, options: CheckOptions) -> Setup:
    """The :class:`Setup` of a check, or :class:`RobustnessInputError` in one line."""
    from kadv.attack import InitViewError, Study, StudySettings
    from kadv.losses import LossConfig
    from kadv.render import Shading
    from kadv.report.outputs import ViewRenderer

    init_count, budget_passes = options.init_count, options.budget_passes
    if isinstance(init_count, bool) or not isinstance(init_count, int) or init_count < 1:
        raise RobustnessInputError(f"init_count must be an integer >= 1, got {init_count!r}")
    if isinstance(budget_passes, bool) or not isinstance(budget_passes, int) or budget_passes < 2:
        raise RobustnessInputError(f"budget_passes must be an integer >= 2, got {budget_passes!r}")
    settings = current()
    budget = max(2, round(budget_passes * settings.budget_factor))
    height, width = options.size
    depth_model = resolve_model(model)
    built = resolve_scene(scene)
    try:
        study = Study.build(
            built,
            depth_model,
            StudySettings(
                size=(height, width),
                shading=Shading(lighting=options.lighting),
                loss=LossConfig(kind=options.loss, alignment=options.alignment),
                progress=options.progress,
            ),
        )
        views = _init_views(study, init_count, options.seed)
    except InitViewError as error:
        raise RobustnessInputError(f"scene {built.name!r}: {error}") from error
    except ValueError as error:
        raise RobustnessInputError(str(error)) from error
    folder = Path(options.artifacts) if options.artifacts is not None else settings.artifacts
    if folder is None:
        folder = Path(tempfile.mkdtemp(prefix="kadv-"))
    return Setup(
        depth_model.name,
        built.name,
        study,
        views,
        budget,
        folder,
        f"{slug(depth_model.name)}-{slug(built.name)}-seed{options.seed}",
        ViewRenderer(study.objective, height, width, supersample=2),
    )


def _init_views(study, count: int, seed: int) -> list:
    """A check's ``count`` init views: the scene file's cameras first, then views sampled under
    ``seed`` that the study's model gets right (after its alignment), all checked."""
    from kadv.attack import InitViewConfig, check_init_views, file_init_views, sample_init_views

    renderer, penalty, (height, width) = study.renderer, study.settings.penalty, study.settings.size
    views = file_init_views(renderer, penalty.margin)[:count]
    views += sample_init_views(
        renderer, study.model, count - len(views), seed, InitViewConfig(), penalty, height, width,
        alignment=study.objective.alignment,
    )  # fmt: skip
    check_init_views(renderer, views, penalty, height, width)
    return views


def check_radii(radii) -> tuple[tuple[float, float], ...]:
    """The radii as (degrees, metres) pairs, or :class:`RobustnessInputError` naming what is wrong:
    each positive, both increasing (nested: each radius holds the one before)."""
    try:
        pairs = tuple((float(d), float(m)) for d, m in radii)
    except (TypeError, ValueError):
        raise RobustnessInputError(f"radii must be (degrees, metres) pairs, got {radii!r}") from None
    if not pairs:
        raise RobustnessInputError("radii is empty: give at least one (degrees, metres) pair")
    for d, m in pairs:
        if not (math.isfinite(d) and math.isfinite(m) and d > 0 and m > 0):
            raise RobustnessInputError(f"radii: each radius must be positive, got ({d:g}, {m:g})")
    for (d0, m0), (d1, m1) in itertools.pairwise(pairs):
        if d1 < d0 or m1 < m0 or (d1, m1) == (d0, m0):
            raise RobustnessInputError(
                f"radii must increase (each holds the one before), got ({d0:g}, {m0:g}) then ({d1:g}, {m1:g})"
            )
    return pairs
