"""Profile: a model's viewpoint robustness on one scene against the radius of the camera's move,
over seeds: per radius the worst view the search finds and the typical view, their areas (the
scores), the search's noise and agreement, and their table and pictures.

Adversarial robustness reports accuracy over the perturbation's size in the same way; RoboDepth
averages over severities. The searches it is made from: :mod:`kadv.attack.radii`."""

from __future__ import annotations

import dataclasses
import itertools
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from kadv.attack.radii import FAIL_BELOW, SeedProfile
from kadv.io import save_figure

__all__ = ["Profile", "curve_area", "save_profile_panels"]


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
        space: where that alignment was fitted (the model's output kind's own space).
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
    space: str = "disparity"

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
        space: str = "disparity",
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
            space=space,
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
            f"{self.alignment} alignment in {self.space} space: {np.mean(self.delta1_init):.3f} at the init views",
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
