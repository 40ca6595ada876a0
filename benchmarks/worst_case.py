"""Is the worst case a measurement? Regret against the best known worst case, search noise, paired
wins against the baselines, the cheap fidelity's rank agreement, and the noise family's order.

Cells: each scene's init views (the seven probes, the box room and grey_white_room; kadv-tiny, seed
0, fitted into the upright envelope: held fixed, common random numbers) times the nested radii of a
profile (5°/0.1 m, 15°/0.3 m, 45°/1 m). A run is one init view searched at every radius, smallest
first, as a profile searches (kadv.testing.profile.search_radii: the default warm-starts each
radius from the worst views of the smaller ones); a view's worst at a radius is the lowest delta1
found within it or a smaller one. Methods: ``default`` (kadv's default search now), ``hybrid`` (the
default before), ``random``, ``cma``, ``nevergrad``, and ``local`` (the default with black-box
lanes instead of gradient lanes: what the gradient earns).

1. Best known worst case W* per cell: the lowest delta1 any run of any method found, among them
   CMA-ES at 5x the budget over four seeds; kept in ``--out/pool-<scene>.json``, lowered by any
   later run, as RobustBench keeps its best-known attacks.
2. Regret (w - W*) / (w0 - W*) per cell and seed, w0 the init view's delta1: median and 90th
   percentile per method at 1x, and the default's at 0.5x, 1x and 2x. Seeds per run (``PLAN``):
   five for the default at 1x, four for CMA-ES, three for hybrid and random search, two for
   nevergrad at 1x, one for its long run, the default at 0.5x and 2x, and ``local`` (the medians of
   those are over cells).
3. Search noise: per cell, the standard deviation (and range) of the worst delta1 over the seeds.
4. Paired wins of the default against random, CMA-ES and nevergrad per cell and seed, at equal
   evaluations (the budget's exact evaluations) and at equal seconds (the baseline's best within
   the default's seconds at that radius, read from a run of 3x the budget, 5x for CMA-ES), sign
   test.
5. The cheap fidelity: at each radius, Spearman's correlation between delta1 scored on a cheap
   render and on the exact one, over 64 candidate poses per cell, for the default's screening (one
   ray per pixel) and for the reprojection of anchor layers rendered at the init view; the share of
   each one's top 8 that is in the exact top 8; their seconds per view. ``proxy.png``: the
   reprojection's delta1 against the exact, per radius.
6. The noise family's order under the worst case (benchmarks/ranking.py's family, profiled as one
   scorecard: the default search, each model also scored at the others' worst views; kept in
   ``--out/family.json``): on how many probe-seed pairs the worst-case area falls strictly with sigma.

Every run is kept as JSON under ``--out`` as soon as it is made, and a rerun reads it back, so the
benchmark can be run in pieces (``--parts``, ``--scenes``, ``--seeds``); ``--budget`` is the
default budget (evaluations per init view and radius). The last line:
``worst_case regret_median=... regret_p90=... noise_median=... win_random=... ...``.

Run: .venv/bin/python benchmarks/worst_case.py [--out outputs/worst_case] [--parts ...] [--scenes all|a,b]
     [--seeds 0,1,2,3,4] [--budget 48] [--views scene:count,...]
"""

from __future__ import annotations

import argparse
import dataclasses
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

from kadv.attack import AttackConfig, HalvingSettings
from kadv.attack.init_views import fit_into_envelope
from kadv.attack.search import DEFAULT_METHOD, SearchContext
from kadv.geometry import perturb_world_T_cam
from kadv.io import atomic_write
from kadv.models import load_model
from kadv.render.dibr import reproject
from kadv.render.layers import AnchorLayers, camera_face_normals, render_anchor
from kadv.scenes.probes import PROBES, probe_scene
from kadv.testing.options import CheckOptions, setup
from kadv.testing.profile import DEFAULT_RADII, search_radii

ENVELOPE = "upright"
SCENES = (*PROBES, "box_room", "grey_white_room")
BASELINES = ("random", "cma", "nevergrad")
PARTS = ("regret", "wins", "proxy", "family")
# the baselines' long runs, in budgets: their best within the default's seconds is read from them;
# CMA-ES's over four seeds at five budgets is also what W* asks of some method at least
LONG = {"random": 3, "cma": 5, "nevergrad": 3}
# (method, budgets, seeds): the default over five seeds, for the noise; the rest as a 2-core CPU affords
PLAN = (
    ("default", 1, 5),
    ("hybrid", 1, 3),
    ("random", LONG["random"], 3),
    ("cma", LONG["cma"], 4),
    ("nevergrad", 1, 2),
    ("nevergrad", LONG["nevergrad"], 1),
    ("default", 0.5, 1),
    ("default", 2, 1),
    ("local", 1, 1),
)
PROXY_VIEWS, TOP_K = 64, 8
# baselines that ask and tell without knowing the budget: their run at 1x is the long run's prefix
PREFIX_METHODS = ("random", "cma")


def method_config(method: str, budget: int) -> AttackConfig:
    """The attack config of a method label at an evaluation budget."""
    if method == "default":
        return AttackConfig(DEFAULT_METHOD, budget_evaluations=budget, envelope=ENVELOPE)
    if method == "local":
        return AttackConfig("halving", HalvingSettings(refine="local"), budget_evaluations=budget, envelope=ENVELOPE)
    return AttackConfig(method, budget_evaluations=budget, envelope=ENVELOPE)


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

    def run(self, view: int, method: str, seed: int, budget: int) -> dict:
        """The nested-radii search of one init view; per radius its curve and worst view."""
        b = self.built
        started = time.perf_counter()
        results = search_radii(
            b.objective,
            b.differentiable,
            [self.views[view]],
            b.size,
            method_config(method, budget),
            DEFAULT_RADII,
            seed,
        )
        radii = []
        for result in results:
            view_result = result.views[0]
            curve, best, exact = [], math.inf, 0
            for record in view_result.records:
                exact += not record.screened
                if record.rankable and record.delta1 < best:
                    best = record.delta1
                    curve.append([exact, record.seconds, best, record.params])
            radii.append(
                {
                    "curve": curve,
                    "evaluations": view_result.budget.forward,
                    "screened": view_result.budget.screened,
                    "seconds": view_result.budget.seconds,
                }
            )
        init = results[0].views[0].init_record.delta1
        return {"init": init, "radii": radii, "seconds": time.perf_counter() - started}


def worst_within(run: dict, radius: int, evaluations: float = math.inf, seconds: float = math.inf) -> float:
    """The lowest delta1 within radius ``radius`` (or a smaller one) that the run found within its
    first ``evaluations`` exact evaluations and ``seconds`` at each radius (``seconds``: a list per radius)."""
    limits = seconds if isinstance(seconds, list) else [seconds] * (radius + 1)
    best = run["init"]
    for k in range(radius + 1):
        for count, at, delta1, _ in run["radii"][k]["curve"]:
            if count <= evaluations and at <= limits[k]:
                best = min(best, delta1)
    return best


class Store:
    """The runs and the pool of one scene under ``out``, read back on a rerun."""

    def __init__(self, out: Path, cells: Cells, name: str) -> None:
        self.out, self.cells, self.name = out, cells, name
        self.pool_path = out / f"pool-{name}.json"
        self.pool = json.loads(self.pool_path.read_text()) if self.pool_path.is_file() else {}

    def run(self, view: int, method: str, seed: int, multiple: float, budget: int) -> dict:
        path = self.out / "runs" / f"{self.name}-v{view}-{method}-s{seed}-x{multiple:g}.json"
        if path.is_file():
            return json.loads(path.read_text())
        if method in PREFIX_METHODS:  # a longer run of a method blind to its budget holds this one
            longer = sorted(path.parent.glob(f"{self.name}-v{view}-{method}-s{seed}-x*.json"))
            if longer:
                return json.loads(longer[-1].read_text())
        run = self.cells.run(view, method, seed, max(2, round(multiple * budget)))
        text = json.dumps(run)
        atomic_write(path, lambda tmp: tmp.write_text(text))
        self.join_pool(view, run, f"{method} seed {seed} x{multiple:g}")
        print(f"  {self.name} v{view} {method} seed {seed} x{multiple:g}: worst "
              + " ".join(f"{worst_within(run, k):.3f}" for k in range(len(DEFAULT_RADII)))
              + f" ({run['seconds']:.0f} s)", flush=True)  # fmt: skip
        return run

    def join_pool(self, view: int, run: dict, source: str) -> None:
        """Any view lower than the pool's at its cell joins the pool (W*)."""
        changed = False
        for k, radius in enumerate(run["radii"]):
            for _, _, delta1, params in radius["curve"]:
                key = f"v{view}/r{k}"
                if key not in self.pool or delta1 < self.pool[key]["delta1"]:
                    self.pool[key] = {"delta1": delta1, "params": params, "source": source}
                    changed = True
        if changed:
            text = json.dumps(self.pool, indent=1)
            atomic_write(self.pool_path, lambda tmp: tmp.write_text(text))

    def best_known(self, view: int, radius: int) -> float:
        """W*: the pool's lowest delta1 within the radius (a smaller radius's views lie within it)."""
        return min(self.pool[f"v{view}/r{k}"]["delta1"] for k in range(radius + 1) if f"v{view}/r{k}" in self.pool)


def regret(worst: float, init: float, best: float) -> float:
    """(w - W*) / (w0 - W*); 0 where the init view is the best known (nothing to find)."""
    return 0.0 if init - best <= 1e-9 else (worst - best) / (init - best)


def sign_test(wins: int, losses: int) -> float:
    return binomtest(wins, wins + losses).pvalue if wins + losses else math.nan


class Runs:
    """Every run parts 1-4 need, made or read back, and the worst each found under a limit."""

    def __init__(self, stores: dict[str, Store], views: dict[str, int], seeds: list[int], budget: int) -> None:
        self.stores, self.seeds, self.budget = stores, seeds, budget
        self.runs: dict = {}
        for name, store in stores.items():
            for view in range(views[name]):
                for method, multiple, count in PLAN:
                    for seed in seeds[:count]:
                        self.runs[name, view, method, seed, multiple] = store.run(view, method, seed, multiple, budget)
        radii = range(len(DEFAULT_RADII))
        self.cells = [(name, view, k) for name in stores for view in range(views[name]) for k in radii]

    def worst(self, cell: tuple, method: str, seed: int, multiple: float = 1, seconds=math.inf) -> float:
        """The method's worst delta1 in ``cell`` under ``seed`` at ``multiple`` budgets (and within
        ``seconds`` per radius); NaN where it has no such run. A baseline that asks without knowing
        the budget is read from its long run's first evaluations."""
        name, view, k = cell
        run = self.runs.get((name, view, method, seed, multiple))
        if run is None and method in PREFIX_METHODS:
            run = self.runs.get((name, view, method, seed, LONG[method]))
            return math.nan if run is None else worst_within(run, k, multiple * self.budget, seconds)
        return math.nan if run is None else worst_within(run, k, seconds=seconds)

    def long(self, cell: tuple, method: str, seed: int) -> dict | None:
        """The baseline's long run (its best within the default's seconds is read from it), if made."""
        return self.runs.get((cell[0], cell[1], method, seed, LONG[method]))

    def init(self, cell: tuple) -> float:
        return self.runs[cell[0], cell[1], "default", self.seeds[0], 1]["init"]

    def regrets(self, cell: tuple, method: str, multiple: float = 1) -> tuple[list[float], list[float]]:
        """The regret under each seed it was run with, and the worst delta1 under each."""
        best = self.stores[cell[0]].best_known(cell[1], cell[2])
        values = [self.worst(cell, method, seed, multiple) for seed in self.seeds]
        values = [v for v in values if not math.isnan(v)]
        return [regret(v, self.init(cell), best) for v in values], values


def regret_part(runs: Runs) -> dict[str, str]:
    """Parts 1-3: regret and search noise per method and budget, and the default's per radius."""
    figures = {}
    print("\n1-2. regret (w - W*) / (w0 - W*) per cell and seed at the budget; search noise over seeds per cell")
    print("| method | budget | regret median | regret p90 | noise median (sd) | noise median (range) | mean worst |")
    print("|---|---|---|---|---|---|---|")
    rows = [("default", 0.5), ("default", 1), ("default", 2)] + [(m, 1) for m in ("hybrid", "local", *BASELINES)]
    for method, multiple in rows:
        regrets, values = zip(*(runs.regrets(cell, method, multiple) for cell in runs.cells))
        flat = [r for cell in regrets for r in cell]
        sds, ranges = [float(np.std(v)) for v in values], [float(np.ptp(v)) for v in values]
        print(
            f"| {method} | {multiple:g}x | {np.median(flat):.3f} | {np.percentile(flat, 90):.3f} | "
            f"{np.median(sds):.3f} | {np.median(ranges):.3f} | {np.mean([x for v in values for x in v]):.3f} |"
        )
        if (method, multiple) == ("default", 1):
            figures |= {
                "regret_median": f"{np.median(flat):.3f}",
                "regret_p90": f"{np.percentile(flat, 90):.3f}",
                "noise_median": f"{np.median(sds):.3f}",
            }
    print("\n   the default at 1x per radius: regret median, noise median (sd)")
    for k, (degrees, metres) in enumerate(DEFAULT_RADII):
        regrets, values = zip(*(runs.regrets(cell, "default") for cell in runs.cells if cell[2] == k))
        sds = [float(np.std(v)) for v in values]
        print(f"   {degrees:g}°/{metres:g} m: {np.median([r for c in regrets for r in c]):.3f}, {np.median(sds):.3f}")
    return figures


def wins_part(runs: Runs, subject: str = "default") -> dict[str, str]:
    """Part 4: the paired wins of ``subject`` (the default; ``hybrid``, the default before) at equal
    evaluations and seconds, and its delta1 drop against random's at equal seconds; the figures of
    the last line are the default's."""
    figures = {}
    print(f"\n3. paired wins of {subject} (1x) per cell and seed: equal evaluations | equal seconds")
    print("| against | wins-losses-ties (evaluations) | share | sign test p | wins-losses-ties (seconds) | share | p |")
    print("|---|---|---|---|---|---|---|")
    drops = {k: [0.0, 0.0] for k in range(len(DEFAULT_RADII))}
    for baseline in [m for m in (*BASELINES, "hybrid") if m != subject]:
        tallies = {"evaluations": [0, 0, 0], "seconds": [0, 0, 0]}
        short = 0
        for cell in runs.cells:
            name, view, k = cell
            for seed in runs.seeds:
                ours = runs.worst(cell, subject, seed)
                if math.isnan(ours):
                    continue
                spent = [r["seconds"] for r in runs.runs[name, view, subject, seed, 1]["radii"]]
                theirs = {"evaluations": runs.worst(cell, baseline, seed)}
                long_run = runs.long(cell, baseline, seed) if baseline in BASELINES else None
                if long_run is not None:
                    theirs["seconds"] = worst_within(long_run, k, seconds=spent)
                    short += long_run["radii"][k]["seconds"] < spent[k]  # it ran out before the default's time
                for scale, value in theirs.items():
                    if math.isnan(value):
                        continue
                    tallies[scale][0 if ours < value - 1e-9 else 1 if ours > value + 1e-9 else 2] += 1
                if baseline == "random" and "seconds" in theirs:
                    drops[k][0] += runs.init(cell) - ours
                    drops[k][1] += runs.init(cell) - theirs["seconds"]
        text = []
        for scale, (wins, losses, ties) in tallies.items():
            share = wins / (wins + losses) if wins + losses else math.nan
            text += [f"{wins}-{losses}-{ties}", f"{share:.2f}", f"{sign_test(wins, losses):.1e}"]
            if baseline in BASELINES and subject == "default":
                figures[f"win_{baseline}" + ("" if scale == "evaluations" else "_s")] = f"{share:.2f}"
        print(f"| {baseline} | " + " | ".join(text) + " |" + (f" ({short} long runs ended first)" if short else ""))
    for k in (0, 1):
        ratio = f"{drops[k][0] / drops[k][1]:.2f}" if drops[k][1] > 0 else "inf"
        if subject == "default":
            figures[f"drop_vs_random_r{k}"] = ratio
        print(f"   delta1 drop over random's at equal seconds within {DEFAULT_RADII[k][0]:g}°: {ratio}")
    return figures


def _expanded(anchor: AnchorLayers, batch: int) -> AnchorLayers:
    """One anchor's layers repeated for ``batch`` views (views, not copies)."""
    maps = {n: getattr(anchor, n).expand(batch, *getattr(anchor, n).shape[1:]) for n in ("rgb", "points", "normals")}
    maps |= {n: getattr(anchor, n).expand(batch, *getattr(anchor, n).shape[1:]) for n in ("triangle_ids", "mask")}
    return dataclasses.replace(
        anchor, world_T_cam=anchor.world_T_cam.expand(batch, 4, 4), K=anchor.K.expand(batch, 3, 3), **maps
    )


def proxy_part(stores: dict[str, Store], views: dict[str, int], out: Path) -> dict[str, str]:
    """Part 5: delta1 on the exact render, the screening's one ray per pixel and the reprojection of
    anchor layers at the init view (pixels the warp cannot fill shaded by one exact ray), over
    candidate poses per cell."""
    path = out / "proxy.json"
    table = json.loads(path.read_text()) if path.is_file() else {}
    for name, store in stores.items():
        for view in range(views[name]):
            for k, (degrees, metres) in enumerate(DEFAULT_RADII):
                key = f"{name}/v{view}/r{k}"
                if key in table:
                    continue
                table[key] = _proxy_cell(store.cells, view, degrees, metres)
                text = json.dumps(table)
                atomic_write(path, lambda tmp, t=text: tmp.write_text(t))
                print(f"  proxy {key}: " + ", ".join(f"{m} {table[key]['ms'][m]:.0f} ms" for m in table[key]["ms"]))
    print("\n4. the cheap fidelities against the exact render, per radius (median over cells)")
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
        print(
            f"| {degrees:g}°/{metres:g} m | {stats['ss1'][0]:.3f} | {stats['ss1'][1]:.2f} | "
            f"{stats['reprojection'][0]:.3f} | {stats['reprojection'][1]:.2f} | {coverage:.2f} |"
        )
        if k < 2:
            figures[f"proxy_spearman_r{k}"] = f"{stats['reprojection'][0]:.3f}"
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
    ms = {m: np.median([e["ms"][m] for e in table.values()]) for m in ("exact", "ss1", "reprojection")}
    print("   seconds per view (median over cells): " + ", ".join(f"{m} {v:.1f} ms" for m, v in ms.items()))
    return figures


def _top_kept(cheap: list[float], exact: list[float]) -> float:
    """The share of the cheap fidelity's TOP_K lowest delta1 that are among the exact TOP_K lowest."""
    return len(set(np.argsort(cheap)[:TOP_K]) & set(np.argsort(exact)[:TOP_K])) / TOP_K


def _proxy_cell(cells: Cells, view: int, degrees: float, metres: float) -> dict:
    b = cells.built
    config = method_config("random", 10**6)
    config = dataclasses.replace(config, max_angle_deg=degrees, max_distance=metres)
    context = SearchContext(b.objective, b.differentiable, cells.views[view], *b.size, config)
    height, width = b.size
    params = context.project(config.sample_ball(qmc.Sobol(6, scramble=True, seed=view).random(PROXY_VIEWS)))
    reached, _ = context.guard(torch.zeros_like(params[:, 3:]), params[:, 3:])
    params = torch.cat([params[:, :3], reached], dim=1)
    pose = perturb_world_T_cam(context.base(len(params)), params[:, :3], params[:, 3:])
    diff = b.differentiable.config
    anchor = render_anchor(b.renderer, context.base(1), context.K, height, width, 2, 32, diff.supersample)
    out = {"exact": [], "ss1": [], "reprojection": [], "coverage": [], "ms": {}}
    timing = dict.fromkeys(("exact", "ss1", "reprojection"), 0.0)
    with torch.no_grad():
        for chunk in pose.split(16):
            started = time.perf_counter()
            exact = b.renderer.render(chunk, context.K, height, width, supersample=diff.supersample)
            terms = b.objective(exact.rgb, exact.depth, exact.mask, chunk, context.K)
            timing["exact"] += time.perf_counter() - started
            started = time.perf_counter()
            cheap = b.renderer.render(chunk, context.K, height, width, supersample=1)
            cheap_terms = b.objective(cheap.rgb, cheap.depth, cheap.mask, chunk, context.K)
            timing["ss1"] += time.perf_counter() - started
            started = time.perf_counter()
            normals = camera_face_normals(b.renderer.surfaces, cheap.triangle_ids[:, 0], chunk).permute(0, 3, 1, 2)
            layers = _expanded(anchor, len(chunk))
            A_T_P = torch.linalg.inv(layers.world_T_cam) @ chunk
            warp = reproject(layers, cheap.depth, normals.float(), A_T_P, context.K)
            rgb = torch.where(warp.valid, warp.rgb, cheap.rgb)  # the cast's own shading where the warp has none
            proxy_terms = b.objective(rgb, cheap.depth, cheap.mask, chunk, context.K)
            timing["reprojection"] += time.perf_counter() - started
            out["exact"] += terms.delta1.tolist()
            out["ss1"] += cheap_terms.delta1.tolist()
            out["reprojection"] += proxy_terms.delta1.tolist()
            covered = warp.valid.sum(dim=(1, 2, 3)) / cheap.mask.sum(dim=(1, 2, 3)).clamp_min(1)
            out["coverage"] += covered.tolist()
    # the reprojection's time leaves out the one-ray cast it needs for the exact depth (it reuses ss1's)
    out["ms"] = {m: 1000 * t / len(pose) for m, t in timing.items()}
    return out


def family_part(out: Path, probes: list[str], seeds: list[int], budget: int) -> dict[str, str]:
    """Part 6: benchmarks/ranking.py's noise family on the probes, as one scorecard (the default
    search, its worst views pooled over the family's searches); kept in ``out/family.json``."""
    from ranking import SIGMAS, NoisyDepth

    from kadv.testing import Profile, scorecard

    path = out / "family.json"
    kept = json.loads(path.read_text()) if path.is_file() else {}
    tiny = load_model("kadv_tiny")
    family = [NoisyDepth(tiny, s) if s else tiny for s in SIGMAS]
    for probe, seed in itertools.product(probes, seeds):
        if f"{probe}/{seed}" in kept:
            continue
        card = scorecard(family, [probe], seeds=(seed,), envelope=ENVELOPE, budget_evaluations=budget,
                         artifacts=out / "family_views")  # fmt: skip
        kept[f"{probe}/{seed}"] = {m.name: card.results[probe][m.name].to_dict() for m in family}
        text = json.dumps(kept)
        atomic_write(path, lambda tmp, t=text: tmp.write_text(t))
    strict, rows = 0, []
    for probe, seed in itertools.product(probes, seeds):
        areas = [Profile.from_dict(kept[f"{probe}/{seed}"][m.name]).worst_score for m in family]
        falling = all(a > b for a, b in itertools.pairwise(areas))
        strict += falling
        text = " | ".join(f"{a:.3f}" for a in areas)
        rows.append(f"| {probe} | {seed} | {text} | {'yes' if falling else 'NO'} |")
    print("\n5. the noise family's worst-case area (sigma " + ", ".join(f"{s:g}" for s in SIGMAS) + ")")
    print("| probe | seed | " + " | ".join(f"sigma {s:g}" for s in SIGMAS) + " | strictly falling |")
    print("|---|---|" + "---|" * (len(SIGMAS) + 1))
    print("\n".join(rows))
    return {"family_worst_strict": f"{strict}/{len(rows)}"}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", default="outputs/worst_case")
    parser.add_argument("--parts", default=",".join(PARTS))
    parser.add_argument("--scenes", default="all")
    parser.add_argument("--seeds", default="0,1,2,3,4")
    parser.add_argument("--family-seeds", default="0,1,2")
    parser.add_argument("--budget", type=int, default=48, help="evaluations per init view and radius")
    parser.add_argument("--views", default="", help="scene:count,...: measure only a scene's first init views")
    args = parser.parse_args()
    out, parts = Path(args.out), args.parts.split(",")
    names = list(SCENES) if args.scenes == "all" else args.scenes.split(",")
    common.check_names(parser, {"--parts": (parts, PARTS), "--scenes": (names, SCENES)})
    seeds = [int(s) for s in args.seeds.split(",")]
    most: dict[str, int] = {}  # checked before any scene is built
    for item in filter(None, args.views.split(",")):
        name, _, count = item.partition(":")
        common.check_names(parser, {"--views": ([name], names)})
        if not count.isdigit() or int(count) < 1:
            parser.error(f"--views: {item!r} is not scene:count with a count of 1 or more")
        most[name] = int(count)
    out.mkdir(parents=True, exist_ok=True)
    stores = {name: Store(out, Cells(name), name) for name in names}
    views = {name: min(len(store.cells.views), most.get(name, math.inf)) for name, store in stores.items()}
    figures: dict[str, str] = {}
    if {"regret", "wins"} & set(parts):
        runs = Runs(stores, views, seeds, args.budget)
        if "regret" in parts:
            figures |= regret_part(runs)
        if "wins" in parts:
            figures |= wins_part(runs)
            wins_part(runs, "hybrid")  # the default before, for comparison
    if "proxy" in parts:
        figures |= proxy_part(stores, views, out)
    if "family" in parts:
        probes = [n for n in names if n in PROBES]
        figures |= family_part(out, probes, [int(s) for s in args.family_seeds.split(",")], args.budget)
    print("worst_case " + " ".join(f"{k}={v}" for k, v in figures.items()))


if __name__ == "__main__":
    main()
