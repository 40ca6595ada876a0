"""Bayesian optimisation in a trust region (TuRBO-1, Eriksson et al. 2019) on BoTorch: a Gaussian
process on the pose normalised to the unit cube, batches chosen by Thompson sampling inside a box
around the best view, the box grown on success, shrunk on failure and restarted once it collapses.

One batch of ``batch`` poses is one model call, so the model scores several poses per draw of the
process. The fitting and sampling take host seconds that no model pass pays for: the method is for
budgets counted in passes of a model dearer than a fit (docs/attack.md).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass

import numpy as np
import torch

from kadv.attack.loop import Proposer, fitness, register_proposer
from kadv.attack.records import ViewRecord

__all__ = ["TurboProposer", "TurboSettings"]


@dataclass(frozen=True)
class TurboSettings:
    """``attack.turbo``.

    Attributes:
        init_views: poses of the space-filling design that starts the search and each restart
            (scrambled Sobol points spread over the bounds' balls).
        batch: poses chosen per draw of the process, scored in one model call.
        candidates: Thompson-sampling candidates drawn in the trust region per batch.
        length_init, length_min, length_max: the trust region's side in the unit cube (scaled per
            axis by the process's length scales) at a start, below which it restarts, and at most.
        success_tolerance, failure_tolerance: batches in a row that raise (do not raise) the best
            objective before the region doubles (halves).
        refit_growth: the process's hyper-parameters are fitted again (from the last fit's) once
            the views scored have grown by this factor since that fit; between fits the process
            takes the new views with the hyper-parameters held (1: a fit every batch).
    """

    init_views: int = 12
    batch: int = 4
    candidates: int = 1024
    length_init: float = 0.8
    length_min: float = 0.0078125
    length_max: float = 1.6
    success_tolerance: int = 3
    failure_tolerance: int = 2
    refit_growth: float = 1.25

    def __post_init__(self) -> None:
        if self.refit_growth < 1.0:
            raise ValueError(f"attack.turbo.refit_growth must be at least 1, got {self.refit_growth}")
        if not (0 < self.length_min < self.length_init <= self.length_max):
            raise ValueError(
                "attack.turbo needs 0 < length_min < length_init <= length_max, got "
                f"{self.length_min}, {self.length_init}, {self.length_max}"
            )
        if self.candidates < self.batch:
            raise ValueError(
                f"attack.turbo.candidates must be at least attack.turbo.batch ({self.batch}), got {self.candidates}"
            )
        if self.init_views < 2:
            raise ValueError(f"attack.turbo.init_views must be at least 2 to fit a process, got {self.init_views}")


@register_proposer("turbo", TurboSettings)
class TurboProposer(Proposer):
    """Maximises the objective over the unit cube x, the point of the pose space's box at
    ``2x - 1`` (:meth:`~kadv.attack.space.PoseSpace.from_box`) pulled within the bounds' balls.
    The process is fitted on the poses reached (after the bounds, the envelope and the step
    guard), an invalid view at the lowest objective seen. The context's warm starts are scored
    first, with the first design."""

    def __init__(self, context, rng: np.random.Generator) -> None:
        super().__init__(context, rng)
        self.space = context.space
        self.x = torch.zeros(0, self.space.dims, dtype=torch.float64)
        self.y = torch.zeros(0, dtype=torch.float64)
        self.design: list[torch.Tensor] = []  # poses of a space-filling design still to ask
        self.hypers: dict[str, torch.Tensor] = {}  # the last fit's, where the next fit starts
        self.fitted_on = 0  # views the last fit saw
        self._restart()
        self.design = list(context.starts) + self.design  # views found bad before (a smaller radius) join the first

    def _restart(self) -> None:
        self.design = list(self.space.sobol(self.settings.init_views, self.rng))
        self.length = self.settings.length_init
        self.successes = self.failures = 0
        self.start = len(self.y)  # the restart's own views: its region centres on their best
        self.best = -math.inf

    def _to_unit(self, params: torch.Tensor) -> torch.Tensor:
        return (self.space.to_box(params) + 1.0) / 2.0

    def _from_unit(self, x: torch.Tensor) -> torch.Tensor:
        return self.space.bound(self.space.from_box(2.0 * x - 1.0))

    def ask(self, count: int) -> torch.Tensor:
        if not self.design and self.length < self.settings.length_min:
            self._restart()
        if self.design:
            asked, self.design = self.design[:count], self.design[count:]
            return torch.stack(asked)
        return self._from_unit(self._thompson(min(self.settings.batch, count)))

    def tell(self, records: list[ViewRecord]) -> None:
        values = torch.from_numpy(fitness(records))
        self.x = torch.cat([self.x, self._to_unit(torch.tensor([r.params for r in records], dtype=torch.float64))])
        self.y = torch.cat([self.y, values])
        if len(self.y) - self.start <= len(records):  # the design's first batch: nothing to compare with
            self.best = float(values.max())
            return
        risen = float(values.max()) > self.best + 1e-3 * abs(self.best)
        self.best = max(self.best, float(values.max()))
        self.successes, self.failures = (self.successes + 1, 0) if risen else (0, self.failures + 1)
        if self.successes >= self.settings.success_tolerance:
            self.length, self.successes = min(2.0 * self.length, self.settings.length_max), 0
        elif self.failures >= self.settings.failure_tolerance:
            self.length, self.failures = self.length / 2.0, 0

    def _thompson(self, count: int) -> torch.Tensor:
        """``count`` distinct points (count, dims) of the trust region, each the maximum of one draw
        of the process over the candidates."""
        with warnings.catch_warnings():  # here, not at the top: only this search needs them
            warnings.simplefilter("ignore", DeprecationWarning)  # gpytorch's torch.jit.script at import
            from botorch.exceptions import InputDataWarning
            from botorch.fit import fit_gpytorch_mll
            from botorch.models import SingleTaskGP
            from botorch.models.transforms import Standardize
            from gpytorch.mlls import ExactMarginalLogLikelihood
            from linear_operator.utils.warnings import NumericalWarning

        finite = torch.isfinite(self.y)
        floor = self.y[finite].min() if bool(finite.any()) else torch.tensor(0.0, dtype=torch.float64)
        y = torch.where(finite, self.y, floor)
        # the process's own draws (hyper-parameter fitting, posterior samples) from the search's seed
        with torch.random.fork_rng(), warnings.catch_warnings():
            torch.manual_seed(int(self.rng.integers(2**63 - 1)))
            warnings.simplefilter("ignore", InputDataWarning)  # a constant y (all views invalid) is fitted as it is
            warnings.simplefilter("ignore", NumericalWarning)  # jitter for repeated poses (a ball's surface, a wall)
            gp = SingleTaskGP(self.x, y[:, None], outcome_transform=Standardize(m=1))
            # a batch moves the likelihood's optimum little: each fit starts where the last ended,
            # and fitting only once the views have grown by a factor keeps the fits' share of a
            # long search flat (the fits were most of this method's seconds)
            gp.load_state_dict(self.hypers, strict=False)
            if len(y) >= self.settings.refit_growth * self.fitted_on:
                fit_gpytorch_mll(ExactMarginalLogLikelihood(gp.likelihood, gp))
                self.hypers = {name: value.detach().clone() for name, value in gp.named_parameters()}
                self.fitted_on = len(y)
            own = torch.arange(len(y)) >= self.start
            centre = self.x[own][y[own].argmax()]
            scales = gp.covar_module.lengthscale.detach().reshape(-1)
            dims = self.space.dims
            weights = scales / scales.prod().pow(1.0 / dims)  # longer where the objective varies slowly
            half_side = (self.length * weights / 2.0).to(self.x)
            low, high = (centre - half_side).clamp(0.0, 1.0), (centre + half_side).clamp(0.0, 1.0)
            sobol = torch.quasirandom.SobolEngine(dims, scramble=True, seed=int(self.rng.integers(2**31 - 1)))
            unit = sobol.draw(self.settings.candidates, dtype=torch.float64)
            # the candidates as the poses they will be, within the balls, so the draws score what is evaluated
            candidates = self._to_unit(self._from_unit(low + (high - low) * unit))
            with torch.no_grad():
                draws = gp.posterior(candidates).rsample(torch.Size([count])).reshape(count, -1)
        chosen: list[int] = []
        for draw in draws:
            order = torch.argsort(draw, descending=True).tolist()
            chosen.append(next(i for i in order if i not in chosen))
        return candidates[chosen]
