"""Camera envelopes: bounds on the pose itself, so that every searched view is one a real camera
takes (a phone held upright, a robot's mast camera), whatever the search's rotation and distance
bounds around the init view allow.

An envelope bounds the roll (about the optical axis), the pitch (the optical axis's elevation above
the horizon) and the optical centre's height above the first surface straight below it; the yaw
stays free. Angles follow :func:`kadv.geometry.yaw_pitch_roll` in kadv's y-up world.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import torch

from kadv.checks import check_shape
from kadv.geometry import (
    axis_angle_to_matrix,
    matrix_to_axis_angle,
    rc_from_world_T_cam,
    rotation_from_yaw_pitch_roll,
    yaw_pitch_roll,
)
from kadv.render.exact import ExactRenderer

__all__ = ["ENVELOPES", "OUTSIDE_ENVELOPE", "Envelope", "EnvelopeFigures", "get_envelope"]

OUTSIDE_ENVELOPE = "outside the envelope"
_SLACK_DEG, _SLACK_M = 1e-5, 1e-5  # what rounding moves a pose projected onto a bound


@dataclass(frozen=True)
class Envelope:
    """Bounds on camera poses (``conf/envelope/``); None leaves a quantity free.

    Attributes:
        name: the preset's name, or "custom".
        max_roll_deg: the roll may not exceed this in magnitude, degrees.
        pitch_deg: (lowest, highest) pitch, degrees above the horizon.
        height: (lowest, highest) height of the optical centre above the first surface straight
            below it, metres.
        fov_deg: (lowest, highest) horizontal field of view, degrees, that the search may set
            (square pixels, centred principal point; :class:`kadv.attack.PoseSpace`); None: each
            view keeps its init view's. The init view itself keeps its own.
    """

    name: str = "free"
    max_roll_deg: float | None = None
    pitch_deg: tuple[float, float] | None = None
    height: tuple[float, float] | None = None
    fov_deg: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        if self.max_roll_deg is not None and not (math.isfinite(self.max_roll_deg) and 0 <= self.max_roll_deg <= 180):
            raise ValueError(f"envelope.max_roll_deg must be in [0, 180] or null, got {self.max_roll_deg}")
        for key, bounds, span, within in (
            ("pitch_deg", self.pitch_deg, "[-90, 90]", lambda low, high: -90 <= low and high <= 90),
            ("height", self.height, ">= 0", lambda low, high: low >= 0),
            # a pinhole's field of view lies strictly between 0 and 180 degrees; kadv keeps off both ends
            ("fov_deg", self.fov_deg, "(1, 179)", lambda low, high: 1 < low and high < 179),
        ):
            if bounds is None:
                continue
            if (
                not isinstance(bounds, (tuple, list))
                or len(bounds) != 2
                or not all(isinstance(b, (int, float)) and math.isfinite(b) for b in bounds)
            ):
                raise ValueError(f"envelope.{key} must be [lowest, highest] or null, got {bounds!r}")
            low, high = bounds
            if low > high or not within(low, high):
                raise ValueError(f"envelope.{key} [{low}, {high}] is empty or leaves {span}")
            object.__setattr__(self, key, (float(low), float(high)))

    @property
    def free(self) -> bool:
        """Whether the envelope bounds no pose (roll, pitch, height); the field of view aside."""
        return self.max_roll_deg is None and self.pitch_deg is None and self.height is None

    def describe(self) -> str:
        """The bounds in words, e.g. ``upright (roll within ±5°, pitch -30° to 30°)``."""
        parts = []
        if self.max_roll_deg is not None:
            parts.append(f"roll within ±{self.max_roll_deg:g}°")
        if self.pitch_deg is not None:
            parts.append(f"pitch {self.pitch_deg[0]:g}° to {self.pitch_deg[1]:g}°")
        if self.height is not None:
            parts.append(f"height {self.height[0]:g} to {self.height[1]:g} m")
        if self.fov_deg is not None:
            parts.append(f"field of view {self.fov_deg[0]:g}° to {self.fov_deg[1]:g}°")
        return f"{self.name} ({', '.join(parts) or 'any pose'})"

    def figures(self, renderer: ExactRenderer, world_T_cam: torch.Tensor) -> EnvelopeFigures:
        """The quantities the envelope bounds, for poses (B, 4, 4), on the poses' device."""
        check_shape(world_T_cam, "B 4 4", "world_T_cam")
        rotation, centre = rc_from_world_T_cam(world_T_cam.detach())
        angles = yaw_pitch_roll(rotation.double())
        height = _height(renderer, centre) if self.height is not None else torch.full_like(angles[:, 0], math.nan)
        return EnvelopeFigures(self, angles, height)

    def project(self, renderer: ExactRenderer, base: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
        """Pose parameters (B, 6) relative to ``base`` (B, 4, 4) (:func:`kadv.geometry.perturb_world_T_cam`)
        moved into the envelope: pitch and roll clamped to their bounds at the same yaw, the centre
        moved straight up or down into the height bounds. Rows inside it (to the rounding a projected
        pose carries) come back unchanged, bit for bit, so projecting twice moves nothing more; a
        centre with no surface below it stays (its view is judged outside the envelope)."""
        if self.free:
            return params
        omega, delta = params[:, :3], params[:, 3:]
        rotation0, centre0 = rc_from_world_T_cam(base.to(params))
        rotation = rotation0 @ axis_angle_to_matrix(omega)
        angles = yaw_pitch_roll(rotation)
        clamped = angles.clone()
        if self.pitch_deg is not None:
            clamped[:, 1] = angles[:, 1].clamp(math.radians(self.pitch_deg[0]), math.radians(self.pitch_deg[1]))
        if self.max_roll_deg is not None:
            limit = math.radians(self.max_roll_deg)
            clamped[:, 2] = angles[:, 2].clamp(-limit, limit)
        turned = ((clamped - angles).abs() > math.radians(_SLACK_DEG)).any(dim=1, keepdim=True)
        inside = matrix_to_axis_angle(rotation0.transpose(1, 2) @ rotation_from_yaw_pitch_roll(clamped))
        omega = torch.where(turned, inside, omega)
        if self.height is not None:
            centre = centre0 + delta
            height = _height(renderer, centre).to(params)
            wanted = height.clamp(*self.height)
            lift = torch.where(torch.isfinite(height), wanted - height, torch.zeros_like(height))
            delta = torch.where((lift.abs() > _SLACK_M)[:, None], delta + lift[:, None] * _UP.to(params), delta)
        return torch.cat([omega, delta], dim=1)


_UP = torch.tensor([0.0, 1.0, 0.0], dtype=torch.float64)


def _height(renderer: ExactRenderer, centre: torch.Tensor) -> torch.Tensor:
    """(B,) distance from each centre (B, 3) straight down to the first surface (inf: none), float64."""
    origins = centre.detach().to(renderer.device, torch.float64)
    hits = renderer.cast(origins, (-_UP).to(origins).expand_as(origins))
    return hits.t.double().to(centre.device)


@dataclass
class EnvelopeFigures:
    """What an envelope bounds, for B views, on their device; judged on the host when read.

    Attributes:
        envelope: the bounds.
        angles: (B, 3) yaw, pitch and roll, radians.
        height: (B,) metres above the first surface straight below (inf: none; NaN: not measured).
    """

    envelope: Envelope
    angles: torch.Tensor
    height: torch.Tensor

    def reasons(self) -> list[str | None]:
        """Per view, why it lies outside the envelope, or None where it lies inside (to rounding)."""
        envelope = self.envelope
        degrees = torch.rad2deg(self.angles).cpu().tolist()
        heights = self.height.cpu().tolist()
        reasons: list[str | None] = []
        for (_, pitch, roll), height in zip(degrees, heights):
            reason = None
            # within 1e-5 degrees: a pose just clamped to a bound reads back past it by the axis-angle
            # round trip's rounding (up to about 2e-6 degrees seen)
            if envelope.max_roll_deg is not None and abs(roll) > envelope.max_roll_deg + _SLACK_DEG:
                reason = f"roll {roll:.1f}° beyond ±{envelope.max_roll_deg:g}°"
            elif envelope.pitch_deg is not None and not (
                envelope.pitch_deg[0] - _SLACK_DEG <= pitch <= envelope.pitch_deg[1] + _SLACK_DEG
            ):
                reason = f"pitch {pitch:.1f}° outside {envelope.pitch_deg[0]:g}° to {envelope.pitch_deg[1]:g}°"
            elif envelope.height is not None and not (
                envelope.height[0] - _SLACK_M <= height <= envelope.height[1] + _SLACK_M
            ):
                below = "no surface below the camera" if math.isinf(height) else f"height {height:.2f} m"
                reason = f"{below}, outside {envelope.height[0]:g} to {envelope.height[1]:g} m"
            reasons.append(reason)
        return reasons


ENVELOPES = {
    "free": Envelope("free"),
    "upright": Envelope("upright", max_roll_deg=5.0, pitch_deg=(-30.0, 30.0)),
    "handheld": Envelope("handheld", max_roll_deg=15.0, pitch_deg=(-45.0, 45.0), height=(0.8, 2.0)),
    "robot": Envelope("robot", max_roll_deg=2.0, pitch_deg=(-15.0, 15.0), height=(0.3, 1.5)),
}


def get_envelope(envelope: str | Envelope) -> Envelope:
    """An :class:`Envelope`, or the preset of that name (``free``, ``upright``, ``handheld``, ``robot``)."""
    if isinstance(envelope, Envelope):
        return envelope
    if envelope not in ENVELOPES:
        raise ValueError(f"envelope {envelope!r} is not a preset; choose one of {', '.join(ENVELOPES)}")
    return ENVELOPES[envelope]
