"""Robustness against the size of the camera's move: how far must the camera move, within the poses
a real camera takes, before the model fails?

:func:`robustness_profile` searches nested radii (degrees, metres) around a scene's init views
within a camera envelope, and reports per radius the worst view the default search finds and the
typical view (uniform draws), then one score: the area under the typical curve, which ranks models
because every model is scored on the same drawn views (the worst view is each model's own search's,
and its area varies with the search; docs/testing.md measures both). Adversarial robustness reports
accuracy over the perturbation's size in the same way; RoboDepth averages over severities.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch

from kadv.testing.inputs import RobustnessInputError
from kadv.testing.options import CheckOptions, Setup, check_radii, setup, worst_record

__all__ = [
    "DEFAULT_RADII",
    "FAIL_BELOW",
    "PROFILE_KEYS",
    "SEARCH_SEED_STRIDE",
    "TYPICAL_VIEWS",
    "WARM_STARTS",
    "Profile",
    "ProfileSettings",
    "SeedProfile",
    "SeedRun",
    "curve_area",
    "pool_worst_views",
    "profile_settings",
    "profile_views",
    "robustness_profile",
    "save_profile_panels",
    "save_worst_pictures",
    "search_radii",
    "seed_run",
    "warm_starts",
    "worst_views",
]

DEFAULT_RADII = ((5.0, 0.1), (15.0, 0.3), (45.0, 1.0))  # (degrees, metres), nested
# A drawn view fails below this delta1: the highest threshold that the init views' delta1 stays above
# and under which a noisier model never fails less (benchmarks/ranking.py --parts threshold)
FAIL_BELOW = 0.6
TYPICAL_VIEWS = 16  # uniform draws per init view and radius
WARM_STARTS = 2  # the worst separated views within the smaller radii that a search at the next starts from
# search seed j of a profile's seed s (init views fixed) is s + SEARCH_SEED_STRIDE * j
SEARCH_SEED_STRIDE = 10_000
_DRAW_ROUNDS = 32  # rounds of 4 x typical_views draws at most, for the envelope to keep enough
# what a profile takes beyond CheckOptions (whose radius and seed it replaces)
PROFILE_KEYS = ("radii", "envelope", "seeds", "typical_views", "fail_below", "search_seeds")


@dataclass(frozen=True)
class Profile:
    """A model's viewpoint robustness on one scene against the radius of the camera's move.

    Attributes:
        model, scene: their names.
        envelope: the camera envelope the views kept to (:mod:`kadv.penalties.envelope`).
        radii: the nested radii, (degrees, metres) each.
        seeds: the seeds of the init views and searches.
        delta1_init: mean delta1 at the init views, per seed.
        worst_by_seed: (seeds, radii) mean over init views of the worst valid view's delta1 found
            within each radius by the search under the seed itself; never rising with the radius.
        typical_by_seed: (seeds, radii) mean delta1 of views drawn uniformly from each radius.
        failure_by_seed: (seeds, radii) share of those views whose delta1 is below ``fail_below``.
        draws: per radius, the delta1 of every valid drawn view, over init views and seeds.
        fail_below: the delta1 under which a drawn view counts as failed.
        pictures: per radius, the four-panel picture of the worst view found (first seed).
        search_noise_by_seed: (seeds, radii) the sample standard deviation (ddof 1) of that worst
            over the searches of ``search_seeds`` search seeds, the init views fixed; empty rows
            with one search seed (not measured).
        cost_by_seed: per seed, per init view: the searches' model passes and seconds over all
            radii (the noise's extra searches left out), and the drawn views' passes.
        agreement_by_seed: (seeds, radii) the agreement of the searches at each radius, summed over
            the init views: [runs that reached their worst, runs made, init views whose worst one
            run alone found] (:class:`kadv.attack.Agreement`).
        alignment: how every delta1 met the ground truth (``loss.alignment``).
    """

    model: str
    scene: str
    envelope: str
    radii: tuple[tuple[float, float], ...]
    seeds: tuple[int, ...]
    delta1_init: list[float]
    worst_by_seed: list[list[float]]
    typical_by_seed: list[list[float]]
    failure_by_seed: list[list[float]]
    draws: list[list[float]]
    fail_below: float
    pictures: list[str]
    search_noise_by_seed: list[list[float]] = dataclasses.field(default_factory=list)
    cost_by_seed: list[dict[str, float]] = dataclasses.field(default_factory=list)
    agreement_by_seed: list[list[list[int]]] = dataclasses.field(default_factory=list)
    alignment: str = "scale_shift"

    @property
    def worst(self) -> list[float]:
        """Per radius, the worst delta1, mean over seeds."""
        return np.mean(self.worst_by_seed, axis=0).tolist()

    @property
    def typical(self) -> list[float]:
        """Per radius, the typical delta1, mean over seeds."""
        return _nanmean(self.typical_by_seed)

    @property
    def failure_rate(self) -> list[float]:
        """Per radius, the share of drawn views that fail, mean over seeds."""
        return _nanmean(self.failure_by_seed)

    @property
    def typical_interval(self) -> list[tuple[float, float]]:
        """Per radius, the 95% interval of the typical delta1 over all the draws (normal, of the mean)."""
        return [_mean_interval(d) for d in self.draws]

    @property
    def failure_interval(self) -> list[tuple[float, float]]:
        """Per radius, the 95% interval of the failure rate over all the draws (Wilson's)."""
        return [_wilson(sum(v < self.fail_below for v in d), len(d)) for d in self.draws]

    @classmethod
    def of(
        cls,
        model: str,
        scene: str,
        envelope: str,
        radii: tuple[tuple[float, float], ...],
        seeds: tuple[int, ...],
        seed_profiles: list[SeedProfile],
        fail_below: float = FAIL_BELOW,
        pictures: list[str] | None = None,
        alignment: str = "scale_shift",
    ) -> Profile:
        """The profile of ``seed_profiles`` (one per seed, :func:`profile_views`)."""
        return cls(
            model=model,
            scene=scene,
            envelope=envelope,
            radii=radii,
            seeds=tuple(seeds),
            delta1_init=[p.delta1_init for p in seed_profiles],
            worst_by_seed=[p.worst for p in seed_profiles],
            typical_by_seed=[p.typical for p in seed_profiles],
            failure_by_seed=[p.failure for p in seed_profiles],
            draws=[[v for p in seed_profiles for v in p.draws[k]] for k in range(len(radii))],
            fail_below=float(fail_below),
            pictures=list(pictures or []),
            search_noise_by_seed=[p.search_noise for p in seed_profiles],
            cost_by_seed=[p.cost for p in seed_profiles],
            agreement_by_seed=[p.agreement for p in seed_profiles],
            alignment=alignment,
        )

    @classmethod
    def from_dict(cls, data: dict) -> Profile:
        """The profile :meth:`to_dict` wrote (its derived figures are computed again)."""
        fields = {f.name for f in dataclasses.fields(cls)}
        values = {k: v for k, v in data.items() if k in fields}
        return cls(**values | {"radii": tuple(tuple(r) for r in values["radii"]), "seeds": tuple(values["seeds"])})

    @classmethod
    def merge(cls, profiles: list[Profile]) -> Profile:
        """One profile of the same model, scene name, envelope and radii over all the profiles' seeds
        (a scorecard builds its probe scene anew for each seed)."""
        first = profiles[0]
        return dataclasses.replace(
            first,
            seeds=tuple(seed for p in profiles for seed in p.seeds),
            delta1_init=[v for p in profiles for v in p.delta1_init],
            worst_by_seed=[row for p in profiles for row in p.worst_by_seed],
            typical_by_seed=[row for p in profiles for row in p.typical_by_seed],
            failure_by_seed=[row for p in profiles for row in p.failure_by_seed],
            draws=[[v for p in profiles for v in p.draws[k]] for k in range(len(first.radii))],
            search_noise_by_seed=[row for p in profiles for row in p.search_noise_by_seed],
            cost_by_seed=[row for p in profiles for row in p.cost_by_seed],
            agreement_by_seed=[row for p in profiles for row in p.agreement_by_seed],
        )

    @property
    def radii_text(self) -> str:
        """The radii as text: ``5°/0.1 m, 15°/0.3 m, 45°/1 m``."""
        return ", ".join(f"{d:g}°/{m:g} m" for d, m in self.radii)

    @property
    def scores(self) -> list[float]:
        """The score under each seed (see :attr:`score`)."""
        return [curve_area(init, typical) for init, typical in zip(self.delta1_init, self.typical_by_seed)]

    @property
    def score(self) -> float:
        """In [0, 1]: the area under the typical curve, from the init views' delta1 at radius 0 through
        the mean delta1 of the views drawn at each radius, each step between radii weighing the same
        (as RoboDepth weighs severities), mean over seeds. 1: no move within the radii costs the model
        anything. NaN where a radius kept no drawn view."""
        return float(np.mean(self.scores))

    @property
    def worst_scores(self) -> list[float]:
        """The area under the worst-case curve under each seed (see :attr:`worst_score`)."""
        return [curve_area(init, worst) for init, worst in zip(self.delta1_init, self.worst_by_seed)]

    @property
    def worst_score(self) -> float:
        """In [0, 1]: the same area under the worst-case curve, mean over seeds: how far the camera
        must move, within the envelope, before the worst view the search finds fails the model (the
        study's adversarial figure, as a curve over the move's size)."""
        return float(np.mean(self.worst_scores))

    @property
    def resilience(self) -> float:
        """The worst-case area over the init views' delta1, mean over seeds: the share of its
        accuracy at the init views that the model keeps against the worst views (as RoboDepth's mRR
        divides by clean accuracy); 1: no move within the radii costs it anything."""
        return float(np.mean([w / i if i > 0 else math.nan for w, i in zip(self.worst_scores, self.delta1_init)]))

    @property
    def score_spread(self) -> float:
        """max - min of the score over the seeds."""
        return float(np.ptp(self.scores))

    @property
    def search_noise(self) -> list[float]:
        """Per radius, the median over seeds of the search noise (NaN: not measured): how much the
        worst found moves with the search's seed alone, apart from the init views' spread."""
        rows = [row for row in self.search_noise_by_seed if row]
        return np.median(rows, axis=0).tolist() if rows else [math.nan] * len(self.radii)

    @property
    def cost(self) -> dict[str, float]:
        """Per init view, mean over seeds: the searches' model passes and seconds, the drawn views' passes."""
        keys = ("search_passes", "search_seconds", "draw_passes")
        return {k: float(np.mean([c[k] for c in self.cost_by_seed])) if self.cost_by_seed else math.nan for k in keys}

    def agreement_text(self, radius: int) -> str:
        """The agreement at a radius over seeds and init views: ``3/4``, ``1/2 (1 alone)``; ``-``
        where none was recorded."""
        if not self.agreement_by_seed:
            return "-"
        reached, runs, alone = (sum(row[radius][i] for row in self.agreement_by_seed) for i in range(3))
        return f"{reached}/{runs}" + (f" ({alone} alone)" if alone else "")

    def noise_text(self) -> str:
        """One line: the search noise per radius and its largest, and the init views' spread."""
        measured = [row for row in self.search_noise_by_seed if row]
        if measured:
            per_radius = ", ".join(f"{v:.3f}" for v in self.search_noise)
            text = (
                f"search noise (sd of the worst over search seeds, init views fixed): {per_radius} by radius, "
                f"largest {max(max(row) for row in measured):.3f}"
            )
        else:
            text = "search noise not measured (search_seeds=1; 3 or more measure it)"
        return f"{text}; init views' spread (worst-case area over seeds): {np.ptp(self.worst_scores):.3f}"

    def cost_text(self) -> str:
        """One line: what the profile cost per init view."""
        cost = self.cost
        return (
            f"cost per init view: {cost['search_passes']:.0f} model passes searching ({len(self.radii)} radii), "
            f"{cost['search_seconds']:.1f} s; {cost['draw_passes']:.0f} passes on drawn views"
        )

    def markdown(self) -> str:
        """A table: per radius, the worst and typical delta1, the failure rate; then the score."""
        lines = [
            f"{self.model} on {self.scene}, envelope {self.envelope}, seeds {list(self.seeds)}, delta1 after "
            f"{self.alignment} alignment: {np.mean(self.delta1_init):.3f} at the init views",
            "",
            f"| radius | worst delta1 | agreement | typical delta1 (95%) | failure rate, delta1 < {self.fail_below:g} "
            "(95%) |",
            "|---|---|---|---|---|",
        ]
        for k, (degrees, metres) in enumerate(self.radii):
            lo, hi = self.typical_interval[k]
            flo, fhi = self.failure_interval[k]
            lines.append(
                f"| {degrees:g}°, {metres:g} m | {self.worst[k]:.3f} | {self.agreement_text(k)} | "
                f"{self.typical[k]:.3f} ({lo:.3f}-{hi:.3f}) | {self.failure_rate[k]:.0%} ({flo:.0%}-{fhi:.0%}) |"
            )
        lines += [
            "",
            f"worst-case area {self.worst_score:.3f} ± {np.ptp(self.worst_scores):.3f}, "
            f"resilience {self.resilience:.3f} (worst-case area / init delta1)",
            f"score {self.score:.3f} ± {self.score_spread:.3f} (typical area; spread over seeds)",
            self.noise_text(),
        ]
        if self.cost_by_seed:
            lines.append(self.cost_text())
        return "\n".join(lines)

    def to_dict(self) -> dict:
        """Everything, plus the means, the score and its spread, as plain JSON values."""
        out = asdict(self)
        out.update(
            typical_interval=self.typical_interval,
            failure_interval=self.failure_interval,
            worst=self.worst,
            typical=self.typical,
            failure_rate=self.failure_rate,
            score=self.score,
            score_spread=self.score_spread,
            worst_scores=self.worst_scores,
            worst_score=self.worst_score,
            resilience=self.resilience,
        )
        return out

    def save_png(self, path: str | Path) -> Path:
        """delta1 against the radius, worst and typical, with bands over the seeds, and the worst
        view's picture at each radius."""
        import matplotlib.pyplot as plt
        from PIL import Image

        from kadv.report.figures import save_figure

        count = len(self.radii)
        # the curve on the left; the worst views' four-panel pictures stacked on the right, one a radius
        if self.pictures:
            figure = plt.figure(figsize=(13.0, max(4.2, 2.0 * count)))
            grid = figure.add_gridspec(count, 2, width_ratios=[1.0, 1.9])
        else:
            figure = plt.figure(figsize=(5.0, 4.2))
            grid = figure.add_gridspec(count, 1)
        axis = figure.add_subplot(grid[:, 0])
        steps = np.arange(count + 1)
        for values, label, colour in (
            (self.worst_by_seed, "worst", "tab:red"),
            (self.typical_by_seed, "typical", "tab:blue"),
        ):
            curves = np.array([[init, *row] for init, row in zip(self.delta1_init, values)])
            axis.plot(steps, curves.mean(axis=0), marker="o", color=colour, label=label)
            axis.fill_between(steps, curves.min(axis=0), curves.max(axis=0), color=colour, alpha=0.2, linewidth=0)
        axis.set_xticks(steps, ["init"] + [f"{d:g}°\n{m:g} m" for d, m in self.radii])
        axis.set_ylim(0, 1.02)
        axis.set_ylabel("delta1 (band: min to max over seeds)")
        score = f"score {self.score:.3f} ± {self.score_spread:.3f}"
        axis.set_title(f"{self.model} on {self.scene} ({self.envelope})\n{score}")
        axis.legend(loc="lower left")
        for k, picture in enumerate(self.pictures):
            tile = figure.add_subplot(grid[k, 1])
            with Image.open(picture) as image:
                tile.imshow(np.asarray(image.convert("RGB")))
            tile.set_title(f"worst within {self.radii[k][0]:g}°, {self.radii[k][1]:g} m", fontsize=9)
            tile.set_axis_off()
        figure.tight_layout()
        return save_figure(Path(path), figure)


def save_profile_panels(path: str | Path, panels: dict[str, dict[str, Profile]]) -> Path:
    """One panel per key of ``panels`` (a probe, a scene): each of its profiles' worst (solid) and
    typical (dashed) delta1 against the radius, with bands over the seeds, labelled by its key
    (which names its score). The scorecard's and the report's pictures."""
    import matplotlib.pyplot as plt

    from kadv.report.figures import save_figure

    columns = min(4, len(panels))
    rows = math.ceil(len(panels) / columns)
    figure, axes = plt.subplots(rows, columns, figsize=(3.6 * columns, 3.0 * rows), squeeze=False)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for index, (name, profiles) in enumerate(panels.items()):
        axis = axes[index // columns, index % columns]
        for m, (label, profile) in enumerate(profiles.items()):
            steps = np.arange(len(profile.radii) + 1)
            colour = colours[m % len(colours)]
            for values, style in ((profile.worst_by_seed, "-"), (profile.typical_by_seed, "--")):
                curves = np.array([[init, *row] for init, row in zip(profile.delta1_init, values)])
                shown = label if style == "-" else None
                axis.plot(steps, curves.mean(axis=0), style, color=colour, marker="o", markersize=3, label=shown)
                axis.fill_between(steps, curves.min(0), curves.max(0), color=colour, alpha=0.15, linewidth=0)
            axis.set_xticks(steps, ["init"] + [f"{d:g}°\n{r:g} m" for d, r in profile.radii], fontsize=7)
        axis.set_ylim(0, 1.02)
        axis.set_title(name, fontsize=9)
        axis.legend(fontsize=7, loc="lower left")
    for index in range(len(panels), rows * columns):
        axes[index // columns, index % columns].set_axis_off()
    figure.suptitle("delta1 against the camera's move: worst (solid) and typical (dashed); legend: score")
    figure.tight_layout()
    return save_figure(Path(path), figure)


def _nanmean(rows: list[list[float]]) -> list[float]:
    """Per column, the mean of the values that are not NaN (NaN where there are none)."""
    values = np.array(rows, dtype=float)
    counts = (~np.isnan(values)).sum(axis=0)
    sums = np.nansum(values, axis=0)
    return [float(t / n) if n else math.nan for t, n in zip(sums, counts)]


def curve_area(init: float, values: list[float]) -> float:
    """The area under the curve from ``init`` (radius 0) through ``values`` (one per radius), each
    step between radii weighing the same, in [0, 1] for delta1 values: a profile's score when the
    values are the typical curve, its worst_score when they are the worst."""
    curve = [init, *values]
    return float(np.mean([(a + b) / 2 for a, b in itertools.pairwise(curve)]))


def _wilson(failures: int, count: int) -> tuple[float, float]:
    if count == 0:
        return (math.nan, math.nan)
    z, p = 1.96, failures / count
    centre = (p + z * z / (2 * count)) / (1 + z * z / count)
    half = z * math.sqrt(p * (1 - p) / count + z * z / (4 * count * count)) / (1 + z * z / count)
    return (max(0.0, centre - half), min(1.0, centre + half))


def _mean_interval(values: list[float]) -> tuple[float, float]:
    if len(values) < 2:
        return (math.nan, math.nan)
    mean, half = float(np.mean(values)), 1.96 * float(np.std(values, ddof=1)) / math.sqrt(len(values))
    return (mean - half, mean + half)


def _typical(
    objective, differentiable, init, size, config, seed: int, index: int, count: int
) -> tuple[list[float], int]:
    """delta1 of the valid views among ``count`` drawn uniformly (Sobol) from the radius and the
    envelope around ``init``, and the model passes spent on them."""
    from scipy.stats import qmc

    from kadv.attack import SearchContext
    from kadv.geometry import perturb_world_T_cam

    context = SearchContext(objective, differentiable, init, *size, config)
    space = context.space
    sobol = qmc.Sobol(space.dims, scramble=True, seed=np.random.default_rng([seed, index, 7]))
    chosen = []
    # rejection keeps the draws uniform within the envelope; a tight envelope (robot's roll of 2
    # degrees in a 45-degree ball) keeps few of them, so the design is drawn on in rounds
    for _ in range(_DRAW_ROUNDS):
        params = space.sample(sobol.random(4 * count))
        poses = perturb_world_T_cam(context.base(len(params)).cpu(), params[:, :3], params[:, 3:6])
        inside = [reason is None for reason in config.envelope.figures(objective.renderer, poses).reasons()]
        chosen += list(params[torch.tensor(inside)])
        if len(chosen) >= count:
            break
    if not chosen:
        return [], 0
    chosen = torch.stack(chosen[:count])
    return [r.delta1 for r in context.evaluate(0, chosen) if r.valid], len(chosen)


@dataclass
class SeedProfile:
    """One seed's share of a :class:`Profile` (what :func:`profile_views` returns).

    Attributes:
        delta1_init: mean delta1 at the init views.
        typical, failure: per radius, as :class:`Profile`'s ``*_by_seed`` rows.
        draws: per radius, the delta1 of every valid drawn view.
        found: per radius and init view, the (init view, record) of the worst view found within
            that radius (by its own search, or scored at views other searches found: :meth:`pool`).
        results: per radius, the attack's result within it.
        search_noise: per radius, the sd (ddof 1) of :attr:`worst` over the search seeds (empty: one).
        cost: per init view, the searches' passes and seconds over all radii, the draws' passes.
        agreement: per radius, as :class:`Profile`'s ``agreement_by_seed`` rows.
    """

    delta1_init: float
    typical: list[float]
    failure: list[float]
    draws: list[list[float]]
    found: list[list[tuple]]
    results: list
    search_noise: list[float] = dataclasses.field(default_factory=list)
    cost: dict[str, float] = dataclasses.field(default_factory=dict)
    agreement: list[list[int]] = dataclasses.field(default_factory=list)

    @property
    def carried(self) -> list[list[tuple]]:
        """Per radius and init view, the worst view within that radius or a smaller one (nested)."""
        rows, best = [], list(self.found[0])
        for row in self.found:
            best = [b if b[1].delta1 < f[1].delta1 else f for b, f in zip(best, row)]
            rows.append(best)
        return rows

    @property
    def worst(self) -> list[float]:
        """Per radius, the mean over init views of the worst delta1 within it: never rising."""
        return [float(np.mean([record.delta1 for _, record in row])) for row in self.carried]

    @property
    def worst_views(self) -> list[tuple]:
        """Per radius, the (init view, record) of the worst view within it, over the init views."""
        return [min(row, key=lambda pair: pair[1].delta1) for row in self.carried]

    def pool(self, radius: int, view: int, records: list) -> None:
        """Take ``records`` (this model's scores at views found by other searches within
        ``radius`` from init view ``view``) into account: the worst rankable one lowers the view's
        worst there if it is lower."""
        rankable = [r for r in records if r.rankable]
        if rankable:
            init, current = self.found[radius][view]
            lowest = worst_record(rankable)
            if lowest.delta1 < current.delta1:
                self.found[radius][view] = (init, lowest)


def worst_views(records: list, count: int, min_distance: float, min_angle_deg: float) -> list:
    """Up to ``count`` rankable records of lowest delta1 (the highest loss among ties), each
    separated from those chosen before it: the views a larger radius's search starts from."""
    from kadv.attack.records import select_top_views

    return select_top_views(records, count, min_distance, min_angle_deg, order=lambda r: (r.delta1, -r.loss))


def search_radii(
    objective,
    differentiable,
    views: list,
    size: tuple[int, int],
    config,
    radii: tuple[tuple[float, float], ...],
    seed: int,
    progress: bool = False,
    searched: dict[int, object] | None = None,
    warm: int = WARM_STARTS,
) -> list:
    """The search ``config`` within each radius, smallest first (its bounds set to the radius): each
    init view's search at a radius gets the ``warm`` worst separated views found within the smaller
    ones as warm starts (they lie within it; :class:`~kadv.attack.SearchContext`'s ``starts``).
    ``searched`` holds results already found at some radii (by index), used instead of searching.
    Returns one :class:`~kadv.attack.AttackResult` per radius."""
    from kadv.attack import attack

    results: list = []
    for k, (degrees, metres) in enumerate(radii):
        within = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres)
        result = (searched or {}).get(k)
        if result is None:
            starts = warm_starts(results, len(views), warm, config) if results else None
            result = attack(objective, differentiable, views, *size, within, seed, progress=progress, starts=starts)
        results.append(result)
    return results


def warm_starts(results: list, views: int, count: int, config) -> dict[int, torch.Tensor]:
    """Per init view, the points (N, dims) of the pose space of the ``count`` worst separated views
    that the attack ``results`` found from it."""
    starts = {}
    for index in range(views):
        records = [r for result in results for r in result.views[index].records]
        chosen = worst_views(records, count, config.min_separation, config.min_separation_deg)
        dims = len(records[0].params) if records else 6
        starts[index] = torch.tensor([r.params for r in chosen], dtype=torch.float64).reshape(-1, dims)
    return starts


def profile_views(
    objective,
    differentiable,
    views: list,
    size: tuple[int, int],
    config,
    radii: tuple[tuple[float, float], ...],
    seed: int,
    typical_views: int = TYPICAL_VIEWS,
    fail_below: float = FAIL_BELOW,
    progress: bool = False,
    searched: dict[int, object] | None = None,
    search_seeds: int = 1,
) -> SeedProfile:
    """One seed's profile of the init ``views``: per radius, the search ``config`` (its bounds set to
    the radius, warm-started from the smaller radii: :func:`search_radii`) and ``typical_views``
    uniform draws per init view; the worst view carried from radius to radius (the radii are
    nested). ``searched`` holds results already found at some radii (by index), which are used
    instead of searching again. With ``search_seeds`` above 1, the search runs again under search
    seeds ``seed + SEARCH_SEED_STRIDE * j`` from the same init views, for its noise."""
    results = search_radii(objective, differentiable, views, size, config, radii, seed, progress, searched)
    out = SeedProfile(math.nan, [], [], [[] for _ in radii], [], [])
    draw_passes = 0
    for k, ((degrees, metres), result) in enumerate(zip(radii, results)):
        within = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres)
        typical: list[float] = []
        for i, view in enumerate(result.views):
            drawn, passes = _typical(objective, differentiable, view.init, size, within, seed, i, typical_views)
            typical += drawn
            draw_passes += passes
        if k == 0:
            out.delta1_init = float(np.mean([v.init_record.delta1 for v in result.views]))
        out.found.append([(view.init, worst_record(view.records)) for view in result.views])
        out.typical.append(float(np.mean(typical)) if typical else math.nan)
        out.failure.append(float(np.mean([d < fail_below for d in typical])) if typical else math.nan)
        out.draws[k] = typical
        out.results.append(result)
        out.agreement.append(_agreement_row([view.agreement for view in result.views]))
    budgets = [view.budget for result in results for view in result.views]
    out.cost = {
        "search_passes": sum(b.passes for b in budgets) / len(views),
        "search_seconds": sum(b.seconds for b in budgets) / len(views),
        "draw_passes": draw_passes / len(views),
    }
    if search_seeds > 1:
        worst = [out.worst] + [
            _worst_of(
                search_radii(objective, differentiable, views, size, config, radii, seed + SEARCH_SEED_STRIDE * j)
            )
            for j in range(1, search_seeds)
        ]
        out.search_noise = np.std(worst, axis=0, ddof=1).tolist()
    return out


def _agreement_row(agreements: list) -> list[int]:
    """[runs that reached their worst, runs made, init views whose worst one run alone found]
    over the init views' agreements (:func:`kadv.attack.attack` gives every result one)."""
    return [sum(a.reached for a in agreements), sum(a.runs for a in agreements), sum(a.alone for a in agreements)]


def _worst_of(results: list) -> list[float]:
    """Per radius, the mean over init views of the worst delta1 within it or a smaller one."""
    lowest = [math.inf] * len(results[0].views)
    rows = []
    for result in results:
        lowest = [min(low, worst_record(view.records).delta1) for low, view in zip(lowest, result.views)]
        rows.append(float(np.mean(lowest)))
    return rows


def robustness_profile(
    model,
    scene,
    *,
    radii=DEFAULT_RADII,
    envelope="upright",
    seeds=(0,),
    typical_views: int = TYPICAL_VIEWS,
    fail_below: float = FAIL_BELOW,
    search_seeds: int = 1,
    **options,
) -> Profile:
    """The model's :class:`Profile` on ``scene``: per radius, the worst and typical delta1 within it
    and the envelope, over the scene's init views and ``seeds``; deterministic for the seeds.

    Args:
        model, scene: as :func:`kadv.testing.viewpoint_robustness` takes them.
        radii: nested (degrees, metres) bounds on the move from each init view, increasing.
        envelope: a preset's name (``free``, ``upright``, ``handheld``, ``robot``) or an
            :class:`kadv.penalties.Envelope`.
        seeds: one profile run per seed (init views and searches); the score's spread is over them.
        typical_views: views drawn per init view and radius for the typical case.
        fail_below: a drawn view whose delta1 is below this counts as failed.
        search_seeds: searches per seed from the same init views (the first under the seed
            itself); two or more measure the search noise apart from the init views' spread.
        options: :class:`kadv.testing.CheckOptions`' other fields (``budget_passes``: per init
            view and radius for the worst case; ``init_count``, ``size``, ``method``, ``loss``,
            ``lighting``, ``artifacts``, ``progress``).

    Raises:
        RobustnessInputError: bad radii, seeds, envelope, model, scene or setting, in one line.
    """
    settings = profile_settings(radii, envelope, typical_views, fail_below, options, "robustness_profile", search_seeds)
    seeds = tuple(seeds)
    if not seeds or not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in seeds):
        raise RobustnessInputError(f"seeds must be one or more integers >= 0, got {list(seeds)}")
    runs = [seed_run(model, scene, settings, seed) for seed in seeds]
    return settings.profile(runs, save_worst_pictures(runs[0], settings.radii))


@dataclass(frozen=True)
class ProfileSettings:
    """How a profile searches and draws (checked): the check's options, the radii, the search and
    its envelope, the typical views per init view and radius, the failure threshold, the searches
    per seed."""

    checked: CheckOptions
    radii: tuple[tuple[float, float], ...]
    config: object
    typical_views: int
    fail_below: float
    search_seeds: int = 1

    def profile(self, runs: list[SeedRun], pictures: list[str]) -> Profile:
        """The :class:`Profile` of one model's seed runs."""
        built = runs[0].built
        names = (built.model_name, built.scene_name, self.config.envelope.name)
        seeds = tuple(run.seed for run in runs)
        seeded = [run.seeded for run in runs]
        return Profile.of(*names, self.radii, seeds, seeded, self.fail_below, pictures, self.checked.alignment)


def profile_settings(
    radii, envelope, typical_views, fail_below, options: dict, taker: str, search_seeds: int = 1
) -> ProfileSettings:
    """:class:`ProfileSettings` from a profile's arguments, or :class:`RobustnessInputError` naming
    the bad one (``taker``: the function that was given them)."""
    from kadv.attack import AttackConfig
    from kadv.penalties import get_envelope

    taken = sorted({"radius", "seed"} & set(options))
    if taken:
        raise RobustnessInputError(f"{taker} takes radii and seeds, not {' or '.join(taken)}")
    checked = CheckOptions.of(options, taker)
    radii = check_radii(radii)
    if not (isinstance(typical_views, int) and typical_views >= 2):
        raise RobustnessInputError(f"typical_views must be an integer >= 2, got {typical_views!r}")
    if not (isinstance(fail_below, (int, float)) and 0 < fail_below <= 1):
        raise RobustnessInputError(f"fail_below must be in (0, 1], got {fail_below!r}")
    if isinstance(search_seeds, bool) or not (isinstance(search_seeds, int) and search_seeds >= 1):
        raise RobustnessInputError(f"search_seeds must be an integer >= 1, got {search_seeds!r}")
    try:
        bounds = get_envelope(envelope)
        config = AttackConfig(checked.method, envelope=bounds, restarts=checked.restarts)
    except ValueError as error:
        raise RobustnessInputError(str(error)) from None
    return ProfileSettings(checked, radii, config, typical_views, float(fail_below), search_seeds)


@dataclass
class SeedRun:
    """One model's profile run under one seed: what it searched with and what it found."""

    seed: int
    built: Setup
    views: list
    config: object
    seeded: SeedProfile


def seed_run(model, scene, settings: ProfileSettings, seed: int) -> SeedRun:
    """The :class:`SeedRun` of ``model`` on ``scene`` under ``seed``, or
    :class:`RobustnessInputError` in one line."""
    from kadv.attack.init_views import InitViewError, fit_into_envelope

    built = setup(model, scene, dataclasses.replace(settings.checked, seed=seed))
    try:
        config = dataclasses.replace(settings.config, budget_passes=built.budget)
        views = [fit_into_envelope(built.renderer, v, config.envelope, built.penalty.margin) for v in built.views]
    except InitViewError as error:
        raise RobustnessInputError(f"scene {built.scene_name!r}: {error}") from None
    except ValueError as error:  # a budget too small for the method
        raise RobustnessInputError(f"budget_passes={built.budget}: {error}") from None
    seeded = profile_views(
        built.objective,
        built.differentiable,
        views,
        built.size,
        config,
        settings.radii,
        seed,
        settings.typical_views,
        settings.fail_below,
        settings.checked.progress,
        search_seeds=settings.search_seeds,
    )
    return SeedRun(seed, built, views, config, seeded)


def save_worst_pictures(run: SeedRun, radii) -> list[str]:
    """The four-panel picture of the worst view found within each radius, in the run's folder."""
    from kadv.report.run import save_view_picture

    pictures = []
    for k, ((degrees, metres), (init, record)) in enumerate(zip(radii, run.seeded.worst_views)):
        label = f"worst within {degrees:g}°, {metres:g} m"
        path = run.built.folder / f"{run.built.stem}-{run.config.envelope.name}-radius{k}.png"
        pictures.append(str(save_view_picture(path, run.built.render, init, record, label)))
    return pictures


def pool_worst_views(runs: list[SeedRun], radii, count: int = WARM_STARTS) -> int:
    """Score every run's model at the ``count`` worst views each other run's search found, per
    radius and init view, and lower its worst there where one of them is worse for it (the worst
    case over all the searches: common views for every model, as RobustBench pools its attacks).
    The runs must share their init views (the same scene and seed). Returns the views scored."""
    from kadv.attack import SearchContext

    scored = 0
    for run in runs:
        for k, (degrees, metres) in enumerate(radii):
            within = dataclasses.replace(run.config, max_angle_deg=degrees, max_distance=metres)
            for i, init in enumerate(run.views):
                others = [
                    record
                    for other in runs
                    if other is not run and torch.equal(other.views[i].world_T_cam, init.world_T_cam)
                    for record in worst_views(
                        other.seeded.results[k].views[i].records,
                        count,
                        within.min_separation,
                        within.min_separation_deg,
                    )
                ]
                if not others:
                    continue
                b = run.built
                context = SearchContext(b.objective, b.differentiable, init, *b.size, within)
                params = torch.tensor([r.params for r in others], dtype=torch.float64)
                run.seeded.pool(k, i, context.evaluate(0, params))
                scored += len(others)
    return scored
