"""What every search method shares: its settings, pose bounds, the guarded move, view evaluation
and recording."""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from kadv.attack.init_views import InitView
from kadv.attack.objective import Objective, ObjectiveTerms
from kadv.attack.records import ViewRecord
from kadv.geometry import intrinsics_from_fov, matrix_to_axis_angle, perturb_world_T_cam
from kadv.penalties import step_guard, view_validity
from kadv.render import DifferentiableRenderer, RenderOutput

__all__ = ["METHODS", "AttackConfig", "SearchContext"]

METHODS = ("gradient", "random", "cma")


@dataclass(frozen=True)
class AttackConfig:
    """How to search (``conf/attack/``). Angles in degrees, distances in metres.

    Attributes:
        method: "gradient" (Adam through the differentiable renderer), "random" or "cma".
        steps: gradient steps per restart (each restart evaluates steps + 1 views).
        restarts: gradient runs per init view, batched; restart 0 starts at the init view, the
            others from seeded pose jitter.
        lr_rotation: Adam learning rate of the rotation vector (radians).
        lr_translation: Adam learning rate of the centre offset (metres).
        jitter_deg, jitter_distance: largest rotation and centre offset of a restart's start.
        max_angle_deg, max_distance: how far a pose may move from its init view (None: unbounded).
        top_n: adversarial views kept per init view.
        min_separation, min_separation_deg: two adversarial views differ by at least this much
            in centre position or in orientation.
        population: views per batch of the black-box methods.
        cma_sigma: CMA-ES initial step size, as a fraction of the search box.
        budget_evaluations: black-box evaluations per init view; None: the gradient method's
            forward passes, restarts * (steps + 1).
        budget_seconds: black-box seconds per init view (None: no time limit).
    """

    method: str = "gradient"
    steps: int = 30
    restarts: int = 3
    lr_rotation: float = 0.02
    lr_translation: float = 0.03
    jitter_deg: float = 3.0
    jitter_distance: float = 0.05
    max_angle_deg: float | None = 45.0
    max_distance: float | None = 1.0
    top_n: int = 5
    min_separation: float = 0.05
    min_separation_deg: float = 3.0
    population: int = 8
    cma_sigma: float = 0.3
    budget_evaluations: int | None = None
    budget_seconds: float | None = None

    def __post_init__(self) -> None:
        if self.method not in METHODS:
            raise ValueError(f"attack.method must be one of {', '.join(METHODS)}, got {self.method!r}")
        for name in ("steps", "restarts", "top_n", "population"):
            value = getattr(self, name)
            if not isinstance(value, int) or value < (0 if name == "steps" else 1):
                raise ValueError(f"attack.{name} must be an integer >= {0 if name == 'steps' else 1}, got {value!r}")
        for name in ("lr_rotation", "lr_translation", "cma_sigma"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) > 0):
                raise ValueError(f"attack.{name} must be positive, got {getattr(self, name)}")
        for name in ("jitter_deg", "jitter_distance", "min_separation", "min_separation_deg"):
            if not (math.isfinite(getattr(self, name)) and getattr(self, name) >= 0):
                raise ValueError(f"attack.{name} must be >= 0, got {getattr(self, name)}")
        for name in ("max_angle_deg", "max_distance", "budget_seconds"):
            value = getattr(self, name)
            if value is not None and not (math.isfinite(value) and value > 0):
                raise ValueError(f"attack.{name} must be positive or null, got {value}")
        if self.budget_evaluations is not None and self.budget_evaluations < 1:
            raise ValueError(f"attack.budget_evaluations must be >= 1 or null, got {self.budget_evaluations}")

    @property
    def evaluations(self) -> int:
        """Black-box evaluations per init view."""
        return self.budget_evaluations or self.restarts * (self.steps + 1)

    def search_box(self) -> torch.Tensor:
        """Half-widths (6,) of the pose box a gradient run may reach: its bounds, or Adam's reach
        (a learning rate per step) where it is unbounded or reaches less far."""
        rotation = self.lr_rotation * max(self.steps, 1)
        translation = self.lr_translation * max(self.steps, 1)
        if self.max_angle_deg is not None:
            rotation = min(rotation, math.radians(self.max_angle_deg))
        if self.max_distance is not None:
            translation = min(translation, self.max_distance)
        return torch.tensor([rotation] * 3 + [translation] * 3, dtype=torch.float64)

    def project(self, params: torch.Tensor) -> torch.Tensor:
        """Pull pose parameters (B, 6) back within the rotation-angle and distance bounds."""
        omega, delta = params[:, :3], params[:, 3:]
        if self.max_angle_deg is not None:
            omega = omega * (math.radians(self.max_angle_deg) / omega.norm(dim=1, keepdim=True).clamp_min(1e-12)).clamp(max=1.0)
        if self.max_distance is not None:
            delta = delta * (self.max_distance / delta.norm(dim=1, keepdim=True).clamp_min(1e-12)).clamp(max=1.0)
        return torch.cat([omega, delta], dim=1)


class SearchContext:
    """Everything needed to evaluate views around one init view.

    Args:
        objective: the objective (it holds the model, the loss and the exact renderer).
        differentiable: the differentiable renderer (its exact renderer must be the objective's).
        init: the init view.
        height, width: image size.
    """

    def __init__(self, objective: Objective, differentiable: DifferentiableRenderer, init: InitView, height: int,
                 width: int) -> None:
        self.objective = objective
        self.differentiable = differentiable
        self.renderer = differentiable.renderer
        self.init = init
        self.height, self.width = height, width
        self.K = intrinsics_from_fov(init.fov_x_deg, height, width)
        self.margin = objective.penalty.margin
        self.validity_options = objective.penalty.validity_options()

    def base(self, batch: int) -> torch.Tensor:
        return self.init.world_T_cam.double()[None].expand(batch, 4, 4)

    def guard(self, old: torch.Tensor, new: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        """Let the centre offsets (B, 3) move from ``old`` to ``new`` only as far as the step guard allows.

        A refused move is shortened to the guard's clear fraction; if that is still refused, the
        camera stays. Returns the offsets reached and the fraction of each move taken (B,).
        """
        c0 = self.init.world_T_cam[:3, 3].double()
        check = step_guard(self.renderer, c0 + old, c0 + new, self.margin)
        fraction = torch.where(check.allowed, torch.ones_like(check.max_fraction), check.max_fraction)
        shortened = old + fraction[:, None] * (new - old)
        refused = ~check.allowed
        if bool(refused.any()):
            again = step_guard(self.renderer, c0 + old[refused], c0 + shortened[refused], self.margin)
            fraction[refused] = torch.where(again.allowed, fraction[refused], torch.zeros_like(fraction[refused]))
            shortened = old + fraction[:, None] * (new - old)
        return shortened, fraction

    def records(self, step: int, params: torch.Tensor, world_T_cam: torch.Tensor, terms: ObjectiveTerms,
                guard_fraction: torch.Tensor, stats: tuple[torch.Tensor, ...] | None = None,
                refreshed: bool = False, lanes: range | None = None,
                render: RenderOutput | None = None) -> list[ViewRecord]:
        """One :class:`ViewRecord` per view, with the view's validity verdict (from ``render``, the
        views' exact render, when given)."""
        pose = world_T_cam.detach()
        validity = view_validity(self.renderer, pose, self.K, self.height, self.width, render=render,
                                 **self.validity_options)
        theta = matrix_to_axis_angle(pose[:, :3, :3])
        lanes = lanes or range(len(pose))
        rows = []
        for b, lane in enumerate(lanes):
            coverage, rgb_error, depth_error = (float(s[b]) for s in stats) if stats else (math.nan,) * 3
            rows.append(ViewRecord(
                step=step, restart=lane, params=params[b].detach().tolist(), theta=theta[b].tolist(),
                centre=pose[b, :3, 3].tolist(), l_depth=float(terms.l_depth[b].detach()), l_dist=float(terms.l_dist[b].detach()),
                objective=float(terms.objective[b].detach()), delta1=float(terms.delta1[b]), abs_rel=float(terms.abs_rel[b]),
                verdict=validity.verdicts[b], guard_fraction=float(guard_fraction[b]), coverage=coverage,
                rgb_error=rgb_error, depth_error=depth_error, refreshed=refreshed))
        return rows

    def evaluate_exact(self, params: torch.Tensor) -> tuple[torch.Tensor, ObjectiveTerms, RenderOutput]:
        """Poses (B, 4, 4), objective terms and exact renders of views (no gradient)."""
        with torch.no_grad():
            pose = perturb_world_T_cam(self.base(len(params)), params[:, :3], params[:, 3:])
            out = self.renderer.render(pose, self.K, self.height, self.width,
                                       supersample=self.differentiable.config.supersample)
            return pose, self.objective(out.rgb, out.depth, out.mask, pose), out
