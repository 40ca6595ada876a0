"""Is the worst case a measurement, at equal cost? Held-out regret, search noise with the init views
fixed, paired wins against the baselines at equal model passes and at equal seconds, and the cheap
fidelities' rank agreement and cost.

Cells: each scene's init views (the seven probes, the box room and grey_white_room; kadv-tiny, seed
0, fitted into the upright envelope: held fixed, common random numbers) times the nested radii of a
profile (5°/0.1 m, 15°/0.3 m, 45°/1 m). A run is one init view searched at every radius, smallest
first, as a profile searches (each radius warm-started from the worst views of the smaller ones,
the passes split over the radii as a profile splits them, ``kadv.attack.radii.ramp_shares``); its
worst at a radius is the lowest delta1 found within it or a smaller one. ``--scenes`` also takes
``modern_hall`` and ``japanese_classroom``, rooms no default was chosen on (never in ``all``).

Two regimes, one currency each:

- network-bound, **equal passes**: every method gets ``--budget`` model passes per init view and
  radius on average, every image the model runs on and every backward pass counted (the regime of every real
  model, where passes are the seconds);
- render-bound, **equal seconds**: every method, the default included, runs in the same process
  right after the default's pass-budget run, under ``budget_seconds`` equal to the seconds that run
  took at each radius (kadv-tiny on this CPU, where rendering dominates).

Methods: ``default`` (kadv's default search now: its screening's fidelity is ``auto``) and the
candidates for it: ``halving`` (black-box lanes, a screen at one ray per pixel), ``halving_gradient``
(gradient lanes through the render at one ray per pixel, each step they take validated exactly; the
same screen), ``halving_exact`` (black-box lanes, every view exact), ``halving_gradient_exact``
(gradient lanes through the exact render, every view exact), ``hybrid``, ``random``, ``cma``,
``nevergrad``, ``turbo`` (a Gaussian process in a trust region, BoTorch), ``halving_halved`` (four
black-box lanes, the lower half stopped every two steps); each over the same
``--seeds`` (five by default) in both regimes.
The default takes halving_exact's settings under a pass budget (those runs are shared) and, here,
halving's under a seconds budget: the three are one method for W*.

1. Best known worst case W*, held out: for a method, the lowest delta1 that the *other* methods'
   runs found in the cell (both regimes), and a reference attack at ``REFERENCE`` times the budget
   over four seeds, taken in turn by random search and IPOP-CMA-ES (two seeds each). The scored
   method never sets its own W*.
2. Regret (w - W*) / (w0 - W*) per cell and seed, w0 the init view's delta1: median and 90th
   percentile per method and regime.
3. Search noise: per cell, the sample standard deviation (ddof 1) of the worst over the seeds, the
   init views fixed; cells where every seed's worst is 0 are left out (saturated). Median with its
   95% bootstrap interval over cells, and the largest, per method and per radius.
4. Paired wins of the default against random, CMA-ES and nevergrad per cell and seed in each
   regime, with a sign test; its delta1 drop over random's at equal seconds at 5° and 15°.
5. The fidelities: per radius, Spearman's correlation of delta1 scored at one ray per pixel and by
   the reprojection of anchor layers against the exact render, over ``PROXY_VIEWS`` poses per
   cell (the first init view of each scene), and each one's milliseconds per view at 240x320 (the
   reprojection's: the one-ray cast it needs for the view's depth, the warp, and the model).
6. (``--parts budgets``, not run by default) The default (or each of ``--budget-methods``) alone
   at ``--budgets`` passes per init view and radius on average, split by each of ``--shares``
   (``default``, ``equal``, ``a:b:c``): its search noise per radius and its mean worst, which more
   passes lower.
7. (``--parts study``, not run by default) The study's own protocol, ``attack=gradient`` with 5
   restarts of 400 steps from the init view (the best restart kept; 4,005 passes), at the largest
   radius from the first init view of each probe and the box room, under ``--study-seeds``; the
   default's paired wins against it there, as a profile at ``--budget`` passes a radius and alone
   at the largest radius with the profile's passes, all of them there (as ``kadv-attack`` searches;
   a quarter of the protocol's passes or less): its worst at most as high counts as a win.

Runs are kept as JSON under ``--out/runs``, keyed by the method's config, budget, seed, the seconds
it was given, and a hash of the kadv source it depends on (every search method's module left out
but its own and those it imports): a run made by other code, settings or budget is never read, a
rerun resumes, and a change to one method reruns only the runs that depend on it. Last line:
``worst_case passes_per_view=... regret_median=... noise_median=... noise_max=... agreement_median=...
win_*_passes=... win_*_s=... drop_vs_random_r0=... screen_spearman_r0=... reproject_ms=... exact_ms=...``
(and ``noise_median_<budget>=...``, ``win_study_passes=... win_study_alone_passes=...``).
``agreement_median``: the median over the default's runs, at the largest radius, of the share of its
restarts that reached its worst.

Run: .venv/bin/python benchmarks/worst_case.py [--out outputs/worst_case] [--parts regret,proxy,budgets,study]
     [--scenes all|a,b] [--views scene:count,...] [--seeds 0,1,2,3,4] [--budget 48] [--methods ...]
     [--budgets 48,96,192] [--shares default,equal,1:1:2] [--study-seeds 0,1]
"""

from __future__ import annotations

import argparse
import ast
import dataclasses
import functools
import hashlib
import itertools
import json
import math
import time
from pathlib import Path

import common  # first: kadv's runtime settings, before torch starts its thread pool

import matplotlib
import numpy as np
import torch
from scipy.stats import binomtest, qmc, spearmanr

matplotlib.use("Agg")
import matplotlib.pyplot as plt

from kadv.attack import AttackConfig, CMASettings, GradientSettings, HalvingSettings, attack
from kadv.attack.init_views import fit_into_envelope
from kadv.attack.radii import radius_budgets
from kadv.attack.search import DEFAULT_METHOD, SearchContext
from kadv.catalogue.probes import PROBES, probe_scene
from kadv.geometry import perturb_world_T_cam
from kadv.io import atomic_write
from kadv.models import load_model
from kadv.render.dibr import Reprojection, warp_boxed
from kadv.render.layers import camera_face_normals, render_anchor
from kadv.testing.options import CheckOptions, setup
from kadv.testing.profile import DEFAULT_RADII, WARM_STARTS, warm_starts

ENVELOPE = "upright"
SCENES = (*PROBES, "box_room", "grey_white_room")
# rooms no default of the search was chosen on: named with --scenes, never in "all"
HELD_OUT = ("modern_hall", "japanese_classroom")
PARTS = ("regret", "proxy", "budgets", "study")
BASELINES = ("random", "cma", "nevergrad")
# label -> (method, settings); "default" is kadv's default search with its defaults
CANDIDATES = {
    "halving": ("halving", HalvingSettings(screen_supersample=1)),
    "halving_gradient": ("halving", HalvingSettings(screen_supersample=1, refine="gradient")),
    "halving_exact": ("halving", HalvingSettings(screen_supersample=None)),
    "halving_gradient_exact": ("halving", HalvingSettings(screen_supersample=None, refine="gradient")),
    "hybrid": ("hybrid", None),
    "random": ("random", None),
    "cma": ("cma", None),
    "nevergrad": ("nevergrad", None),
    "turbo": ("turbo", None),
    # four local lanes, the lower half stopped every two steps (attack.halving.halve_every)
    "halving_halved": ("halving", HalvingSettings(screen_supersample=None, lanes=4, halve_every=2)),
    "hybrid_warp": ("hybrid", None),
    "halving_gradient_warp": ("halving", HalvingSettings(screen_supersample=None, refine="gradient")),
}
# labels whose gradient lanes render through the warp (render=warp): the values of the steps between
# refreshes come from the anchor's reprojection, and the exact render validates what a lane takes
WARPED = {"hybrid_warp", "halving_gradient_warp"}
# The default screens exactly under a pass budget (halving_exact's config, so its runs at equal
# passes are the default's) and at one ray per pixel under a seconds budget when the render
# outweighs the model (halving's): one method, never the other's W*.
PASSES_TWIN = "halving_exact"
DEFAULT_FAMILY = {"default", "halving", "halving_exact"}
REFERENCE = 10  # the reference attack's budget, in budgets
REFERENCE_METHODS = {"ref_random": ("random", None), "ref_cma": ("cma", CMASettings(ipop=True))}
# label -> restarts of the default search (attack.restarts), each on a share of the budget
RESTARTED = {"default_r3": 3, "default_r5": 5}
# the study's protocol: 5 restarts x 400 gradient steps from the init view, the best restart kept
STUDY = {"study": ("gradient", GradientSettings(steps=400, restarts=5))}
STUDY_SCENES = (*PROBES, "box_room")
PROXY_VIEWS, TOP_K, PROXY_SIZE = 32, 8, (240, 320)
ANCHOR_LAYERS = 2  # the proxy's anchor: a second layer fills what the first hides from the init view
MIN_BUDGET = 7  # model passes per init view and radius at least (the default search's floor)
SATURATED = 1e-9  # a worst of delta1 at most this under every seed: nothing left to find


# kadv's source that a run's numbers come from (the commands, reports and test plumbing are left out)
VERSIONED = ("attack", "geometry", "losses", "models", "penalties", "render", "scenes", "testing/options.py",
             "testing/profile.py")  # fmt: skip


@functools.cache  # read once: the code this process runs, even if the files change while it runs
def source_version(method: str | None = None) -> str:
    """A hash of the kadv source a run's numbers come from: a run made by other code is never read back.

    ``method``: the source a run of that search method depends on, the search methods' modules left
    out but its own and those it imports (a change to one method keeps the others' runs, and the
    reference attack's); None: every module."""
    root = Path(__file__).resolve().parents[1] / "kadv"
    paths = [
        p
        for part in VERSIONED
        for p in (sorted((root / part).rglob("*.py")) if (root / part).is_dir() else [root / part])
    ]
    if method is not None:
        methods = root / "attack" / "methods"
        paths = [p for p in paths if p.parent != methods] + [
            methods / f"{m}.py" for m in _method_modules(methods, method)
        ]
    digest = hashlib.sha256()
    for path in paths:
        digest.update(str(path.relative_to(root)).encode() + path.read_bytes())
    return digest.hexdigest()[:12]


def _method_modules(folder: Path, name: str) -> list[str]:
    """The modules of kadv.attack.methods that method module ``name`` is made of: itself and those
    it imports, in turn, sorted."""
    found, todo = set(), [name]
    while todo:
        module = todo.pop()
        found.add(module)
        tree = ast.parse((folder / f"{module}.py").read_text())
        imported = {n.module for n in ast.walk(tree) if isinstance(n, ast.ImportFrom) and n.module}
        todo += [m.rsplit(".", 1)[1] for m in imported if m.startswith("kadv.attack.methods.")]
        todo = [m for m in todo if m not in found]
    return sorted(found)


def method_config(label: str, budget: int | None, seconds: float | None = None) -> AttackConfig:
    """The attack config of a label: ``budget`` passes per init view and radius, or ``seconds``."""
    if label == "default" or label in RESTARTED:
        method, settings = DEFAULT_METHOD, None
    else:
        method, settings = {**CANDIDATES, **REFERENCE_METHODS, **STUDY}[label]
    return AttackConfig(method, settings, budget_passes=budget, budget_seconds=seconds, envelope=ENVELOPE,
                        restarts=RESTARTED.get(label, 1))  # fmt: skip


class Cells:
    """One scene's search setup (kadv-tiny, seed 0): its init views in the envelope, built once."""

    def __init__(self, name: str) -> None:
        from common import load_bench_scene

        scene = probe_scene(name, 0) if name in PROBES else load_bench_scene(name)
        self.name = name
        self.built = setup(load_model("kadv_tiny"), scene, CheckOptions(seed=0, lighting=common.default_lighting()))
        envelope = AttackConfig(envelope=ENVELOPE).envelope
        margin = self.built.penalty.margin
        self.views = [fit_into_envelope(self.built.renderer, v, envelope, margin) for v in self.built.views]
        # the gradient lanes through the warp (conf/render/warp.yaml)
        self.warp = self.built.study.variant(render=common.render_preset("warp")).differentiable

    def run(self, view: int, config: AttackConfig, seed: int, seconds: list[float] | None = None,
            radii=DEFAULT_RADII, warped: bool = False, shares=None) -> dict:  # fmt: skip
        """The nested-radii search of one init view (``seconds``: per radius, replacing the pass
        budget; ``warped``: the gradient through ``render=warp``; ``shares``: the pass budget split
        over the radii by them, :func:`~kadv.attack.radii.radius_budgets`); per radius its curve of
        improvements, passes, seconds and agreement (the share of its restarts that reached its worst)."""
        b = self.built
        differentiable = self.warp if warped else b.differentiable
        results: list = []
        budgets = radius_budgets(config.budget_passes, len(radii), shares)
        for k, (degrees, metres) in enumerate(radii):
            within = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres, budget_passes=budgets[k])
            if seconds is not None:
                within = dataclasses.replace(within, budget_passes=None, budget_seconds=seconds[k])
            starts = warm_starts(results, 1, WARM_STARTS, config) if results else None
            results.append(attack(b.objective, differentiable, [self.views[view]], *b.size, within, seed,
                                  progress=False, starts=starts))  # fmt: skip
        rows = []
        for result in results:
            view_result = result.views[0]
            curve, best = [], math.inf
            for record in view_result.records:
                if record.rankable and record.delta1 < best:
                    best = record.delta1
                    curve.append([record.passes, record.seconds, best])
            budget, agreed = view_result.budget, view_result.agreement
            spent = {"passes": budget.passes, "screened": budget.screened, "seconds": budget.seconds}
            rows.append({"curve": curve, "agreement": agreed.reached / agreed.runs} | spent)
        return {"init": results[0].views[0].init_record.delta1, "radii": rows}


def worst_within(run: dict, radius: int) -> float:
    """The lowest delta1 the run found within radius ``radius`` or a smaller one."""
    return min([run["init"]] + [point[2] for k in range(radius + 1) for point in run["radii"][k]["curve"]])


class Store:
    """Runs on disk under ``out/runs``, keyed by config, budget, seed, seconds and the version of the
    source the method depends on."""

    def __init__(self, out: Path) -> None:
        self.folder = out / "runs"

    def run(self, cells: Cells, view: int, label: str, seed: int, budget: int | None, seconds=None,
            radii=DEFAULT_RADII, shares=None) -> dict:  # fmt: skip
        config = method_config(label, budget)
        key = [repr(config), seed, seconds, source_version(config.method), cells.name, view]
        key += ["render=warp"] if label in WARPED else []
        key += [] if shares is None else [f"shares={list(shares)}"]
        key = json.dumps(key + ([] if radii == DEFAULT_RADII else [radii]))  # the profile's radii: keys as before
        digest = hashlib.sha256(key.encode()).hexdigest()[:16]
        path = self.folder / f"{cells.name}-v{view}-{label}-s{seed}-{'s' if seconds else 'p'}-{digest}.json"
        if path.is_file():
            return json.loads(path.read_text())
        started = time.perf_counter()
        run = cells.run(view, config, seed, seconds, radii, warped=label in WARPED, shares=shares) | {"key": key}
        text = json.dumps(run)
        atomic_write(path, lambda tmp: tmp.write_text(text))
        worst = " ".join(f"{worst_within(run, k):.3f}" for k in range(len(radii)))
        regime = "equal seconds" if seconds else f"{run['radii'][-1]['passes'] if budget is None else budget} passes"
        print(f"  {cells.name} v{view} {label} seed {seed} ({regime}): worst {worst} "
              f"({time.perf_counter() - started:.0f} s)", flush=True)  # fmt: skip
        return run


def sign_test(wins: int, losses: int) -> float:
    return binomtest(wins, wins + losses).pvalue if wins + losses else math.nan


def regret(worst: float, init: float, best: float) -> float:
    """(w - W*) / (w0 - W*), floored at 0 (a run may beat the held-out W*); 0 where the init view
    is the best known (nothing to find)."""
    return 0.0 if init - best <= 1e-9 else max(0.0, worst - best) / (init - best)


def bootstrap_median(values: list[float], rng: np.random.Generator, draws: int = 2000) -> tuple[float, float]:
    """The 95% percentile-bootstrap interval of the median."""
    values = np.asarray(values)
    medians = np.median(values[rng.integers(0, len(values), size=(draws, len(values)))], axis=1)
    return float(np.percentile(medians, 2.5)), float(np.percentile(medians, 97.5))


class Runs:
    """Every run the regret part needs, made in order (the default at equal passes and then at its
    own seconds, then each other method at equal passes and at those seconds, cell view by cell
    view, seed by seed) or read back."""

    def __init__(self, store: Store, cells: dict[str, Cells], views: dict[str, int], seeds, budget, labels,
                 reference_seeds) -> None:  # fmt: skip
        self.seeds, self.labels = seeds, labels
        self.passes: dict = {}  # (scene, view, label, seed) -> run at equal passes
        self.seconds: dict = {}  # the same, at the default's seconds
        self.reference: dict = {}  # (scene, view) -> reference runs
        for name, cell in cells.items():
            for view in range(views[name]):
                for seed in seeds:
                    own = store.run(cell, view, "default", seed, budget)
                    self.passes[name, view, "default", seed] = own
                    spent = [r["seconds"] for r in own["radii"]]
                    self.seconds[name, view, "default", seed] = store.run(cell, view, "default", seed, budget, spent)
                    for label in labels:
                        if label == "default":
                            continue
                        if label != PASSES_TWIN:  # its runs at equal passes are the default's
                            self.passes[name, view, label, seed] = store.run(cell, view, label, seed, budget)
                        self.seconds[name, view, label, seed] = store.run(cell, view, label, seed, budget, spent)
                reference = list(REFERENCE_METHODS)  # the seeds taken in turn by random search and IPOP-CMA-ES
                self.reference[name, view] = [
                    store.run(cell, view, reference[i % len(reference)], seed, REFERENCE * budget)
                    for i, seed in enumerate(reference_seeds)
                ]
        radii = range(len(DEFAULT_RADII))
        self.cells = [(name, view, k) for name in cells for view in range(views[name]) for k in radii]

    def family(self, label: str) -> set[str]:
        """The labels that are one method with ``label``: the default and the settings it takes."""
        return DEFAULT_FAMILY if label in DEFAULT_FAMILY else {label}

    def worst(self, cell: tuple, label: str, seed: int, regime: str) -> float:
        name, view, k = cell
        if regime == "passes" and label == PASSES_TWIN:
            label = "default"
        run = (self.passes if regime == "passes" else self.seconds).get((name, view, label, seed))
        return math.nan if run is None else worst_within(run, k)

    def init(self, cell: tuple) -> float:
        return self.passes[cell[0], cell[1], "default", self.seeds[0]]["init"]

    def best_known(self, cell: tuple, label: str) -> tuple[float, str]:
        """W* held out from ``label``'s method: the other methods' runs (both regimes) and the
        reference; and which source set it."""
        name, view, k = cell
        held_out = self.family(label)
        best = (self.init(cell), "init")
        for (n, v, other, _), run in [*self.passes.items(), *self.seconds.items()]:
            if (n, v) == (name, view) and other not in held_out:
                best = min(best, (worst_within(run, k), other))
        for run in self.reference[name, view]:
            best = min(best, (worst_within(run, k), "reference"))
        return best

    def regrets(self, label: str, regime: str, radius: int | None = None) -> list[float]:
        out = []
        for cell in self.cells:
            if radius is not None and cell[2] != radius:
                continue
            best, _ = self.best_known(cell, label)
            for seed in self.seeds:
                value = self.worst(cell, label, seed, regime)
                if not math.isnan(value):
                    out.append(regret(value, self.init(cell), best))
        return out

    def noise(self, label: str, radius: int | None = None) -> list[float]:
        """Per unsaturated cell, the sample sd (ddof 1) of the worst over the seeds (equal passes)."""
        out = []
        for cell in self.cells:
            if radius is not None and cell[2] != radius:
                continue
            sd = seed_noise([self.worst(cell, label, seed, "passes") for seed in self.seeds])
            if sd is not None:
                out.append(sd)
        return out


def seed_noise(values: list[float]) -> float | None:
    """The sample sd (ddof 1) of one cell's worst over the seeds (NaN: a run missing), or None where
    it is not measured: fewer than two runs, or every worst 0 (saturated)."""
    values = [v for v in values if not math.isnan(v)]
    return float(np.std(values, ddof=1)) if len(values) >= 2 and max(values) > SATURATED else None


def regret_part(runs: Runs) -> dict[str, str]:
    """Parts 1-4."""
    rng = np.random.default_rng(0)
    figures: dict[str, str] = {}
    print(f"\n1-3. held-out regret per cell and seed ({len(runs.cells)} cells, seeds {runs.seeds}); "
          "search noise: sd (ddof 1) over the seeds per unsaturated cell, init views fixed")  # fmt: skip
    print("| method | regret median (passes) | p90 | regret median (seconds) | p90 | noise median (95%) | noise max "
          "| cells |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for label in runs.labels:
        passes, seconds = runs.regrets(label, "passes"), runs.regrets(label, "seconds")
        noise = runs.noise(label)
        lo, hi = bootstrap_median(noise, rng)
        seconds_text = f"{np.median(seconds):.3f} | {np.percentile(seconds, 90):.3f}"
        print(f"| {label} | {np.median(passes):.3f} | {np.percentile(passes, 90):.3f} | {seconds_text} | "
              f"{np.median(noise):.3f} ({lo:.3f}-{hi:.3f}) | {np.max(noise):.3f} | {len(noise)} |")  # fmt: skip
        if label == "default":
            agreed = [run["radii"][-1]["agreement"] for (*_, other, _), run in runs.passes.items() if other == label]
            figures |= {
                "regret_median": f"{np.median(passes):.3f}",
                "regret_p90": f"{np.percentile(passes, 90):.3f}",
                "noise_median": f"{np.median(noise):.3f}",
                "noise_max": f"{np.max(noise):.3f}",
                "agreement_median": f"{np.median(agreed):.2f}",
            }
    print("\n   per radius: regret median at equal passes / at equal seconds; noise median, max (unsaturated cells)")
    print("| method | " + " | ".join(f"{d:g}°/{m:g} m" for d, m in DEFAULT_RADII) + " |")
    print("|---|" + "---|" * len(DEFAULT_RADII))
    for label in runs.labels:
        cells = []
        for k in range(len(DEFAULT_RADII)):
            noise = runs.noise(label, k)
            seconds = f"{np.median(runs.regrets(label, 'seconds', k)):.3f}"
            cells.append(
                f"{np.median(runs.regrets(label, 'passes', k)):.3f} / {seconds}; "
                f"noise {np.median(noise):.3f}, {np.max(noise):.3f} ({len(noise)})"
            )
        print(f"| {label} | " + " | ".join(cells) + " |")
    sources: dict[str, int] = {}
    for cell in runs.cells:
        source = runs.best_known(cell, "default")[1]
        sources[source] = sources.get(source, 0) + 1
    share = {s: n / len(runs.cells) for s, n in sorted(sources.items(), key=lambda kv: -kv[1])}
    print("\n   W* held out from the default, set by: " + ", ".join(f"{s} {v:.2f}" for s, v in share.items()))
    figures |= {f"wstar_{s}": f"{v:.2f}" for s, v in share.items()}
    print("\n4. paired wins of the default per cell and seed (wins-losses-ties, share of decided, sign test p)")
    print("| against | equal passes | share | p | equal seconds | share | p |")
    print("|---|---|---|---|---|---|---|")
    drops = {k: [0.0, 0.0] for k in range(len(DEFAULT_RADII))}
    for baseline in [label for label in runs.labels if label not in runs.family("default")]:
        text = []
        for regime in ("passes", "seconds"):
            tally = [0, 0, 0]
            for cell in runs.cells:
                for seed in runs.seeds:
                    ours, theirs = runs.worst(cell, "default", seed, regime), runs.worst(cell, baseline, seed, regime)
                    if math.isnan(ours) or math.isnan(theirs):
                        continue
                    tally[0 if ours < theirs - 1e-9 else 1 if ours > theirs + 1e-9 else 2] += 1
                    if baseline == "random" and regime == "seconds":
                        drops[cell[2]][0] += runs.init(cell) - ours
                        drops[cell[2]][1] += runs.init(cell) - theirs
            wins, losses, ties = tally
            share = wins / (wins + losses) if wins + losses else math.nan
            text += [f"{wins}-{losses}-{ties}", f"{share:.2f}", f"{sign_test(wins, losses):.1e}"]
            if baseline in BASELINES:
                figures[f"win_{baseline}_{'passes' if regime == 'passes' else 's'}"] = f"{share:.2f}"
        print(f"| {baseline} | " + " | ".join(text) + " |")
    for k in (0, 1) if "random" in runs.labels else ():  # no random search run: no ratio to print
        ratio = drops[k][0] / drops[k][1] if drops[k][1] > 0 else math.inf
        figures[f"drop_vs_random_r{k}"] = f"{ratio:.2f}"
        print(f"   delta1 drop over random's at equal seconds within {DEFAULT_RADII[k][0]:g}°: {ratio:.2f}")
    return figures


def proxy_part(cells: dict[str, Cells], out: Path) -> dict[str, str]:
    """Part 5: delta1 on the exact render, at one ray per pixel and by the reprojection of anchor
    layers rendered at the init view (pixels the warp cannot fill shaded by one exact ray), over
    candidate poses per cell of each scene's first init view, at 240x320."""
    path = out / f"proxy-{source_version()}.json"
    table = json.loads(path.read_text()) if path.is_file() else {}
    for name, cell in cells.items():
        for k, (degrees, metres) in enumerate(DEFAULT_RADII):
            key = f"{name}/r{k}"
            if key not in table:
                table[key] = _proxy_cell(cell, degrees, metres)
                text = json.dumps(table)
                atomic_write(path, lambda tmp, t=text: tmp.write_text(t))
                print(f"  proxy {key}: " + ", ".join(f"{m} {table[key]['ms'][m]:.0f} ms" for m in table[key]["ms"]))
    print(f"\n5. the cheap fidelities against the exact render at {PROXY_SIZE[0]}x{PROXY_SIZE[1]}, per radius "
          "(median over cells)")  # fmt: skip
    print("| radius | one ray per pixel: Spearman | top-8 kept | reprojection: Spearman | top-8 kept | coverage |")
    print("|---|---|---|---|---|---|")
    figures, figure = {}, plt.figure(figsize=(4.0 * len(DEFAULT_RADII), 3.8))
    for k, (degrees, metres) in enumerate(DEFAULT_RADII):
        entries = [v for key, v in table.items() if key.endswith(f"/r{k}")]
        stats = {}
        for fidelity in ("ss1", "reprojection"):
            rho = [spearmanr(e["exact"], e[fidelity]).statistic for e in entries]
            kept = [_top_kept(e[fidelity], e["exact"]) for e in entries]
            stats[fidelity] = (float(np.nanmedian(rho)), float(np.mean(kept)))
        coverage = float(np.median([np.mean(e["coverage"]) for e in entries]))
        print(f"| {degrees:g}°/{metres:g} m | {stats['ss1'][0]:.3f} | {stats['ss1'][1]:.2f} | "
              f"{stats['reprojection'][0]:.3f} | {stats['reprojection'][1]:.2f} | {coverage:.2f} |")  # fmt: skip
        if k < 2:
            figures[f"screen_spearman_r{k}"] = f"{stats['ss1'][0]:.3f}"
        axis = figure.add_subplot(1, len(DEFAULT_RADII), k + 1)
        exact = np.concatenate([e["exact"] for e in entries])
        axis.scatter(exact, np.concatenate([e["reprojection"] for e in entries]), s=4, alpha=0.5, label="reprojection")
        axis.scatter(exact, np.concatenate([e["ss1"] for e in entries]), s=4, alpha=0.5, label="one ray per pixel")
        axis.plot([0, 1], [0, 1], color="grey", linewidth=0.8)
        axis.set_xlabel("delta1, exact render")
        axis.set_ylabel("delta1, cheap render")
        axis.set_title(f"{degrees:g}°/{metres:g} m: Spearman {stats['reprojection'][0]:.2f} | {stats['ss1'][0]:.2f}")
        axis.legend(fontsize=7, loc="upper left")
    figure.tight_layout()
    figure.savefig(out / "proxy.png", dpi=110)
    ms = {m: np.median([e["ms"][m] for e in table.values()]) for m in ("exact", "ss1", "reprojection", "warp")}
    listed = ", ".join(f"{m} {v:.1f}" for m, v in ms.items())
    print(
        f"   milliseconds per view, render and model (median over cells; warp: the reprojection's warp of "
        f"{ANCHOR_LAYERS} layers alone): {listed}"
    )
    figures |= {"reproject_ms": f"{ms['reprojection']:.1f}", "exact_ms": f"{ms['exact']:.1f}"}
    return figures


def _top_kept(cheap: list[float], exact: list[float]) -> float:
    """The share of the cheap fidelity's TOP_K lowest delta1 that are among the exact TOP_K lowest."""
    return len(set(np.argsort(cheap)[:TOP_K]) & set(np.argsort(exact)[:TOP_K])) / TOP_K


def _proxy_cell(cell: Cells, degrees: float, metres: float) -> dict:
    b = cell.built
    config = dataclasses.replace(method_config("random", 10**6), max_angle_deg=degrees, max_distance=metres)
    height, width = PROXY_SIZE
    context = SearchContext(b.objective, b.differentiable, cell.views[0], height, width, config)
    params = context.project(config.sample_ball(qmc.Sobol(6, scramble=True, seed=0).random(PROXY_VIEWS)))
    reached, _ = context.guard(torch.zeros_like(params[:, 3:]), params[:, 3:])
    params = torch.cat([params[:, :3], reached], dim=1)
    pose = perturb_world_T_cam(context.base(len(params)), params[:, :3], params[:, 3:])
    diff = b.differentiable.config
    anchor = render_anchor(b.renderer, context.base(1), context.K, height, width, ANCHOR_LAYERS, 32, diff.supersample)
    out = {"exact": [], "ss1": [], "reprojection": [], "coverage": [], "ms": {}}
    timing = dict.fromkeys(("exact", "ss1", "reprojection", "warp"), 0.0)
    with torch.no_grad():
        for chunk in pose.split(8):
            started = time.perf_counter()
            exact = b.renderer.render(chunk, context.K, height, width, supersample=diff.supersample)
            terms = b.objective(exact.rgb, exact.depth, exact.mask, chunk, context.K)
            timing["exact"] += time.perf_counter() - started
            started = time.perf_counter()
            cheap = b.renderer.render(chunk, context.K, height, width, supersample=1)
            cheap_terms = b.objective(cheap.rgb, cheap.depth, cheap.mask, chunk, context.K)
            timing["ss1"] += time.perf_counter() - started
            started = time.perf_counter()
            b.renderer.render(chunk, context.K, height, width, colour=False)  # what the warp's depth test needs
            cast = time.perf_counter() - started
            started = time.perf_counter()
            normals = camera_face_normals(b.renderer.surfaces, cheap.triangle_ids[:, 0], chunk).permute(0, 3, 1, 2)
            A_T_P = torch.linalg.inv(anchor.world_T_cam) @ chunk
            # view by view, as a search warps them: one anchor's maps, read in place
            warps = [warp_boxed(anchor.boxed, cheap.depth[i : i + 1], normals[i : i + 1].float(), A_T_P[i : i + 1],
                                context.K, diff.depth_tolerance) for i in range(len(chunk))]  # fmt: skip
            warp = Reprojection(
                *(torch.cat([getattr(w, f) for w in warps]) for f in ("rgb", "depth", "valid", "layer"))
            )
            rgb = torch.where(warp.valid, warp.rgb, cheap.rgb)  # the cast's own shading where the warp has none
            timing["warp"] += time.perf_counter() - started
            proxy_terms = b.objective(rgb, cheap.depth, cheap.mask, chunk, context.K)
            # a reprojected view's cost: the unshaded cast, the warp and the model (its holes' shading,
            # taken here from the one-ray render, left out)
            timing["reprojection"] += cast + time.perf_counter() - started
            out["exact"] += terms.delta1.tolist()
            out["ss1"] += cheap_terms.delta1.tolist()
            out["reprojection"] += proxy_terms.delta1.tolist()
            covered = warp.valid.sum(dim=(1, 2, 3)) / cheap.mask.sum(dim=(1, 2, 3)).clamp_min(1)
            out["coverage"] += covered.tolist()
    out["ms"] = {m: 1000 * t / len(pose) for m, t in timing.items()}
    return out


def budgets_part(
    store: Store, cells: dict[str, Cells], views: dict[str, int], seeds, budgets, labels=("default",),
    shares=(None,),
) -> dict[str, str]:  # fmt: skip
    """Part 6: the default (and the other ``labels``: ``default_r3``, its three restarts, or a candidate) alone at
    each of ``budgets`` passes per init view and radius on average, split over the radii by each of
    ``shares`` (None: kadv's default split; the init views fixed): its search noise per radius (median and
    largest over the unsaturated cells), its mean worst, which more passes lower, and the mean
    share of its restarts that reached each worst."""
    figures: dict[str, str] = {}
    print("\n6. at more passes: search noise median, max (unsaturated cells); mean worst; agreement, per radius")
    print(
        "| method | passes a radius | shares | "
        + " | ".join(f"{d:g}°/{m:g} m" for d, m in DEFAULT_RADII)
        + " | noise median |"
    )
    print("|---|---|---|" + "---|" * (len(DEFAULT_RADII) + 1))
    for label, budget, split in itertools.product(labels, budgets, shares):
        runs = [[store.run(cells[n], v, label, seed, budget, shares=split) for seed in seeds]
                for n in cells for v in range(views[n])]  # fmt: skip
        row, pooled = [], []
        for k in range(len(DEFAULT_RADII)):
            worsts = [[worst_within(run, k) for run in cell] for cell in runs]
            noise = [sd for sd in map(seed_noise, worsts) if sd is not None]
            pooled += noise
            agreed = np.mean([run["radii"][k]["agreement"] for cell in runs for run in cell])
            row.append(f"{np.median(noise):.3f}, {np.max(noise):.3f}; worst {np.mean(worsts):.3f}; "
                       f"agreed {agreed:.2f}")  # fmt: skip
        written = "default" if split is None else ":".join(f"{v:g}" for v in split)
        print(f"| {label} | {budget} | {written} | " + " | ".join(row) + f" | {np.median(pooled):.3f} |")
        suffix = ("" if label == "default" else f"_{label}") + ("" if split is None else f"_{written}")
        figures[f"noise_median_{budget}{suffix}"] = f"{np.median(pooled):.3f}"
    return figures


def study_part(store: Store, cells: dict[str, Cells], seeds: list[int], budget: int) -> dict[str, str]:
    """Part 7: the study's protocol against the default at the largest radius, per scene's first init
    view and seed: the default as a profile searches (``budget`` passes a radius on average, its
    worst within the largest radius or a smaller one) and as ``kadv-attack`` searches that radius
    alone (the profile's passes, all of them there)."""
    largest = DEFAULT_RADII[-1]
    within = f"{largest[0]:g}°/{largest[1]:g} m"
    alone = budget * len(DEFAULT_RADII)
    print(f"\n7. the study's protocol (gradient, 5 restarts x 400 steps) against the default within {within}: as a "
          f"profile at {budget} passes a radius, and alone at that radius with {alone} passes (first init view; "
          "worst delta1, passes, seconds)")  # fmt: skip
    print("| scene | seed | study: worst | passes | s | default, profile: worst | passes | s "
          "| default alone: worst | passes | s |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    tallies = {"profile": [0, 0], "alone": [0, 0]}  # the default's worst at most as high, higher
    for name, cell in cells.items():
        if name not in STUDY_SCENES:
            continue
        for seed in seeds:
            study = store.run(cell, 0, "study", seed, None, radii=(largest,))
            theirs = worst_within(study, 0)
            runs = {
                "profile": (store.run(cell, 0, "default", seed, budget), len(DEFAULT_RADII) - 1),
                "alone": (store.run(cell, 0, "default", seed, alone, radii=(largest,)), 0),
            }
            protocol = study["radii"][0]
            row = f"| {name} | {seed} | {theirs:.3f} | {protocol['passes']} | {protocol['seconds']:.0f} "
            for kind, (run, radius) in runs.items():
                ours = worst_within(run, radius)
                tallies[kind][0 if ours <= theirs + 1e-9 else 1] += 1
                spent = sum(r["passes"] for r in run["radii"]), sum(r["seconds"] for r in run["radii"])
                row += f"| {ours:.3f} | {spent[0]} | {spent[1]:.0f} "
            print(row + "|")
    for kind, tally in tallies.items():
        print(f"   the default ({kind}): worst at most as high as the protocol's on {tally[0]} of {sum(tally)}")
    share = {kind: tally[0] / sum(tally) if sum(tally) else math.nan for kind, tally in tallies.items()}
    return {"win_study_passes": f"{share['profile']:.2f}", "win_study_alone_passes": f"{share['alone']:.2f}"}


def parse_shares(parser: argparse.ArgumentParser, item: str) -> tuple[float, ...] | None:
    """One ``--shares`` item: None for ``default`` (kadv's split, :func:`~kadv.attack.radii.ramp_shares`),
    ones for ``equal``, else one positive number a radius; a bad one ends the script in one line
    (exit status 2)."""
    if item == "default":
        return None
    if item == "equal":
        return (1.0,) * len(DEFAULT_RADII)
    try:
        values = tuple(float(v) for v in item.split(":"))
        radius_budgets(MIN_BUDGET, len(DEFAULT_RADII), values)
    except ValueError:
        parser.error(f"--shares: {item!r} is not 'default', 'equal' or {len(DEFAULT_RADII)} positive numbers a:b:c")
    return values


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="outputs/worst_case")
    parser.add_argument("--parts", default="regret,proxy", help=f"of {', '.join(PARTS)}")
    parser.add_argument("--scenes", default="all")
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--budget", type=int, default=48, help="model passes per init view and radius")
    parser.add_argument("--views", default="", help="scene:count,...: measure only a scene's first init views")
    parser.add_argument("--methods", default=",".join(["default", *CANDIDATES]), help="the methods compared")
    parser.add_argument("--reference-seeds", default="100,101,102,103", help="the reference attack's seeds (none: '')")
    parser.add_argument("--budgets", default="48,96,192", help="part budgets: the default's passes a radius")
    parser.add_argument("--study-seeds", default="0,1", help="part study: the seeds of both searches")
    parser.add_argument("--budget-methods", default="default",
                        help=f"part budgets: default, {', '.join(RESTARTED)} or a --methods choice")  # fmt: skip
    parser.add_argument("--shares", default="default", help="part budgets: splits of the passes over the radii, "
                        "comma-separated, each 'default' (kadv's), 'equal' or a:b:c")  # fmt: skip
    args = parser.parse_args()
    out, parts = Path(args.out), args.parts.split(",")
    names = list(SCENES) if args.scenes == "all" else args.scenes.split(",")
    labels = args.methods.split(",")
    common.check_names(parser, {"--parts": (parts, PARTS), "--scenes": (names, SCENES + HELD_OUT),
                                "--methods": (labels, ("default", *CANDIDATES))})  # fmt: skip
    common.check_names(
        parser, {"--budget-methods": (args.budget_methods.split(","), ("default", *RESTARTED, *CANDIDATES))}
    )
    if "default" not in labels:
        parser.error("--methods: the default is what the benchmark scores; name it")
    if args.budget < MIN_BUDGET:
        parser.error(f"--budget: at least {MIN_BUDGET} model passes (the default search's floor), got {args.budget}")
    budgets = common.integer_list(parser, "--budgets", args.budgets, least=MIN_BUDGET)
    shares = [parse_shares(parser, item) for item in args.shares.split(",")]
    seeds = common.integer_list(parser, "--seeds", args.seeds)
    reference = common.integer_list(parser, "--reference-seeds", args.reference_seeds, empty=True)
    study_seeds = common.integer_list(parser, "--study-seeds", args.study_seeds, empty=True)
    if len(seeds) < 2:
        parser.error("--seeds: at least two, for the search noise")
    most: dict[str, int] = {}  # checked before any scene is built
    for item in filter(None, args.views.split(",")):
        name, _, count = item.partition(":")
        common.check_names(parser, {"--views": ([name], names)})
        if not count.isdigit() or int(count) < 1:
            parser.error(f"--views: {item!r} is not scene:count with a count of 1 or more")
        most[name] = int(count)
    out.mkdir(parents=True, exist_ok=True)
    cells = {name: Cells(name) for name in names}
    views = {name: min(len(cell.views), most.get(name, math.inf)) for name, cell in cells.items()}
    figures = {"passes_per_view": str(args.budget * len(DEFAULT_RADII))}
    if "regret" in parts:
        figures |= regret_part(Runs(Store(out), cells, views, seeds, args.budget, labels, reference))
    if "proxy" in parts:
        figures |= proxy_part(cells, out)
    if "budgets" in parts:
        figures |= budgets_part(Store(out), cells, views, seeds, budgets, args.budget_methods.split(","), shares)
    if "study" in parts:
        figures |= study_part(Store(out), cells, study_seeds, args.budget)
    print("worst_case " + " ".join(f"{k}={v}" for k, v in figures.items()))


if __name__ == "__main__":
    main()
