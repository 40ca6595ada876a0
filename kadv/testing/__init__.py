"""Viewpoint robustness in your own tests: checks, probe scenes and a scorecard, with no Hydra.

::

    from kadv.testing import assert_viewpoint_robust, scene

    def test_my_model_keeps_its_depth_when_the_camera_moves():
        assert_viewpoint_robust("kadv_tiny", scene("box_room", seed=3), min_delta1=0.5)

Installing kadv also installs its pytest plugin (:mod:`kadv.testing.plugin`): the ``kadv_scene``
and ``kadv_artifacts`` fixtures, the ``kadv`` marker, ``--kadv-budget`` and ``--kadv-keep``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from kadv._lazy import lazy_exports

# loaded on first use: the pytest plugin reads the session settings without importing torch
_EXPORTS = {
    "DEFAULT_BUDGET": "kadv.testing.options",
    "CheckSettings": "kadv.testing.session",
    "DEFAULT_RADII": "kadv.testing.profile",
    "InitViewOutcome": "kadv.testing.robustness",
    "Profile": "kadv.testing.profile",
    "RobustnessInputError": "kadv.testing.inputs",
    "RobustnessResult": "kadv.testing.robustness",
    "Scorecard": "kadv.testing.card",
    "assert_viewpoint_robust": "kadv.testing.robustness",
    "current": "kadv.testing.session",
    "robustness_profile": "kadv.testing.profile",
    "scene": "kadv.testing.inputs",
    "scorecard": "kadv.testing.card",
    "settings": "kadv.testing.session",
    "viewpoint_robustness": "kadv.testing.robustness",
}

if TYPE_CHECKING:  # the same names, for type checkers and the API reference
    from kadv.testing.card import Scorecard, scorecard
    from kadv.testing.inputs import RobustnessInputError, scene
    from kadv.testing.options import DEFAULT_BUDGET
    from kadv.testing.profile import DEFAULT_RADII, Profile, robustness_profile
    from kadv.testing.robustness import (
        InitViewOutcome,
        RobustnessResult,
        assert_viewpoint_robust,
        viewpoint_robustness,
    )
    from kadv.testing.session import CheckSettings, current, settings

__all__ = [
    "DEFAULT_BUDGET",
    "DEFAULT_RADII",
    "CheckSettings",
    "InitViewOutcome",
    "Profile",
    "RobustnessInputError",
    "RobustnessResult",
    "Scorecard",
    "assert_viewpoint_robust",
    "current",
    "robustness_profile",
    "scene",
    "scorecard",
    "settings",
    "viewpoint_robustness",
]

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS)
