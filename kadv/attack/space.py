"""The space a search moves in around one init view: the parameters, their bounds, the envelope,
how black-box methods sample them, and the camera each point is.

A point is (omega (3), delta (3)) relative to the init view's pose
(:func:`kadv.geometry.perturb_world_T_cam`: a rotation vector in the camera frame and a centre
offset in world metres) and, when ``envelope.fov_deg`` frees the field of view, a seventh
coordinate: the horizontal field of view's offset from the init view's, in degrees. Zero is the
init view itself.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch
from scipy.stats import qmc

from kadv.geometry import fov_intrinsics, intrinsics_from_fov
from kadv.penalties.envelope import Envelope
from kadv.penalties.guard import step_guard
from kadv.render.exact import ExactRenderer

__all__ = ["FOV", "PoseSpace"]

FOV = 6  # the index of the field of view's coordinate, when it is searched


@dataclass(frozen=True)
class PoseSpace:
    """Where a search may go from one init view (see the module docstring).

    Attributes:
        max_angle_deg, max_distance: how far a pose may turn and move from the init view (None:
            unbounded; black-box methods then sample up to 180 degrees and 2 m).
        envelope: bounds on the pose itself, and the field of view's range (``fov_deg``).
        init_fov_deg: the init view's horizontal field of view, degrees.
    """

    max_angle_deg: float | None
    max_distance: float | None
    envelope: Envelope
    init_fov_deg: float

    @property
    def fov_searched(self) -> bool:
        """Whether the search sets the field of view (``envelope.fov_deg``)."""
        return self.envelope.fov_deg is not None

    @property
    def dims(self) -> int:
        """Coordinates of a point: 6, or 7 with the field of view searched."""
        return FOV + self.fov_searched

    def zeros(self, count: int = 1) -> torch.Tensor:
        """``count`` copies (count, dims) of the init view."""
        return torch.zeros(count, self.dims, dtype=torch.float64)

    def _fov_offsets(self) -> tuple[float, float]:
        """The field of view's coordinate range: the envelope's, widened to hold the init view's own."""
        low, high = self.envelope.fov_deg
        return min(low, self.init_fov_deg) - self.init_fov_deg, max(high, self.init_fov_deg) - self.init_fov_deg

    def box(self) -> tuple[torch.Tensor, torch.Tensor]:
        """The region black-box methods sample, as centre and half-widths (dims,): the rotation and
        distance bounds about the init view, and the envelope's field-of-view range."""
        rotation = math.radians(self.max_angle_deg if self.max_angle_deg is not None else 180.0)
        translation = self.max_distance if self.max_distance is not None else 2.0
        half = [rotation] * 3 + [translation] * 3
        centre = [0.0] * 6
        if self.fov_searched:
            low, high = (f - self.init_fov_deg for f in self.envelope.fov_deg)
            half.append((high - low) / 2.0)
            centre.append((high + low) / 2.0)
        return torch.tensor(centre, dtype=torch.float64), torch.tensor(half, dtype=torch.float64)

    def from_box(self, unit: torch.Tensor) -> torch.Tensor:
        """Points (N, dims) of the box for coordinates ``unit`` (N, dims) in [-1, 1]."""
        centre, half = self.box()
        return centre + unit * half if self.fov_searched else unit * half

    def to_box(self, params: torch.Tensor) -> torch.Tensor:
        """The box coordinates (N, dims) in [-1, 1] of points (N, dims), clamped to the box."""
        centre, half = self.box()
        return ((params - centre) / half).clamp(-1.0, 1.0)

    def sample(self, unit: np.ndarray) -> torch.Tensor:
        """Map points (N, dims) of the unit cube [0, 1)^dims onto points spread uniformly over the
        two balls of the bounds (rotation vector, centre offset) and the field of view's range:
        a uniform or space-filling design stays one."""
        centre, half = self.box()
        parts = []
        for k, radius in ((0, half[0]), (3, half[3])):
            # three independent coordinates: radius from one, direction from two (Archimedes' projection)
            r = unit[:, k] ** (1.0 / 3.0) * float(radius)
            z = 2.0 * unit[:, k + 1] - 1.0
            phi = 2.0 * math.pi * unit[:, k + 2]
            s = np.sqrt(np.clip(1.0 - z * z, 0.0, None))
            parts.append(np.stack([r * s * np.cos(phi), r * s * np.sin(phi), r * z], axis=1))
        if self.fov_searched:  # uniform over the range
            parts.append(float(centre[FOV]) + (2.0 * unit[:, FOV : FOV + 1] - 1.0) * float(half[FOV]))
        return torch.from_numpy(np.concatenate(parts, axis=1))

    def sobol(self, count: int, rng: np.random.Generator) -> torch.Tensor:
        """``count`` points (count, dims) spread over the space: the first points of a scrambled
        Sobol sequence drawn from ``rng`` (a power of two of them keeps its balance), through
        :meth:`sample`."""
        unit = qmc.Sobol(d=self.dims, scramble=True, rng=rng).random_base2(math.ceil(math.log2(count)))[:count]
        return self.sample(unit)

    def bound(self, params: torch.Tensor) -> torch.Tensor:
        """Points (B, dims) pulled back within the rotation-angle and distance bounds, and the
        field of view within its range (widened to hold the init view's)."""
        omega, delta = params[:, :3], params[:, 3:6]
        if self.max_angle_deg is not None:
            omega = omega * (math.radians(self.max_angle_deg) / omega.norm(dim=1, keepdim=True).clamp_min(1e-12)).clamp(
                max=1.0
            )
        if self.max_distance is not None:
            delta = delta * (self.max_distance / delta.norm(dim=1, keepdim=True).clamp_min(1e-12)).clamp(max=1.0)
        if not self.fov_searched:
            return torch.cat([omega, delta], dim=1)
        return torch.cat([omega, delta, params[:, FOV:].clamp(*self._fov_offsets())], dim=1)

    def project(self, renderer: ExactRenderer, base: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
        """Points (B, dims) :meth:`bound`, then moved into the envelope (on the points' device);
        the step guard has yet to pass the move."""
        params = self.bound(params)
        pose = self.envelope.project(renderer, base, params[:, :6])
        return torch.cat([pose, params[:, FOV:]], dim=1) if self.fov_searched else pose

    def guard(
        self, renderer: ExactRenderer, centre: torch.Tensor, old: torch.Tensor, new: torch.Tensor, margin: float
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Let centre offsets (B, 3) from the init view's ``centre`` (3,) move from ``old`` to
        ``new`` only as far as the step guard allows (:func:`kadv.penalties.step_guard`, ``margin``
        clear of every surface): a refused move is shortened to the guard's clear fraction and, if
        that is still refused, the camera stays. Returns the offsets reached and the fraction of
        each move taken (B,)."""
        check = step_guard(renderer, centre + old, centre + new, margin)
        fraction = torch.where(check.allowed, torch.ones_like(check.max_fraction), check.max_fraction)
        shortened = old + fraction[:, None] * (new - old)
        # every move is checked again, the allowed ones too: deciding which to check would read the
        # verdicts back from the device
        again = step_guard(renderer, centre + old, centre + shortened, margin)
        fraction = torch.where(check.allowed | again.allowed, fraction, torch.zeros_like(fraction))
        return old + fraction[:, None] * (new - old), fraction

    def fov_deg(self, params: torch.Tensor) -> torch.Tensor:
        """The horizontal field of view (B,) float64, degrees, of points (B, dims)."""
        if not self.fov_searched:
            return torch.full((len(params),), self.init_fov_deg, dtype=torch.float64, device=params.device)
        return self.init_fov_deg + params[:, FOV].double()

    def intrinsics(self, params: torch.Tensor | None, height: int, width: int) -> torch.Tensor:
        """Intrinsics of images ``height`` x ``width`` of points (B, dims): the init view's (3, 3)
        when the field of view is not searched (or ``params`` is None), else (B, 3, 3),
        differentiable in the field of view's coordinate."""
        if not self.fov_searched or params is None:
            return intrinsics_from_fov(self.init_fov_deg, height, width)
        return fov_intrinsics(self.fov_deg(params), height, width)
