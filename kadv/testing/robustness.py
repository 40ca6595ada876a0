"""Viewpoint robustness of a depth model on one scene, as a value and as an assertion.

:func:`viewpoint_robustness` runs kadv's default attack (the hybrid search on the smooth delta1
loss) from a few init views at a small size, deterministically for a seed, and reports per init
view the model's delta1 there and at the worst valid view found nearby, with that view's pose and
its four-panel picture. :func:`assert_viewpoint_robust` turns it into a test.
"""

from __future__ import annotations

import math
import tempfile
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import torch

from kadv.testing.inputs import RobustnessInputError, resolve_model, resolve_scene
from kadv.testing.session import current

__all__ = [
    "DEFAULT_BUDGET",
    "InitViewOutcome",
    "RobustnessResult",
    "assert_viewpoint_robust",
    "viewpoint_robustness",
]

DEFAULT_BUDGET = 48  # model evaluations per init view, the init view's included


@dataclass(frozen=True)
class InitViewOutcome:
    """One init view and the worst valid view the search found from it.

    Attributes:
        name: the init view's name ("file0", "sampled0", ...).
        delta1_init, abs_rel_init: the model's accuracy at the init view.
        delta1_worst, abs_rel_worst: at the worst valid full-size view found (the init view itself
            when nothing was worse).
        centre: the worst view's optical centre, world metres (x, y, z; y up).
        angles_deg: its yaw, pitch (positive: up) and roll, degrees.
        evaluations: model evaluations spent from this init view.
        picture: the worst view's four-panel PNG (image | depth | prediction | error).
        world_T_cam: the worst view's pose (4, 4).
    """

    name: str
    delta1_init: float
    abs_rel_init: float
    delta1_worst: float
    abs_rel_worst: float
    centre: tuple[float, float, float]
    angles_deg: tuple[float, float, float]
    evaluations: int
    picture: Path
    world_T_cam: list[list[float]] = field(repr=False)

    @property
    def delta1_drop(self) -> float:
        return self.delta1_init - self.delta1_worst

    def pose_text(self) -> str:
        x, y, z = self.centre
        yaw, pitch, roll = self.angles_deg
        return f"centre ({x:.2f}, {y:.2f}, {z:.2f}) m, yaw {yaw:.1f}, pitch {pitch:.1f}, roll {roll:.1f} deg"


@dataclass(frozen=True)
class RobustnessResult:
    """What :func:`viewpoint_robustness` found.

    Attributes:
        model: the model's name.
        scene: the scene's name.
        seed: the search's seed.
        budget_evaluations: evaluations per init view (after ``--kadv-budget``'s factor).
        views: one outcome per init view.
    """

    model: str
    scene: str
    seed: int
    budget_evaluations: int
    views: list[InitViewOutcome]

    @property
    def worst(self) -> InitViewOutcome:
        """The init view whose worst view has the lowest delta1."""
        return min(self.views, key=lambda view: view.delta1_worst)

    @property
    def delta1_init(self) -> float:
        """Mean delta1 over the init views."""
        return float(np.mean([view.delta1_init for view in self.views]))

    def summary(self) -> str:
        """A few lines: the model, the scene, and each init view's delta1 init -> worst."""
        lines = [
            f"{self.model} on {self.scene}: {len(self.views)} init views, "
            f"{self.budget_evaluations} evaluations each, seed {self.seed}"
        ]
        for view in self.views:
            lines.append(
                f"  {view.name}: delta1 {view.delta1_init:.3f} -> {view.delta1_worst:.3f} "
                f"(AbsRel {view.abs_rel_init:.3f} -> {view.abs_rel_worst:.3f}) at {view.pose_text()}"
            )
        return "\n".join(lines)


def _angles_deg(world_T_cam: torch.Tensor) -> tuple[float, float, float]:
    """(yaw, pitch, roll) in degrees of an OpenCV camera pose (4, 4) in kadv's y-up world."""
    rotation = world_T_cam[:3, :3].double()
    forward, right, down = rotation[:, 2], rotation[:, 0], rotation[:, 1]
    yaw = math.atan2(float(forward[0]), float(forward[2]))
    pitch = math.asin(max(-1.0, min(1.0, float(forward[1]))))
    roll = math.atan2(float(right[1]), -float(down[1]))
    return tuple(math.degrees(a) for a in (yaw, pitch, roll))


def _worst(records: list) -> object:
    """The valid full-size record of lowest delta1 (the highest loss among ties)."""
    rankable = [r for r in records if r.rankable] or records[:1]
    return min(rankable, key=lambda r: (r.delta1, -r.loss))


def viewpoint_robustness(
    model,
    scene,
    *,
    init_count: int = 2,
    budget_evaluations: int = DEFAULT_BUDGET,
    seed: int = 0,
    loss: str = "delta1",
    size: tuple[int, int] = (96, 128),
    method: str = "hybrid",
    lighting: str = "baked",
    artifacts: str | Path | None = None,
    progress: bool = False,
) -> RobustnessResult:
    """Search for views near a scene's init views where ``model`` fails, deterministically for ``seed``.

    Args:
        model: a preset name (``"kadv_tiny"``), a hub id, a ``save_pretrained`` folder, a
            :class:`kadv.models.DepthModel`, or ``(torch module, output kind)``.
        scene: a :class:`kadv.scenes.Scene`, or a name :func:`kadv.testing.scene` takes
            (``"box_room"``, ``"probe/thin_structures"``, a file's path).
        init_count: init views: the scene's cameras first, then sampled views the model gets right.
        budget_evaluations: model evaluations per init view (scaled by ``--kadv-budget`` under pytest).
        seed: the seed of the init views and the search.
        loss: the attacked loss (``"delta1"``, ``"absrel"``, ``"ssim"``, ``"perceptual"``).
        size: (height, width) of the renders.
        method: the search method (:data:`kadv.attack.METHODS`).
        lighting: ``"baked"`` (the commands' default; baked once per scene and cached) or ``"direct"``.
        artifacts: the folder for the worst views' pictures; None: the pytest plugin's folder for
            this test, else a new temporary folder.
        progress: show progress bars.

    Raises:
        RobustnessInputError: a bad model, scene or setting, in one line.
    """
    from kadv.attack import (
        AttackConfig,
        InitViewConfig,
        InitViewError,
        Objective,
        PenaltyConfig,
        attack,
        check_init_views,
        file_init_views,
        sample_init_views,
    )
    from kadv.losses import depth_loss
    from kadv.render import DifferentiableRenderer, ExactRenderer, Shading
    from kadv.report.run import ViewRenderer, save_view_picture

    if isinstance(init_count, bool) or not isinstance(init_count, int) or init_count < 1:
        raise RobustnessInputError(f"init_count must be an integer >= 1, got {init_count!r}")
    if isinstance(budget_evaluations, bool) or not isinstance(budget_evaluations, int) or budget_evaluations < 2:
        raise RobustnessInputError(f"budget_evaluations must be an integer >= 2, got {budget_evaluations!r}")
    settings = current()
    budget = max(2, round(budget_evaluations * settings.budget_factor))
    height, width = size
    depth_model = resolve_model(model)
    built = resolve_scene(scene)
    try:
        renderer = ExactRenderer(built, Shading(lighting=lighting), progress=progress)
        penalty = PenaltyConfig()
        objective = Objective(depth_model, depth_loss(loss), renderer, penalty)
        views = file_init_views(renderer, penalty.margin)[:init_count]
        views += sample_init_views(
            renderer, depth_model, init_count - len(views), seed, InitViewConfig(), penalty, height, width
        )
        check_init_views(renderer, views, penalty, height, width)
        config = AttackConfig(method, budget_evaluations=budget)
    except InitViewError as error:
        raise RobustnessInputError(f"scene {built.name!r}: {error}") from error
    except ValueError as error:
        raise RobustnessInputError(str(error)) from error
    result = attack(objective, DifferentiableRenderer(renderer), views, height, width, config, seed, progress=progress)
    folder = Path(artifacts) if artifacts is not None else settings.artifacts
    if folder is None:
        folder = Path(tempfile.mkdtemp(prefix="kadv-"))
    stem = f"{_slug(depth_model.name)}-{_slug(built.name)}-seed{seed}"
    render = ViewRenderer(objective, height, width, supersample=2)
    outcomes = []
    for view in result.views:
        init, worst = view.init_record, _worst(view.records)
        pose = worst.world_T_cam(view.init.world_T_cam)
        picture = save_view_picture(
            folder / f"{stem}-{view.init.name}-worst.png", render, view.init, worst, f"worst view from {view.init.name}"
        )
        outcomes.append(
            InitViewOutcome(
                name=view.init.name,
                delta1_init=init.delta1,
                abs_rel_init=init.abs_rel,
                delta1_worst=worst.delta1,
                abs_rel_worst=worst.abs_rel,
                centre=tuple(pose[:3, 3].tolist()),
                angles_deg=_angles_deg(pose),
                evaluations=len(view.records),
                picture=picture,
                world_T_cam=pose.tolist(),
            )
        )
    return RobustnessResult(depth_model.name, built.name, seed, budget, outcomes)


def _slug(name: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in name)[:80]


def assert_viewpoint_robust(
    model,
    scene,
    *,
    min_delta1: float | None = None,
    max_delta1_drop: float | None = None,
    **options,
) -> RobustnessResult:
    """Fail unless every init view's worst view keeps delta1 >= ``min_delta1`` and loses at most
    ``max_delta1_drop`` of its init view's delta1.

    Takes :func:`viewpoint_robustness`'s arguments (``init_count``, ``budget_evaluations``,
    ``seed``, ``loss``, ``size``, ...); returns its result when the model passes.

    Raises:
        AssertionError: naming each failing init view, its delta1 init -> worst, the worst view's
            pose and its picture.
        RobustnessInputError: neither threshold set, or a bad model, scene or setting.
    """
    __tracebackhide__ = True  # pytest shows the user's line, not kadv's
    if min_delta1 is None and max_delta1_drop is None:
        raise RobustnessInputError("assert_viewpoint_robust needs min_delta1 or max_delta1_drop (both are unset)")
    for name, value in (("min_delta1", min_delta1), ("max_delta1_drop", max_delta1_drop)):
        if value is not None and not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
            raise RobustnessInputError(f"{name} must be a number in [0, 1], got {value!r}")
    result = viewpoint_robustness(model, scene, **options)
    failing = [
        view
        for view in result.views
        if (min_delta1 is not None and view.delta1_worst < min_delta1)
        or (max_delta1_drop is not None and view.delta1_drop > max_delta1_drop)
    ]
    current().report(result, passed=not failing)
    if failing:
        wanted = " and ".join(
            text
            for text, value in (
                (f"delta1 >= {min_delta1}", min_delta1),
                (f"a delta1 drop <= {max_delta1_drop}", max_delta1_drop),
            )
            if value is not None
        )
        lines = [f"{result.model} is not viewpoint-robust on {result.scene} (wanted {wanted}):"]
        for view in failing:
            lines.append(
                f"  {view.name}: delta1 {view.delta1_init:.3f} -> {view.delta1_worst:.3f} at {view.pose_text()}; "
                f"picture: {view.picture}"
            )
        raise AssertionError("\n".join(lines))
    return result
