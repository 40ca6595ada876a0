"""Study: a scene and a depth model wired for the search, built in one place from one settings object.

Every entry point (``kadv-attack``, :mod:`kadv.testing`, the report's transfer matrix, the
benchmarks) builds its exact renderer, objective and differentiable renderer here, so that a new
setting is threaded through one constructor.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field

import torch

from kadv.attack.driver import attack
from kadv.attack.objective import Objective
from kadv.attack.records import AttackResult, InitViewResult
from kadv.attack.registry import check_searchable
from kadv.attack.search import AttackConfig
from kadv.losses import LossConfig
from kadv.models import DepthModel
from kadv.penalties import PenaltyConfig
from kadv.render import DifferentiableRenderer, DiffRenderConfig, ExactRenderer, Shading
from kadv.render.exact import DEFAULT_MAX_RAYS
from kadv.scenes import Scene

__all__ = ["Study", "StudySettings"]


@dataclass(frozen=True)
class StudySettings:
    """Everything a :class:`Study` is built from besides its scene and model (the commands' config
    groups: ``render/``, ``loss/``, ``penalty/``, ``attack/``, ``envelope/``).

    Attributes:
        size: (height, width) of the renders the model sees.
        shading: the exact render's shading (``render.lighting`` and ``render.shading``).
        backend: the ray caster (``render.backend``: ``auto``, ``open3d``, ``warp``).
        max_rays: rays cast and shaded at once (``render.max_rays``).
        render: the differentiable renderer's options (``render.differentiable``, ``render.supersample``).
        loss: the attacked loss, its comparison space and alignment (``loss/``).
        penalty: the wall penalty and the view validity (``penalty/``).
        attack: the search (``attack/``, ``envelope/``).
        device: where the networks, the loss and the warp run (the casts: the backend's device).
        progress: show the bake's and the search's progress bars.
    """

    size: tuple[int, int] = (240, 320)
    shading: Shading = field(default_factory=Shading)
    backend: str = "auto"
    max_rays: int = DEFAULT_MAX_RAYS
    render: DiffRenderConfig = field(default_factory=DiffRenderConfig)
    loss: LossConfig = field(default_factory=LossConfig)
    penalty: PenaltyConfig = field(default_factory=PenaltyConfig)
    attack: AttackConfig = field(default_factory=AttackConfig)
    device: str | torch.device = "cpu"
    progress: bool = True

    def exact_renderer(self, scene: Scene) -> ExactRenderer:
        """The exact renderer of ``scene`` these settings describe (its lighting baked, or read from
        the cache, now)."""
        options = {"backend": self.backend, "device": self.device, "max_rays": self.max_rays}
        return ExactRenderer(scene, self.shading, progress=self.progress, **options)


@dataclass
class Study:
    """A scene and a model wired for the search (:meth:`build`).

    Attributes:
        scene: the scene searched.
        model: the depth model attacked.
        settings: what the rest was built from.
        renderer: the scene's exact renderer.
        objective: the model, loss and penalty a view is scored by.
        differentiable: the renderer the gradient steps render through.
    """

    scene: Scene
    model: DepthModel
    settings: StudySettings
    renderer: ExactRenderer
    objective: Objective
    differentiable: DifferentiableRenderer

    @classmethod
    def build(cls, scene: Scene, model: DepthModel, settings: StudySettings | None = None) -> Study:
        """The study of ``model`` on ``scene`` under ``settings`` (None: the defaults).

        Raises:
            ValueError: a setting the renderer, the loss or the objective refuses, in one line
                naming its key.
        """
        settings = settings or StudySettings()
        return cls._on(settings.exact_renderer(scene), model, settings)

    @classmethod
    def _on(cls, renderer: ExactRenderer, model: DepthModel, settings: StudySettings, function=None) -> Study:
        """The study on an exact renderer; ``function``: the loss function when one is at hand."""
        check_searchable(settings.attack.method, model)
        loss = settings.loss
        function = loss.loss() if function is None else function
        objective = Objective(model, function, renderer, settings.penalty, loss.space, settings.device, loss.alignment)
        differentiable = DifferentiableRenderer(renderer, settings.render, settings.device)
        return cls(renderer.scene, objective.model, settings, renderer, objective, differentiable)

    def variant(
        self,
        model: DepthModel | None = None,
        loss: LossConfig | None = None,
        render: DiffRenderConfig | None = None,
    ) -> Study:
        """The study with another model, loss or differentiable renderer, on the same exact renderer
        (no second bake, no second ray-casting structure) and, while the loss function stays the
        same, the same loss function (a perceptual loss's VGG-16 is loaded once)."""
        changes = {k: v for k, v in (("loss", loss), ("render", render)) if v is not None}
        settings = dataclasses.replace(self.settings, **changes)
        same = settings.loss.function_key == self.settings.loss.function_key
        function = self.objective.loss if same else None
        return self._on(self.renderer, model if model is not None else self.model, settings, function)

    def attack(
        self,
        init_views: list,
        seed: int,
        config: AttackConfig | None = None,
        completed: dict[int, InitViewResult] | None = None,
        on_result: Callable[[int, InitViewResult], None] | None = None,
        starts: dict[int, torch.Tensor] | None = None,
        progress: bool | None = None,
    ) -> AttackResult:
        """Search from every init view (:func:`kadv.attack.attack`) at the study's size, with
        ``config`` (None: the settings' search), a progress bar as ``progress`` says (None: as the
        settings do)."""
        height, width = self.settings.size
        return attack(
            self.objective,
            self.differentiable,
            init_views,
            height,
            width,
            config or self.settings.attack,
            seed,
            completed=completed,
            on_result=on_result,
            progress=self.settings.progress if progress is None else progress,
            starts=starts,
        )
