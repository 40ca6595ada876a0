"""Keeping the camera honest: distance to surfaces, the shortcut penalty, step guard, view validity."""

from __future__ import annotations

from kadv._renamed import renamed_exports
from kadv.penalties.config import PenaltyConfig
from kadv.penalties.distance import distance_to_surface, shortcut_penalty
from kadv.penalties.envelope import ENVELOPES, Envelope, EnvelopeFigures, get_envelope
from kadv.penalties.guard import StepCheck, step_guard
from kadv.penalties.sampling import random_valid_poses
from kadv.penalties.validity import (
    ViewValidity,
    enclosure_hits,
    fibonacci_sphere,
    plane_counts,
    plane_labels,
    plane_shares,
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
    "enclosure_hits",
    "fibonacci_sphere",
    "get_envelope",
    "plane_counts",
    "plane_labels",
    "plane_shares",
    "random_valid_poses",
    "shortcut_penalty",
    "step_guard",
    "view_validity",
]

__getattr__ = renamed_exports(__name__, {"probe_directions_hits": "enclosure_hits"})
