"""Keeping the camera honest: distance to surfaces, the shortcut penalty, step guard, view validity."""

from __future__ import annotations

from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface, shortcut_penalty
from kadv.penalties.envelope import ENVELOPES, Envelope, EnvelopeFigures, get_envelope
from kadv.penalties.guard import StepCheck, step_guard
from kadv.penalties.sampling import random_valid_poses
from kadv.penalties.validity import (
    ViewValidity,
    fibonacci_sphere,
    plane_counts,
    plane_labels,
    plane_shares,
    probe_directions_hits,
    view_validity,
)

__all__ = [
    "ENVELOPES",
    "Envelope",
    "EnvelopeFigures",
    "PenaltyConfig",
    "StepCheck",
    "ViewValidity",
    "distance_to_surface",
    "fibonacci_sphere",
    "get_envelope",
    "plane_counts",
    "plane_labels",
    "plane_shares",
    "probe_directions_hits",
    "random_valid_poses",
    "shortcut_penalty",
    "step_guard",
    "view_validity",
]
