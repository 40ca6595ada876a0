"""What an attack returns: one record per evaluated view, per-init-view results, the budget.

Every search method returns the same types, so reports treat them alike. ``restart`` is a lane
of the method (a gradient restart, a view's place in a black-box batch); step 0, restart 0 is
always the init view itself. Each result names its *path*: the views a report follows as the
search's trajectory (a gradient run's best restart, a black-box search's successive best views).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import asdict, dataclass, field, fields
from typing import Any

import torch

from kadv.attack.init_views import InitView
from kadv.geometry import axis_angle_to_matrix, perturb_world_T_cam, yaw_pitch_roll

__all__ = [
    "Agreement",
    "AttackResult",
    "Budget",
    "InitViewResult",
    "ViewRecord",
    "agreement",
    "agreement_text",
    "best_so_far",
    "incumbent_path",
    "select_top_views",
    "separated",
    "worst_record",
]


@dataclass
class ViewRecord:
    """One evaluated view.

    Attributes:
        step, restart: where it sits on the trajectory (see the module docstring).
        params: the point of the pose space (:class:`~kadv.attack.space.PoseSpace`): omega (3),
            delta (3), a rotation vector in the camera frame and a centre offset in world metres
            relative to the init view's pose, and when the field of view is searched its offset
            from the init view's in degrees.
        theta: absolute axis-angle of the camera's orientation (3).
        centre: optical centre in world metres (3).
        l_depth, l_dist, objective: the objective's terms (L_depth is recorded whatever the loss).
        delta1, abs_rel: the prediction's accuracy after scale-and-shift alignment.
        verdict: ``view_validity``'s verdict ("valid", "inside an object", ...).
        guard_fraction: fraction of the proposed move that the step guard let through (1: all).
        coverage, rgb_error, depth_error, refreshed: the differentiable renderer's agreement with
            the exact render (NaN and False for views rendered exactly).
        seconds: wall-clock seconds since the search from this init view began (machine-dependent,
            so ``trajectory.csv`` leaves it out).
        passes: the model passes (forward and backward) the search had spent once this view was
            scored, its own forward pass included.
        loss: the attacked loss, which ranks views (L_depth unless the run's loss is another; a
            record built without it takes L_depth).
        scale: the render's size relative to the run's: views screened smaller are never chosen
            or ranked, their best are re-scored at full size.
        screened: scored at a search's cheap fidelity (fewer rays per pixel): like views of
            another scale, never chosen or ranked; their best are re-scored exactly.
        yaw_deg, pitch_deg, roll_deg: the camera's heading, elevation and bank in degrees
            (:func:`kadv.geometry.yaw_pitch_roll`); made from ``theta`` when not given.
        run: the independent run of the init view's search it belongs to (``attack.restarts``;
            0: the first).
        fov_x_deg: the view's horizontal field of view, degrees (NaN: its init view's, in a
            record made without it).
    """

    step: int
    restart: int
    params: list[float]
    theta: list[float]
    centre: list[float]
    l_depth: float
    l_dist: float
    objective: float
    delta1: float
    abs_rel: float
    verdict: str
    guard_fraction: float = 1.0
    coverage: float = math.nan
    rgb_error: float = math.nan
    depth_error: float = math.nan
    refreshed: bool = False
    seconds: float = math.nan
    passes: int = 0
    loss: float = math.nan
    scale: float = 1.0
    screened: bool = False
    yaw_deg: float = math.nan
    pitch_deg: float = math.nan
    roll_deg: float = math.nan
    run: int = 0
    fov_x_deg: float = math.nan

    def __post_init__(self) -> None:
        if math.isnan(self.loss):
            self.loss = self.l_depth
        if math.isnan(self.yaw_deg):
            rotation = axis_angle_to_matrix(torch.tensor(self.theta, dtype=torch.float64))
            self.yaw_deg, self.pitch_deg, self.roll_deg = torch.rad2deg(yaw_pitch_roll(rotation)).tolist()

    @property
    def valid(self) -> bool:
        return self.verdict == "valid"

    @property
    def rankable(self) -> bool:
        """A valid view scored exactly at the run's full size: one a search may choose or follow."""
        return self.valid and self.scale == 1.0 and not self.screened

    def world_T_cam(self, init_world_T_cam: torch.Tensor) -> torch.Tensor:
        """The view's pose (4, 4), recomputed exactly from the init pose and the parameters."""
        params = torch.tensor(self.params, dtype=torch.float64)[None]
        return perturb_world_T_cam(init_world_T_cam.double()[None], params[:, :3], params[:, 3:6])[0]

    def fov(self, init_fov_x_deg: float) -> float:
        """The view's horizontal field of view, degrees: its own, or its init view's when not recorded."""
        return init_fov_x_deg if math.isnan(self.fov_x_deg) else self.fov_x_deg


@dataclass
class Budget:
    """Cost of a search, in the currency of ``attack.budget_passes``: model forward passes (every
    image the model ran on, at any fidelity; ``screened`` of them on a search's cheap renders),
    backward passes through the model, and wall-clock seconds."""

    forward: int = 0
    backward: int = 0
    seconds: float = 0.0
    screened: int = 0

    @property
    def passes(self) -> int:
        """Forward and backward passes: what ``attack.budget_passes`` bounds."""
        return self.forward + self.backward

    def to_dict(self) -> dict[str, float]:
        return asdict(self) | {"passes": self.passes}

    @classmethod
    def from_dict(cls, data: dict) -> Budget:
        """The budget :meth:`to_dict` wrote (its ``passes`` is derived)."""
        return cls(**{k: v for k, v in data.items() if k != "passes"})

    def text(self) -> str:
        """One line: ``123 passes (89 forward, 64 of them screened; 34 backward), 4.1 s``."""
        screened = f", {self.screened} of them screened" if self.screened else ""
        return (
            f"{self.passes} passes ({self.forward} forward{screened}; {self.backward} backward), {self.seconds:.1f} s"
        )

    def __add__(self, other: Budget) -> Budget:
        """The cost of both searches, so that ``sum(budgets, Budget())`` totals a run.

        Examples:
            >>> total = sum([Budget(50, 2, 1.5, 40), Budget(5, 0, 0.5)], Budget())
            >>> total, total.passes
            (Budget(forward=55, backward=2, seconds=2.0, screened=40), 57)
        """
        return Budget(
            self.forward + other.forward,
            self.backward + other.backward,
            self.seconds + other.seconds,
            self.screened + other.screened,
        )


@dataclass(frozen=True)
class Agreement:
    """How many independent runs of a search reached its worst view.

    Attributes:
        reached: runs whose worst delta1 lies within ``tolerance`` of the best run's.
        runs: runs made.
        planned: runs the budget was split into (``attack.restarts``).
        worsts: each run's worst delta1 (its lowest over rankable views), in run order.
        tolerance: the delta1 within which two worsts agree.
    """

    reached: int
    runs: int
    planned: int
    worsts: list[float]
    tolerance: float

    @property
    def alone(self) -> bool:
        """The worst was found by one run alone (or only one ran): nothing confirms it."""
        return self.reached < 2

    @property
    def stopped_early(self) -> bool:
        """Two runs agreed before the budget's share of every planned run was spent."""
        return self.runs < self.planned and not self.alone

    def text(self) -> str:
        """``3/5``, ``2/2 (stopped early, of 5)``, or ``1/3 (alone)``."""
        notes = [f"stopped early, of {self.planned}"] if self.stopped_early else []
        notes += ["alone"] if self.alone else []
        return f"{self.reached}/{self.runs}" + (f" ({'; '.join(notes)})" if notes else "")

    def to_dict(self) -> dict:
        return asdict(self) | {"alone": self.alone, "stopped_early": self.stopped_early}

    @classmethod
    def from_dict(cls, data: dict) -> Agreement:
        return cls(**{f.name: data[f.name] for f in fields(cls)})


def agreement_text(agreement: Agreement | None) -> str:
    """:meth:`Agreement.text`, or ``-`` where there is none."""
    return "-" if agreement is None else agreement.text()


def agreement(results: list[InitViewResult], planned: int, tolerance: float) -> Agreement:
    """The agreement of the runs ``results`` of one init view's search (a run with no rankable
    view counts its worst as 1: no failure found)."""
    worsts = [min((r.delta1 for r in result.records if r.rankable), default=1.0) for result in results]
    best = min(worsts)
    # within the tolerance as written: 0.33 is within 0.03 of 0.30, whatever the sum's rounding
    reached = sum(w - best <= tolerance + 1e-9 for w in worsts)
    return Agreement(reached, len(results), planned, worsts, tolerance)


@dataclass
class InitViewResult:
    """The search from one init view.

    Attributes:
        init: the init view.
        records: every evaluated view in order of evaluation.
        top: the adversarial views, highest loss first.
        budget: what the search cost.
        path: the views a report follows as the search's trajectory, in order.
        agreement: how many of the search's independent runs reached its worst view (None: a
            result made by a search method alone, before :func:`~kadv.attack.restarts.restarted_search`).
    """

    init: InitView
    records: list[ViewRecord]
    top: list[ViewRecord]
    budget: Budget
    path: list[ViewRecord]
    agreement: Agreement | None = None

    @property
    def init_record(self) -> ViewRecord:
        return next(r for r in self.records if r.step == 0 and r.restart == 0)


@dataclass
class AttackResult:
    """Results of one search method over all init views."""

    method: str
    views: list[InitViewResult] = field(default_factory=list)


def worst_record(records: list[ViewRecord]) -> ViewRecord:
    """The valid full-size record of lowest delta1 (the highest loss among ties)."""
    rankable = [r for r in records if r.rankable] or records[:1]
    return min(rankable, key=lambda r: (r.delta1, -r.loss))


def incumbent_path(records: list[ViewRecord]) -> list[ViewRecord]:
    """The init view, then each rankable view that raised the best loss so far, in evaluation order."""
    out, best = [records[0]], records[0].loss if records[0].rankable else -math.inf
    for record in records[1:]:
        if record.rankable and record.loss > best:
            out.append(record)
            best = record.loss
    return out


def best_so_far(records: list[ViewRecord]) -> list[tuple[int, float, float, float, float, float]]:
    """(passes, seconds, L_depth, delta1, AbsRel, loss) of the incumbent each time the best
    rankable loss so far rose: the search's anytime curve in model passes, from the init view."""
    return [(r.passes, r.seconds, r.l_depth, r.delta1, r.abs_rel, r.loss) for r in incumbent_path(records)]


def _angle_between(theta_a: list[float], theta_b: list[float]) -> float:
    """Rotation angle in radians between two orientations given as axis-angles."""
    rotations = axis_angle_to_matrix(torch.tensor([theta_a, theta_b], dtype=torch.float64))
    relative = rotations[0].T @ rotations[1]
    return float(torch.arccos(((torch.trace(relative) - 1) / 2).clamp(-1.0, 1.0)))


def separated(a: ViewRecord, b: ViewRecord, min_distance: float, min_angle_deg: float) -> bool:
    """Two views are distinct when their centres are ``min_distance`` apart or their orientations
    differ by ``min_angle_deg``."""
    distance = math.dist(a.centre, b.centre)
    return distance >= min_distance or math.degrees(_angle_between(a.theta, b.theta)) >= min_angle_deg


def select_top_views(
    records: list[ViewRecord],
    count: int,
    min_distance: float,
    min_angle_deg: float,
    order: Callable[[ViewRecord], Any] = lambda r: -r.loss,
) -> list[ViewRecord]:
    """Up to ``count`` rankable views first in ``order`` (default: highest loss), each separated
    from those chosen before it.

    Greedy in that order (ties keep evaluation order), so the result is deterministic.

    Examples:
        >>> def view(l_depth, x, verdict="valid"):
        ...     return ViewRecord(0, 0, [0.0] * 6, [0.0] * 3, [x, 1.5, 1.0], l_depth, 0.0, l_depth, 0.9, 0.1, verdict)
        >>> views = [view(0.30, 1.00), view(0.50, 1.05), view(0.40, 2.00), view(0.90, 3.0, "inside an object")]
        >>> [v.l_depth for v in select_top_views(views, 2, min_distance=0.2, min_angle_deg=10.0)]
        [0.5, 0.4]
    """
    chosen: list[ViewRecord] = []
    for record in sorted((r for r in records if r.rankable), key=order):
        if len(chosen) == count:
            break
        if all(separated(record, other, min_distance, min_angle_deg) for other in chosen):
            chosen.append(record)
    return chosen
