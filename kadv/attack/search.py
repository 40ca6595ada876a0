"""What every search method shares: the attack's settings, pose bounds, the budget, the guarded
move, view evaluation and recording."""

from __future__ import annotations

import contextlib
import dataclasses
import math
import time
from collections.abc import Iterator
from dataclasses import InitVar, dataclass
from typing import Any

import torch

from kadv.attack.init_views import InitView
from kadv.attack.objective import Objective, ObjectiveTerms
from kadv.attack.records import Budget, InitViewResult, ViewRecord, select_top_views
from kadv.attack.registry import get_method
from kadv.attack.space import FOV, PoseSpace
from kadv.geometry import matrix_to_axis_angle, perturb_world_T_cam, scaled_size, yaw_pitch_roll
from kadv.penalties import ViewValidity, view_validity
from kadv.penalties.envelope import Envelope, get_envelope
from kadv.render import DifferentiableRenderer, DiffRenderOutput, RenderOutput

__all__ = [
    "DEFAULT_METHOD",
    "DEFAULT_PASSES",
    "RENAMED_BUDGET",
    "AttackConfig",
    "Clock",
    "Measures",
    "SearchContext",
    "check_settings",
    "positive_shares",
]

# The search with the lowest held-out regret at equal model passes and at equal seconds
# (benchmarks/worst_case.py; docs/attack.md#the-worst-case-as-a-measurement).
DEFAULT_METHOD = "halving"
# Model passes per init view of an attack (kadv-attack's attack.budget_passes).
DEFAULT_PASSES = 123


def check_settings(settings: Any, node: str) -> None:
    """Refuse a settings dataclass holding a negative count, a non-positive rate or a NaN, naming
    ``<node>.<field>``. Fields named ``*_fraction`` must lie in (0, 1]; others are positive numbers,
    and integers at least 1 (``steps`` and ``halve_every``, where 0 means none, at least 0)."""
    for field in dataclasses.fields(settings):
        value = getattr(settings, field.name)
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            continue
        if isinstance(value, int):
            least = 0 if field.name in ("steps", "halve_every") else 1
            if value < least:
                raise ValueError(f"{node}.{field.name} must be an integer >= {least}, got {value!r}")
        elif field.name.endswith("_fraction"):
            if not (math.isfinite(value) and 0.0 < value <= 1.0):
                raise ValueError(f"{node}.{field.name} must be in (0, 1], got {value}")
        elif not (math.isfinite(value) and value >= 0.0) or (value == 0.0 and not field.name.startswith("jitter")):
            raise ValueError(f"{node}.{field.name} must be positive, got {value}")


RENAMED_BUDGET = (
    "attack.budget_evaluations was renamed attack.budget_passes: model passes per init view, every "
    "image the model runs on (screened or exact) and every backward pass counted"
)


def positive_shares(shares) -> bool:
    """Whether every one of ``shares`` is a positive finite number (a bool is not one)."""
    return all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v) and v > 0 for v in shares)


@dataclass(frozen=True)
class AttackConfig:
    """How to search (``conf/attack/``). Angles in degrees, distances in metres.

    Attributes:
        method: a registered search method (:data:`kadv.attack.METHODS`).
        settings: that method's settings dataclass (the ``attack.<method>`` node); None: its defaults.
        budget_passes: model passes per init view, the init view's included: every image the model
            runs on is one pass (exact or screened, any size), and every backward pass through it
            is one more (None: no count limit; a method without a natural end then needs
            ``budget_seconds``). The passes that choose the init views are counted apart.
        budget_seconds: wall-clock seconds per init view (None: no time limit). A batch starts
            only if the previous one's duration still fits, so the count depends on the machine.
        max_angle_deg, max_distance: how far a pose may turn and move from its init view (None:
            unbounded; black-box methods then sample up to 180 degrees and 2 m).
        top_n: adversarial views kept per init view.
        min_separation, min_separation_deg: two adversarial views differ by at least this much
            in centre position or in orientation.
        envelope: bounds on the pose itself (roll, pitch, height; :mod:`kadv.penalties.envelope`),
            a preset's name or an :class:`Envelope`; every method's views are moved into it, and
            those that still lie outside are recorded, never chosen. ``free``: the study's protocol.
        restarts: independent runs of the search per init view, at most, each under an equal share
            of the budgets (:func:`~kadv.attack.restarts.restarted_search`): the search stops once
            two runs' worsts agree, and reports how many runs reached its worst (its agreement).
        agreement_delta1: two runs agree when their worst views' delta1 differ by at most this.
        radius_shares: how a search across nested radii (a profile, ``attack.radii``) splits its
            passes over them, ``budget_passes`` a radius on average: one positive share a radius
            (None: the k-th radius, smallest first, gets k shares, :func:`~kadv.attack.radii.ramp_shares`;
            ``(1, 1, 1)``: equally).
    """

    method: str = DEFAULT_METHOD
    settings: Any = None
    budget_passes: int | None = DEFAULT_PASSES
    budget_seconds: float | None = None
    max_angle_deg: float | None = 45.0
    max_distance: float | None = 1.0
    top_n: int = 5
    min_separation: float = 0.05
    min_separation_deg: float = 3.0
    envelope: Envelope | str = "free"
    restarts: int = 1
    agreement_delta1: float = 0.03
    radius_shares: tuple[float, ...] | None = None
    budget_evaluations: InitVar[int | None] = None  # renamed: refused with the new name

    def __post_init__(self, budget_evaluations: int | None) -> None:
        if budget_evaluations is not None:
            raise ValueError(RENAMED_BUDGET)
        object.__setattr__(self, "envelope", get_envelope(self.envelope))
        method = get_method(self.method)
        if self.settings is None:
            object.__setattr__(self, "settings", method.settings())
        elif not isinstance(self.settings, method.settings):
            raise ValueError(
                f"attack.{self.method}: expected {method.settings.__name__}, got {type(self.settings).__name__}"
            )
        check_settings(self.settings, f"attack.{self.method}")
        if not isinstance(self.top_n, int) or self.top_n < 1:
            raise ValueError(f"attack.top_n must be an integer >= 1, got {self.top_n!r}")
        for name in ("min_separation", "min_separation_deg"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"attack.{name} must be >= 0, got {getattr(self, name)}")
        for name in ("max_angle_deg", "max_distance", "budget_seconds"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"attack.{name} must be positive or null, got {value}")
        if self.budget_passes is not None and (
            isinstance(self.budget_passes, bool) or not isinstance(self.budget_passes, int) or self.budget_passes < 1
        ):
            raise ValueError(f"attack.budget_passes must be an integer >= 1 or null, got {self.budget_passes!r}")
        if self.passes is None and self.budget_seconds is None:
            raise ValueError(f"attack.method={self.method} needs attack.budget_passes or attack.budget_seconds")
        if isinstance(self.restarts, bool) or not isinstance(self.restarts, int) or self.restarts < 1:
            raise ValueError(f"attack.restarts must be an integer >= 1, got {self.restarts!r}")
        if not (math.isfinite(self.agreement_delta1) and 0.0 <= self.agreement_delta1 <= 1.0):
            raise ValueError(f"attack.agreement_delta1 must be in [0, 1], got {self.agreement_delta1}")
        shares = self.radius_shares
        if shares is not None and not (isinstance(shares, tuple) and shares and positive_shares(shares)):
            raise ValueError(f"attack.radius_shares must be null or positive numbers, one a radius, got {shares!r}")
        self.check_run(method.check)

    def check_run(self, check: Any, supersample: int | None = None) -> None:
        """Call a method's ``check`` with one run's share of the passes, the share named in its error."""
        try:
            check(self.settings, self.run_passes, supersample)
        except ValueError as error:
            if self.restarts == 1:
                raise
            share = f"attack.budget_passes={self.passes} split over attack.restarts={self.restarts}"
            raise ValueError(f"{error} ({share}: {self.run_passes} a run)") from None

    @property
    def run_passes(self) -> int | None:
        """Model passes of one of the ``restarts`` runs: an equal share of :attr:`passes`."""
        return None if self.passes is None else self.passes // self.restarts

    def restart_config(self) -> AttackConfig:
        """The config of one run of :attr:`restarts`: its share of the budgets, and no restarts."""
        if self.restarts == 1:
            return self
        seconds = None if self.budget_seconds is None else self.budget_seconds / self.restarts
        return dataclasses.replace(self, budget_passes=self.run_passes, budget_seconds=seconds, restarts=1)

    @property
    def passes(self) -> int | None:
        """Model passes per init view: the budget, or the method's own end (None: unbounded)."""
        natural = get_method(self.method).passes(self.settings)
        if self.budget_passes is None:
            return natural
        return self.budget_passes if natural is None else min(natural, self.budget_passes)

    def space(self, init_fov_deg: float) -> PoseSpace:
        """The space a search moves in around an init view with that horizontal field of view."""
        return PoseSpace(self.max_angle_deg, self.max_distance, self.envelope, init_fov_deg)


class Clock:
    """The pass and seconds budgets of one init view's search.

    The currency is the model pass: each image the model runs on is one forward pass, whatever its
    fidelity, and each backward pass through the model is one more. A batch of views may start
    while the passes it may take fit in the count and, at the last batch's seconds per pass, in
    what is left of ``budget_seconds`` (so a search ends within about one batch of it, and a small
    batch after a large one, a lane's step after a screening, still starts). A ``progress`` bar
    (tqdm), when set, advances by the passes spent.

    Passes are counted in one place, :meth:`charge`: a search scores its views inside it, and the
    block's views and backward passes are counted, and its seconds timed, as it ends.
    """

    def __init__(self, passes: int | None, seconds: float | None, progress: Any = None) -> None:
        self.passes, self.seconds, self.progress = passes, seconds, progress
        self.started = time.perf_counter()
        self.budget = Budget()
        self._pass_seconds = 0.0  # the last batch's seconds per pass
        # seconds per view of the render and of the model passes of the last batch evaluated ``timed``
        self.render_s = self.model_s = 0.0

    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def remaining(self) -> int:
        """Passes the count budget still allows (a large number when it has none)."""
        return (self.passes if self.passes is not None else 2**31) - self.budget.passes

    def allows(self, count: int, cost: int = 1) -> int:
        """How many of ``count`` views may be scored now, each taking up to ``cost`` passes (2: a
        forward and a backward pass); 0: the search is over."""
        count = min(count, self.remaining() // cost)
        if self.seconds is not None and self._pass_seconds > 0.0:
            left = self.seconds - self.elapsed()
            count = min(count, max(0, math.floor(left / (self._pass_seconds * cost))))
        return max(count, 0)

    @contextlib.contextmanager
    def charge(self, views: int, backward: int = 0, screened: bool = False) -> Iterator[Charge]:
        """Count a batch of ``views`` forward passes (``screened``: at a cheap fidelity) and
        ``backward`` backward passes, scored inside the block, when it ends; the block may set the
        :class:`Charge`'s ``backward`` once it knows how many views it back-propagated."""
        charge = Charge(views, backward, screened)
        started = time.perf_counter()
        yield charge
        self.budget.forward += charge.views
        self.budget.screened += charge.views if charge.screened else 0
        self.budget.backward += charge.backward
        self._pass_seconds = (time.perf_counter() - started) / max(charge.views + charge.backward, 1)
        if self.progress is not None:
            self.progress.update(charge.views + charge.backward)


@dataclass
class Charge:
    """What a :meth:`Clock.charge` block spends: forward passes (``views``; ``screened``: at a cheap
    fidelity) and backward passes."""

    views: int
    backward: int = 0
    screened: bool = False


@dataclass
class Measures:
    """The measures of B views of one step, on the device where they were computed, until
    :meth:`records` reads them to the host (a gradient run does so once it ends).

    Attributes:
        step: the step.
        lanes: each view's lane.
        table: (B, dims + 20 or dims + 23) float64: params (dims), the rotation matrix (9,
            row-major: its rotation vector is computed on the host, where its hundred-odd small
            operations cost no launches), centre (3), the horizontal field of view, L_depth, loss,
            L_dist, objective, delta1, AbsRel, the guard's fraction, and the warp's coverage, rgb
            and depth errors when the views were rendered through the warp.
        validity: the views' validity (its verdicts are made when read).
        refreshed: whether the anchor was rendered again at this step.
        seconds: the search's clock when the step was measured.
        scale: the render's size relative to the run's.
        passes: the model passes the search had spent once these views were scored.
        screened: scored at a search's cheap fidelity (never chosen or followed).
        dims: the coordinates of a point of the pose space (:class:`~kadv.attack.space.PoseSpace`).
    """

    step: int
    lanes: list[int]
    table: torch.Tensor
    validity: ViewValidity
    refreshed: bool
    seconds: float
    scale: float
    passes: int = 0
    screened: bool = False
    dims: int = 6

    def records(self) -> list[ViewRecord]:
        """One :class:`ViewRecord` per view."""
        table = self.table.cpu()
        d = self.dims
        rotation = table[:, d : d + 9].reshape(-1, 3, 3)
        theta = matrix_to_axis_angle(rotation)
        rows = torch.cat([table[:, :d], theta, table[:, d + 9 :]], dim=1).tolist()
        angles = torch.rad2deg(yaw_pitch_roll(rotation)).tolist()
        verdicts = self.validity.verdicts
        records = []
        for b, (lane, row, (yaw, pitch, roll)) in enumerate(zip(self.lanes, rows, angles)):
            fov, l_depth, loss, l_dist, objective, delta1, abs_rel, fraction = row[d + 6 : d + 14]
            coverage, rgb_error, depth_error = row[d + 14 : d + 17] if len(row) > d + 14 else (math.nan,) * 3
            records.append(
                ViewRecord(
                    step=self.step,
                    restart=lane,
                    params=row[0:d],
                    theta=row[d : d + 3],
                    centre=row[d + 3 : d + 6],
                    fov_x_deg=fov,
                    l_depth=l_depth,
                    loss=loss,
                    l_dist=l_dist,
                    objective=objective,
                    delta1=delta1,
                    abs_rel=abs_rel,
                    verdict=verdicts[b],
                    guard_fraction=fraction,
                    coverage=coverage,
                    rgb_error=rgb_error,
                    depth_error=depth_error,
                    refreshed=self.refreshed,
                    seconds=self.seconds,
                    passes=self.passes,
                    scale=self.scale,
                    screened=self.screened,
                    yaw_deg=yaw,
                    pitch_deg=pitch,
                    roll_deg=roll,
                )
            )
        return records


class SearchContext:
    """Everything needed to evaluate views around one init view.

    Args:
        objective: the objective (it holds the model, the loss and the exact renderer).
        differentiable: the differentiable renderer (its exact renderer must be the objective's).
        init: the init view.
        height: image height.
        width: image width.
        config: the attack's settings (bounds, budgets).
        starts: warm starts, points (N, dims) of the pose space (views found bad
            before: at a smaller radius, by another search); methods that take them
            (``halving``) score them exactly first, the others leave them.
    """

    def __init__(
        self,
        objective: Objective,
        differentiable: DifferentiableRenderer,
        init: InitView,
        height: int,
        width: int,
        config: AttackConfig,
        starts: torch.Tensor | None = None,
    ) -> None:
        self.objective = objective
        self.differentiable = differentiable
        self.renderer = differentiable.renderer
        # where poses live: the differentiable render's device, so that a step reads nothing back
        self.device = differentiable.device
        self.init = init
        self._base = init.world_T_cam.double().to(self.device, non_blocking=True)
        self.config = config
        self.height, self.width = height, width
        self.space = config.space(init.fov_x_deg)
        self.K = self.space.intrinsics(None, height, width)  # the init view's
        self.margin = objective.penalty.margin
        self.validity_options = objective.penalty.validity_options()
        self.clock = Clock(config.passes, config.budget_seconds)
        dims = self.space.dims
        self.starts = self.space.zeros(0) if starts is None else starts.double().reshape(-1, dims)

    def base(self, batch: int) -> torch.Tensor:
        """The init view's pose (batch, 4, 4) float64 on :attr:`device`."""
        return self._base[None].expand(batch, 4, 4)

    def differentiable_at(self, supersample: int | None) -> DifferentiableRenderer:
        """The differentiable renderer at ``supersample`` rays per pixel side (None: the run's): a
        cheap fidelity gets a renderer of its own (its own anchor), on the same scene and device."""
        if supersample is None or supersample == self.differentiable.config.supersample:
            return self.differentiable
        config = dataclasses.replace(self.differentiable.config, supersample=supersample)
        return DifferentiableRenderer(self.renderer, config, self.device)

    def differentiable_terms(
        self, differentiable: DifferentiableRenderer, params: torch.Tensor
    ) -> tuple[DiffRenderOutput, ObjectiveTerms]:
        """The differentiable render of points ``params`` (B, dims) at the run's size and the
        objective's terms there, differentiable in the points (the field of view's through the
        intrinsics)."""
        K = self.size(1.0, params)[0]
        out = differentiable(params[:, :FOV], self.base(len(params)), K, self.height, self.width)
        return out, self.objective(out.rgb, out.depth, out.mask, out.world_T_cam, K)

    def project(self, params: torch.Tensor) -> torch.Tensor:
        """Points (B, dims) pulled back within the bounds, then moved into the envelope
        (:meth:`PoseSpace.project`); the step guard has yet to pass the move."""
        return self.space.project(self.renderer, self.base(len(params)), params)

    def guard(self, old: torch.Tensor, new: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Let the centre offsets (B, 3) move from ``old`` to ``new`` only as far as the step guard
        allows (:meth:`PoseSpace.guard`); the offsets reached and the fraction of each move taken
        (B,), on :attr:`device`."""
        old, new = old.to(self.device), new.to(self.device)
        return self.space.guard(self.renderer, self._base[:3, 3], old, new, self.margin)

    def measure(
        self,
        step: int,
        params: torch.Tensor,
        world_T_cam: torch.Tensor,
        terms: ObjectiveTerms,
        guard_fraction: torch.Tensor,
        stats: tuple[torch.Tensor, ...] | None = None,
        refreshed: bool = False,
        lanes: list[int] | range | None = None,
        render: RenderOutput | None = None,
        scale: float = 1.0,
        screened: bool = False,
    ) -> Measures:
        """What the records of B views will hold, left where it was computed (see :class:`Measures`):
        the view's validity (from ``render``, the views' render, when given, at ``scale`` times the
        run's size; ``screened``: at a cheap fidelity) and the search's clock."""
        pose = world_T_cam.detach()
        K, height, width = self.size(scale, params.detach())
        validity = view_validity(self.renderer, pose, K, height, width, render=render, **self.validity_options)
        if not self.config.envelope.free:
            validity.envelope = self.config.envelope.figures(self.renderer, pose)
        numbers = [
            params.detach(),
            pose[:, :3, :3].flatten(1),
            pose[:, :3, 3],
            self.space.fov_deg(params.detach())[:, None],
            *(value.detach()[:, None] for value in (terms.l_depth, terms.loss, terms.l_dist, terms.objective)),
            terms.delta1[:, None],
            terms.abs_rel[:, None],
            guard_fraction[:, None],
            *(s[:, None] for s in stats or ()),
        ]
        device = params.device
        table = torch.cat([n.to(device, torch.float64, non_blocking=True) for n in numbers], dim=1)
        lanes = list(lanes) if lanes is not None else list(range(len(pose)))
        passes = self.clock.budget.passes + len(pose)  # this batch's forward passes are done
        elapsed = self.clock.elapsed()
        return Measures(step, lanes, table, validity, refreshed, elapsed, scale, passes, screened, self.space.dims)

    def records(self, *args, **kwargs) -> list[ViewRecord]:
        """One :class:`ViewRecord` per view: :meth:`measure`'s arguments, read to the host at once."""
        return self.measure(*args, **kwargs).records()

    def size(self, scale: float = 1.0, params: torch.Tensor | None = None) -> tuple[torch.Tensor, int, int]:
        """Intrinsics, height and width of renders at ``scale`` times the run's size: of points
        ``params`` (B, dims) (:meth:`PoseSpace.intrinsics`: the init view's (3, 3) when the
        field of view is fixed or ``params`` is None)."""
        if scale == 1.0 and (params is None or not self.space.fov_searched):
            return self.K, self.height, self.width
        height, width = scaled_size(self.height, self.width, scale)
        return self.space.intrinsics(params, height, width), height, width

    def evaluate(
        self,
        step: int,
        params: torch.Tensor,
        lanes: list[int] | range | None = None,
        scale: float = 1.0,
        supersample: int | None = None,
        screened: bool = False,
        timed: bool = False,
    ) -> list[ViewRecord]:
        """Move from the init view to each point (B, dims) through the step guard, then :meth:`score`
        the poses reached."""
        with self.clock.charge(len(params), screened=screened):
            params = self.project(params.to(self.device))
            reached, fraction = self.guard(torch.zeros_like(params[:, 3:6]), params[:, 3:6])
            params = torch.cat([params[:, :3], reached, params[:, FOV:]], dim=1)
            return self._scored(step, params, fraction, lanes, scale, supersample, screened, timed)

    def score(
        self,
        step: int,
        params: torch.Tensor,
        fraction: torch.Tensor,
        lanes: list[int] | range | None = None,
        scale: float = 1.0,
        supersample: int | None = None,
        screened: bool = False,
        timed: bool = False,
    ) -> list[ViewRecord]:
        """Render points (B, dims) already through the step guard (``fraction``: the share of each move
        taken) exactly at ``scale`` times the run's size (with ``supersample`` rays per pixel side;
        None: the run's), evaluate and record, one model pass a view (``screened``: at a cheap
        fidelity, never ranked: :meth:`screen`). ``timed``: the render's and the model's seconds per
        view go to the clock (each waits for the device, so only where a search asks for them)."""
        with self.clock.charge(len(params), screened=screened):
            return self._scored(step, params, fraction, lanes, scale, supersample, screened, timed)

    def _scored(
        self,
        step: int,
        params: torch.Tensor,
        fraction: torch.Tensor,
        lanes: list[int] | range | None,
        scale: float,
        supersample: int | None,
        screened: bool,
        timed: bool,
    ) -> list[ViewRecord]:
        """:meth:`score`'s work, inside a charge of the clock's."""
        params = params.to(self.device)
        K, height, width = self.size(scale, params)
        supersample = supersample or self.differentiable.config.supersample
        with torch.no_grad():
            pose = perturb_world_T_cam(self.base(len(params)), params[:, :3], params[:, 3:6])
            rendering = self._now() if timed else 0.0
            out = self.renderer.render(pose, K, height, width, supersample=supersample)
            modelling = self._now() if timed else 0.0
            terms = self.objective(out.rgb, out.depth, out.mask, pose, K)
            if timed:
                self.clock.render_s = (modelling - rendering) / len(pose)
                self.clock.model_s = (self._now() - modelling) / len(pose)
        return self.records(
            step, params, pose, terms, fraction, lanes=lanes, render=out, scale=scale, screened=screened
        )

    def _now(self) -> float:
        """The clock, once the device's queued work is done (a GPU's work runs after its call returns)."""
        if self.device.type == "cuda":
            torch.cuda.synchronize(self.device)
        return time.perf_counter()

    def screen(
        self, step: int, params: torch.Tensor, supersample: int | None, batch: int, bar: Any = None
    ) -> list[ViewRecord]:
        """:meth:`evaluate` points (N, dims), ``batch`` views a render, while the budget allows: at the
        cheap fidelity of ``supersample`` rays per pixel side (screened records, never ranked), or
        exactly when ``supersample`` is None. Each view is a model pass like any other
        (``budget.screened`` counts the cheap ones). A progress ``bar`` shows the count meanwhile."""
        records: list[ViewRecord] = []
        for chunk in params.split(batch):
            count = self.clock.allows(len(chunk))
            if count == 0:
                break
            records += self.evaluate(step, chunk[:count], supersample=supersample, screened=supersample is not None)
            if bar is not None:  # "screened" as in the budget's count: at the cheap fidelity only
                bar.set_postfix_str(f"{'scored' if supersample is None else 'screened'} {len(records)}/{len(params)}")
        return records

    def result(self, records: list[ViewRecord], path: list[ViewRecord]) -> InitViewResult:
        """The search's result: its records, the adversarial views chosen from them, the budget
        spent (seconds included) and the path a report follows."""
        self.clock.budget.seconds = self.clock.elapsed()
        top = select_top_views(records, self.config.top_n, self.config.min_separation, self.config.min_separation_deg)
        return InitViewResult(self.init, records, top, self.clock.budget, path)
