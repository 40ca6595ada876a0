"""Viewpoint robustness of a depth model on one scene, as a value and as an assertion.

:func:`viewpoint_robustness` runs kadv's default attack (the hybrid search on the smooth delta1
loss) from a few init views at a small size, deterministically for a seed, and reports per init
view the model's delta1 there and at the worst valid view found nearby, with that view's pose and
its four-panel picture. :func:`assert_viewpoint_robust` turns it into a test.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields
from pathlib import Path

import numpy as np
import torch

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.options import DEFAULT_BUDGET, CheckOptions, check_radii, setup, worst_record
from kadv.testing.session import current

__all__ = [
    "DEFAULT_BUDGET",
    "InitViewOutcome",
    "RobustnessResult",
    "assert_viewpoint_robust",
    "viewpoint_robustness",
]


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
        passes: model passes (forward and backward) spent from this init view.
        seconds: the search's seconds from this init view.
        picture: the worst view's four-panel PNG (image | depth | prediction | error).
        world_T_cam: the worst view's pose (4, 4).
        fov_x_deg: the worst view's horizontal field of view, degrees (its init view's unless
            the envelope's ``fov_deg`` freed it).
    """

    name: str
    delta1_init: float
    abs_rel_init: float
    delta1_worst: float
    abs_rel_worst: float
    centre: tuple[float, float, float]
    angles_deg: tuple[float, float, float]
    passes: int
    seconds: float = field(compare=False)  # the machine's, not the result's
    picture: Path
    world_T_cam: list[list[float]] = field(repr=False)
    fov_x_deg: float = 70.0

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
        budget_passes: model passes per init view (after ``--kadv-budget``'s factor).
        views: one outcome per init view.
        envelope: the camera envelope's name.
        radius: (degrees, metres) the camera could turn and move from each init view.
    """

    model: str
    scene: str
    seed: int
    budget_passes: int
    views: list[InitViewOutcome]
    envelope: str = "free"
    radius: tuple[float, float] = (45.0, 1.0)

    def bounds_text(self) -> str:
        """``within 45°, 1 m (envelope free)``."""
        return f"within {self.radius[0]:g}°, {self.radius[1]:g} m (envelope {self.envelope})"

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
            f"{self.budget_passes} model passes each, seed {self.seed}"
        ]
        for view in self.views:
            lines.append(
                f"  {view.name}: delta1 {view.delta1_init:.3f} -> {view.delta1_worst:.3f} "
                f"(AbsRel {view.abs_rel_init:.3f} -> {view.abs_rel_worst:.3f}) at {view.pose_text()}"
            )
        return "\n".join(lines)


def viewpoint_robustness(model, scene, **options) -> RobustnessResult:
    """Search for views near a scene's init views where ``model`` fails, deterministically for its seed.

    Args:
        model: a preset name (``"kadv_tiny"``), a hub id, a ``save_pretrained`` folder, a
            :class:`kadv.models.DepthModel`, or ``(torch module, output kind)``.
        scene: a :class:`kadv.scenes.Scene`, or a name :func:`kadv.testing.scene` takes
            (``"box_room"``, ``"probe/thin_structures"``, a file's path).
        options: :class:`CheckOptions`' fields (``init_count``, ``budget_passes``, ``seed``,
            ``loss``, ``size``, ``method``, ``lighting``, ``radius``, ``envelope``, ``artifacts``,
            ``progress``).

    Raises:
        RobustnessInputError: a bad model, scene or setting, in one line.
    """
    from kadv.attack import AttackConfig, InitViewError, attack

    checked = CheckOptions.of(options, "viewpoint_robustness")
    ((degrees, metres),) = check_radii([checked.radius])
    built = setup(model, scene, checked)
    try:
        config = AttackConfig(
            checked.method,
            budget_passes=built.budget,
            max_angle_deg=degrees,
            max_distance=metres,
            envelope=checked.envelope,
            restarts=checked.restarts,
        )
        result = attack(
            built.objective,
            built.differentiable,
            built.views,
            *built.size,
            config,
            checked.seed,
            progress=checked.progress,
        )
    except InitViewError as error:
        raise RobustnessInputError(f"scene {built.scene_name!r}: {error}") from error
    except ValueError as error:
        raise RobustnessInputError(str(error)) from error
    outcomes = [_outcome(built, view) for view in result.views]
    return RobustnessResult(
        built.model_name,
        built.scene_name,
        checked.seed,
        built.budget,
        outcomes,
        config.envelope.name,
        (degrees, metres),
    )


def _outcome(built, view) -> InitViewOutcome:
    """An init view's outcome: its worst view found (pose, figures, cost) and its picture."""
    from kadv.geometry import yaw_pitch_roll
    from kadv.report.outputs import save_view_picture

    init, worst = view.init_record, worst_record(view.records)
    pose = worst.world_T_cam(view.init.world_T_cam)
    picture = save_view_picture(
        built.folder / f"{built.stem}-{view.init.name}-worst.png",
        built.render,
        view.init,
        worst,
        f"worst view from {view.init.name}",
    )
    return InitViewOutcome(
        name=view.init.name,
        delta1_init=init.delta1,
        abs_rel_init=init.abs_rel,
        delta1_worst=worst.delta1,
        abs_rel_worst=worst.abs_rel,
        centre=tuple(pose[:3, 3].tolist()),
        angles_deg=tuple(torch.rad2deg(yaw_pitch_roll(pose[:3, :3].double())).tolist()),
        passes=view.budget.passes,
        seconds=view.budget.seconds,
        picture=picture,
        world_T_cam=pose.tolist(),
        fov_x_deg=worst.fov(view.init.fov_x_deg),
    )


def assert_viewpoint_robust(
    model,
    scene,
    *,
    min_delta1: float | None = None,
    max_delta1_drop: float | None = None,
    min_score: float | None = None,
    **options,
):
    """Fail unless every init view's worst view keeps delta1 >= ``min_delta1`` and loses at most
    ``max_delta1_drop`` of its init view's delta1, within one radius and envelope (``radius=``,
    ``envelope=``; by default 45 degrees and 1 m, any pose); and, with ``min_score``, unless the
    model's :func:`kadv.testing.robustness_profile` score reaches it.

    Takes :func:`viewpoint_robustness`'s arguments (``radius``, ``envelope``, ``init_count``,
    ``budget_passes``, ``seed``, ``loss``, ``size``, ...) and, with ``min_score``,
    :func:`kadv.testing.robustness_profile`'s (``radii``, ``seeds``, ...). Returns the result of the
    one-radius check, or the profile when ``min_score`` alone is set.

    Raises:
        AssertionError: naming the radius and envelope, each failing init view, its delta1 init ->
            worst, the worst view's pose and its picture; or the score, its spread and the profile.
        RobustnessInputError: no threshold set, an option neither check takes, or a bad model,
            scene or setting.
    """
    __tracebackhide__ = True  # pytest shows the user's line, not kadv's
    from kadv.testing.profile import PROFILE_KEYS, robustness_profile

    if min_delta1 is None and max_delta1_drop is None and min_score is None:
        raise RobustnessInputError(
            "assert_viewpoint_robust needs min_delta1, max_delta1_drop or min_score (all are unset)"
        )
    for name, value in (("min_delta1", min_delta1), ("max_delta1_drop", max_delta1_drop), ("min_score", min_score)):
        if value is not None and not (isinstance(value, (int, float)) and 0.0 <= value <= 1.0):
            raise RobustnessInputError(f"{name} must be a number in [0, 1], got {value!r}")
    single = {f.name for f in fields(CheckOptions)}
    profiled = (single - {"radius", "seed"}) | set(PROFILE_KEYS)
    unknown = sorted(set(options) - single - (profiled if min_score is not None else set()))
    if unknown:
        raise RobustnessInputError(f"assert_viewpoint_robust takes no option {', '.join(unknown)}")
    outcome = None
    if min_delta1 is not None or max_delta1_drop is not None:
        outcome = _check_radius(
            model, scene, min_delta1, max_delta1_drop, {k: v for k, v in options.items() if k in single}
        )
    if min_score is not None:
        profile = robustness_profile(model, scene, **{k: v for k, v in options.items() if k in profiled})
        passed = profile.score >= min_score  # a NaN score (a radius kept no drawn view) fails too
        current().report(profile, passed)
        if not passed:
            raise AssertionError(
                f"{profile.model}'s viewpoint robustness score on {profile.scene} is {profile.score:.3f} "
                f"(± {profile.score_spread:.3f} over seeds {list(profile.seeds)}), below min_score {min_score} "
                f"(radii {profile.radii_text}, envelope {profile.envelope}):\n{profile.markdown()}"
            )
        outcome = outcome or profile
    return outcome


def _check_radius(model, scene, min_delta1, max_delta1_drop, options: dict) -> RobustnessResult:
    __tracebackhide__ = True
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
        lines = [f"{result.model} is not viewpoint-robust on {result.scene} {result.bounds_text()} (wanted {wanted}):"]
        for view in failing:
            lines.append(
                f"  {view.name}: delta1 {view.delta1_init:.3f} -> {view.delta1_worst:.3f} at {view.pose_text()}; "
                f"picture: {view.picture}"
            )
        raise AssertionError("\n".join(lines))
    return result
