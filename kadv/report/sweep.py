"""Reading a sweep's run directories and turning them into the study's tables and more.

Table 2: adversarial L_depth and delta1 per model x scene with averages; Table 3: the change from
the init views (adversarial - init for L_depth, init - adversarial for delta1); the method table
(each method's gain, model passes and seconds per model x scene); the profile tables of profile runs
(``attack.radii``: Table 2's delta1 at each radius); the transfer matrix.
"""

from __future__ import annotations

import csv
import io
import statistics
from collections import defaultdict
from dataclasses import dataclass, field
from pathlib import Path

import yaml

from kadv.attack.profile import Profile
from kadv.io import atomic_write
from kadv.report.store import SUMMARY
from kadv.report.summary import RunSummary

__all__ = [
    "RunRecord",
    "Table",
    "collect_runs",
    "main_method",
    "method_table",
    "methods_of",
    "profile_tables",
    "profiles_of",
    "table2",
    "table3",
]


@dataclass
class RunRecord:
    """One complete run directory: its summary, its resolved config and where it is."""

    path: Path
    summary: RunSummary
    config: dict

    @property
    def model(self) -> str:
        return self.summary.model

    @property
    def scene(self) -> str:
        return self.summary.scene

    @property
    def method(self) -> str:
        return self.summary.method


@dataclass
class Table:
    """A table with a header row; cells are strings or numbers."""

    title: str
    header: list[str]
    rows: list[list] = field(default_factory=list)

    def markdown(self, digits: int = 4) -> str:
        def cell(value) -> str:
            return f"{value:.{digits}f}" if isinstance(value, float) else str(value)

        lines = [f"| {' | '.join(self.header)} |", f"|{'---|' * len(self.header)}"]
        lines += [f"| {' | '.join(cell(v) for v in row)} |" for row in self.rows]
        return "\n".join(lines) + "\n"

    def csv(self) -> str:
        buffer = io.StringIO()
        writer = csv.writer(buffer, lineterminator="\n")
        writer.writerow(self.header)
        writer.writerows(self.rows)
        return buffer.getvalue()

    def write(self, folder: Path, stem: str) -> list[Path]:
        markdown, text = f"## {self.title}\n\n{self.markdown()}", self.csv()
        return [
            atomic_write(folder / f"{stem}.md", lambda tmp: tmp.write_text(markdown)),
            atomic_write(folder / f"{stem}.csv", lambda tmp: tmp.write_text(text)),
        ]


def collect_runs(paths: list[str | Path]) -> list[RunRecord]:
    """Complete runs under the given sweep or run directories (those holding ``summary.json``).

    Raises:
        FileNotFoundError: a path that does not exist.
        ValueError: no complete run under any of the paths, or a summary this kadv cannot read.
    """
    runs, seen = [], set()
    for path in map(Path, paths):
        if not path.exists():
            raise FileNotFoundError(f"no such run or sweep directory: {path}")
        for summary in sorted([path / SUMMARY] if (path / SUMMARY).is_file() else path.rglob(SUMMARY)):
            run_dir = summary.parent.resolve()
            if run_dir in seen:
                continue
            seen.add(run_dir)
            config_file = run_dir / "config.yaml"
            config = yaml.safe_load(config_file.read_text()) if config_file.is_file() else {}
            runs.append(RunRecord(run_dir, RunSummary.read(summary), config))
    if not runs:
        raise ValueError(f"no complete run (a folder with {SUMMARY}) under {', '.join(map(str, paths))}")
    return runs


def methods_of(runs: list[RunRecord]) -> list[str]:
    """The search methods present, in alphabetical order."""
    return sorted({r.method for r in runs})


def main_method(runs: list[RunRecord]) -> str:
    """The method with the most runs (ties: alphabetical), whose views the transfer matrix re-renders."""
    counts = defaultdict(int)
    for run in runs:
        counts[run.method] += 1
    return min(counts, key=lambda method: (-counts[method], method))


def _grid(runs: list[RunRecord], method: str, value) -> tuple[list[str], list[str], dict[tuple[str, str], float]]:
    """Mean of ``value(run)`` per (model, scene) over the runs of ``method``."""
    cells: dict[tuple[str, str], list[float]] = defaultdict(list)
    for run in runs:
        if run.method == method:
            cells[run.model, run.scene].append(value(run))
    models = sorted({m for m, _ in cells})
    scenes = sorted({s for _, s in cells})
    return models, scenes, {key: statistics.mean(values) for key, values in cells.items()}


def _paired_table(
    title: str, runs: list[RunRecord], method: str, first: tuple[str, object], second: tuple[str, object]
) -> Table:
    """Models as rows; per scene a column pair (first, second); then their averages over scenes."""
    grids = [_grid(runs, method, getter) for _, getter in (first, second)]
    models, scenes = grids[0][0], grids[0][1]
    header = ["model"] + [f"{scene} {name}" for scene in scenes for name in (first[0], second[0])]
    header += [f"Avg {first[0]}", f"Avg {second[0]}"]
    table = Table(title, header)
    for model in models:
        row: list = [model]
        averages: list[list[float]] = [[], []]
        for scene in scenes:
            for k, (_, _, values) in enumerate(grids):
                value = values.get((model, scene))
                row.append(value if value is not None else "")
                if value is not None:
                    averages[k].append(value)
        row += [statistics.mean(a) if a else "" for a in averages]
        table.rows.append(row)
    footer: list = ["Avg"]
    for column in range(1, len(header)):
        values = [row[column] for row in table.rows if isinstance(row[column], float)]
        footer.append(statistics.mean(values) if values else "")
    table.rows.append(footer)
    return table


def _alignments(runs: list[RunRecord], method: str) -> str:
    """The alignments (``loss.alignment``) that one method's runs scored delta1 after, each with
    the space it was fitted in: ``scale_shift alignment in disparity space``."""
    fits = {f"{r.summary.alignment} alignment in {r.summary.space} space" for r in runs if r.method == method}
    return " or ".join(sorted(fits))


def table2(runs: list[RunRecord], method: str) -> Table:
    """The study's Table 2 for one method's runs: adversarial L_depth (higher: worse for the model)
    and delta1 (lower: worse)."""
    return _paired_table(
        f"Table 2: adversarial views ({method} attack; delta1 after {_alignments(runs, method)})",
        runs,
        method,
        ("L_depth", lambda r: r.summary.adversarial_l_depth),
        ("delta1", lambda r: r.summary.adversarial_delta1),
    )


def table3(runs: list[RunRecord], method: str) -> Table:
    """The study's Table 3 for one method's runs: adversarial - init for L_depth, init - adversarial
    for delta1."""
    return _paired_table(
        f"Table 3: change from the init views ({method} attack; delta1 after {_alignments(runs, method)})",
        runs,
        method,
        ("dL_depth", lambda r: r.summary.adversarial_l_depth - r.summary.init_l_depth),
        ("ddelta1", lambda r: r.summary.init_delta1 - r.summary.adversarial_delta1),
    )


def method_table(runs: list[RunRecord]) -> Table | None:
    """Per model x scene x method: L_depth gain, model passes and seconds per init view (None with one method)."""
    if len({r.method for r in runs}) < 2:
        return None
    cells: dict[tuple[str, str, str], list[RunRecord]] = defaultdict(list)
    for run in runs:
        cells[run.model, run.scene, run.method].append(run)
    table = Table(
        "Methods at equal budget",
        ["model", "scene", "method", "L_depth gain", "delta1 drop", "model passes / init view", "seconds / init view"],
    )
    for (model, scene, method), group in sorted(cells.items()):
        views = [v for run in group for v in run.summary.init_views]
        table.rows.append(
            [
                model,
                scene,
                method,
                statistics.mean(r.summary.adversarial_l_depth - r.summary.init_l_depth for r in group),
                statistics.mean(r.summary.init_delta1 - r.summary.adversarial_delta1 for r in group),
                statistics.mean(v.budget.passes for v in views),
                statistics.mean(v.budget.seconds for v in views),
            ]
        )
    return table


def profiles_of(runs: list[RunRecord]) -> dict[tuple[str, str, str], Profile]:
    """The profile runs' profiles, merged over seeds per (model, scene, method) and the same radii
    and envelope (the first such group wins a key; the key names the method)."""
    groups: dict[tuple, list[Profile]] = defaultdict(list)
    for run in runs:
        if run.summary.profile is not None:
            profile = Profile.from_dict(run.summary.profile)
            groups[run.model, run.scene, run.method, profile.radii, profile.envelope].append(profile)
    merged: dict[tuple[str, str, str], Profile] = {}
    for (model, scene, method, _, _), profiles in sorted(groups.items(), key=lambda item: item[0][:3]):
        merged.setdefault((model, scene, method), Profile.merge(profiles))
    return merged


def profile_tables(runs: list[RunRecord]) -> list[Table]:
    """Per set of radii and envelope, one table of the profile runs: per model x scene x method, the
    delta1 at the init views, the worst delta1 at each radius (Table 2's delta1, radius by radius),
    the failure rate of drawn views at the largest radius, and the score with its spread over seeds."""
    tables: dict[tuple, Table] = {}
    for (model, scene, method), profile in profiles_of(runs).items():
        key = (profile.radii, profile.envelope)
        if key not in tables:
            radii = [f"{d:g}°/{m:g} m" for d, m in profile.radii]
            tables[key] = Table(
                f"Profiles: worst delta1 per radius (envelope {profile.envelope})",
                ["model", "scene", "method", "seeds", "delta1 init", *(f"worst {r}" for r in radii)]
                + [f"failure rate {radii[-1]}", "score", "score spread"],
            )
        tables[key].rows.append(
            [
                model,
                scene,
                method,
                len(profile.seeds),
                float(statistics.mean(profile.delta1_init)),
                *profile.worst,
                profile.failure_rate[-1],
                profile.score,
                profile.score_spread,
            ]
        )
    return list(tables.values())
