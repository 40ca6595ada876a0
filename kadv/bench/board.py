"""A leaderboard of entries from any lab: one Markdown table, one HTML page and one JSON file, and a
picture of each model's worst delta1 against the radius.

Entries of one model identity (its weights' digest and inference settings) with disjoint seeds
pool as more replicates.
Entries of another suite, one model name with two identities, overlapping seeds of one identity,
an entry missing a cell, entries whose bake version is not the suite's, and entries of kadv
versions listed in :data:`DIVERGENT_VERSIONS` are refused in one line naming the file and the
field; another torch build or device only warns.
"""

from __future__ import annotations

import base64
import html
import itertools
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from kadv.bench.entry import Entry
from kadv.bench.scores import Z95, Pooled, SuiteScore, best_known, paired_difference, pool_units, suite_score
from kadv.bench.suite import BenchError, Suite
from kadv.bench.verify import check_complete
from kadv.io import atomic_write, save_figure, write_json
from kadv.report.sweep import Table

__all__ = ["DIVERGENT_VERSIONS", "Leaderboard", "Row", "leaderboard", "read_entries", "suite_table2"]

# kadv versions whose entries give other figures than today's for the same suite and model (a bug
# fixed since): their entries are refused in a table. None yet.
DIVERGENT_VERSIONS: dict[str, str] = {}


@dataclass(frozen=True)
class Row:
    """One model's line: its identity, pooled cells, scores and best-known worst case."""

    name: str
    identity: dict
    files: list[str]
    pooled: Pooled
    score: SuiteScore
    best: tuple[float, list[float]]


@dataclass(frozen=True)
class Leaderboard:
    """The models' rows (highest suite score first), the paired verdicts between neighbours, and
    the warnings about builds and devices."""

    suite: Suite
    rows: list[Row]
    pairs: list[tuple[str, str, float, float]]
    warnings: list[str]
    pooled: dict[str, tuple[float, list[float]]] | None = None

    def ranking_text(self) -> str:
        """``a > b ~ c``: ``>`` where the paired difference's 95% interval over seeds excludes 0."""
        if not self.rows:
            return ""
        text = self.rows[0].name
        for (_, second, mean, se), _row in zip(self.pairs, self.rows[1:]):
            apart = abs(mean) > Z95 * se
            text += f" {'>' if apart else '~'} {second}"
        return text

    def markdown(self) -> str:
        """The table: per model the suite score per radius and overall with its interval over
        seeds, the interval over scenes, the best-known worst case, the init delta1, AbsRel."""
        protocol = self.suite.protocol
        radii = [f"{d:g}°/{m:g} m" for d, m in protocol.radii]
        lines = [
            f"suite {self.suite.name} ({self.suite.hash[:12]}): worst delta1 found, mean over cells of the "
            f"seed-averaged worst; delta1 after {protocol.fit_text}; "
            f"{protocol.method}, {protocol.passes_per_view} passes per init view and seed",
            "",
            "| model | init | " + " | ".join(radii) + " | suite score (95% over seeds) | over scenes (95%) "
            "| best-known | AbsRel | seeds |" + (" pooled worst (the others' poses too) |" if self.pooled else ""),
            "|---" * (len(radii) + 7 + bool(self.pooled)) + "|",
        ]
        for row in self.rows:
            score = row.score
            lo, hi = score.overall_interval
            slo, shi = score.scenes_interval
            cells = " | ".join(f"{m:.3f} ± {1.96 * s:.3f}" for m, s in zip(score.per_radius, score.per_radius_se))
            lines.append(
                f"| {row.name} | {score.init:.3f} | {cells} | {score.overall:.3f} ({lo:.3f}-{hi:.3f}) | "
                f"{slo:.3f}-{shi:.3f} | {row.best[0]:.3f} | {score.abs_rel:.3f} | {len(score.seeds)} |"
                + (f" {self.pooled[row.name][0]:.3f} |" if self.pooled else "")
            )
        lines += ["", f"ranking: {self.ranking_text()}"]
        for first, second, mean, se in self.pairs:
            lines.append(f"paired: {first} - {second} = {mean:+.3f} ± {1.96 * se:.3f} (95% over seeds)")
        lines += [f"warning: {w}" for w in self.warnings]
        names = [row.name for row in self.rows]
        lines += ["", "per scene, the worst delta1 at each radius (" + ", ".join(radii) + "):", ""]
        lines += ["| scene | " + " | ".join(names) + " |", "|---" * (len(names) + 1) + "|"]
        for scene in self.suite.scenes:
            cells = [" / ".join(f"{v:.3f}" for v in row.score.per_scene[scene.name]) for row in self.rows]
            lines.append(f"| {scene.name} | " + " | ".join(cells) + " |")
        return "\n".join(lines)

    def to_dict(self) -> dict:
        return {
            "suite": {"name": self.suite.name, "hash": self.suite.hash},
            "models": [
                {
                    "name": row.name,
                    "identity": row.identity,
                    "files": row.files,
                    "score": row.score.to_dict(),
                    "best_known": {"overall": row.best[0], "per_radius": row.best[1]},
                }
                | ({"pooled_worst": dict(zip(("overall", "per_radius"), self.pooled[row.name]))} if self.pooled else {})
                for row in self.rows
            ],
            "paired": [{"first": a, "second": b, "difference": m, "se": s} for a, b, m, s in self.pairs],
            "ranking": self.ranking_text(),
            "warnings": self.warnings,
        }

    def save_png(self, path: str | Path) -> Path:
        """Each model's suite score against the radius, with its 95% band over seeds."""
        import matplotlib.pyplot as plt

        figure, axis = plt.subplots(figsize=(5.5, 4.0))
        radii = self.suite.protocol.radii
        steps = np.arange(len(radii) + 1)
        for row in self.rows:
            means = np.array([row.score.init, *row.score.per_radius])
            half = 1.96 * np.array([0.0, *row.score.per_radius_se])
            axis.plot(steps, means, marker="o", label=f"{row.name} ({row.score.overall:.3f})")
            axis.fill_between(steps, means - half, means + half, alpha=0.2, linewidth=0)
        axis.set_xticks(steps, ["init"] + [f"{d:g}°\n{m:g} m" for d, m in radii])
        axis.set_ylim(0, 1.02)
        axis.set_ylabel("worst delta1 (band: 95% over seeds)")
        axis.set_title(f"suite {self.suite.name}")
        axis.legend(loc="lower left", fontsize=8)
        figure.tight_layout()
        return save_figure(Path(path), figure)

    def write(self, out: str | Path) -> list[Path]:
        """``leaderboard.md``, ``leaderboard.json``, ``leaderboard.png`` and ``leaderboard.html``
        (self-contained: the picture inline) under ``out``."""
        out = Path(out)
        table = self.markdown()
        written = [
            atomic_write(out / "leaderboard.md", lambda tmp: tmp.write_text(table + "\n")),
            write_json(out / "leaderboard.json", self.to_dict()),
            self.save_png(out / "leaderboard.png"),
        ]
        picture = base64.b64encode(written[-1].read_bytes()).decode()
        page = _page(self.suite.name, table, picture)
        written.append(atomic_write(out / "leaderboard.html", lambda tmp: tmp.write_text(page)))
        return written


def _page(title: str, table: str, picture: str) -> str:
    """An HTML page of the Markdown ``table`` (its pipe rows as a table, the other lines as
    paragraphs) and the picture."""
    body, rows = [], []
    for line in table.splitlines() + [""]:
        if line.startswith("|"):
            if not set(line) <= set("|-"):
                rows.append([html.escape(c.strip()) for c in line.strip("|").split("|")])
            continue
        if rows:
            head, *rest = rows
            body.append(
                "<table><thead><tr>" + "".join(f"<th>{c}</th>" for c in head) + "</tr></thead><tbody>"
                + "".join("<tr>" + "".join(f"<td>{c}</td>" for c in r) + "</tr>" for r in rest)
                + "</tbody></table>"
            )  # fmt: skip
            rows = []
        if line:
            body.append(f"<p>{html.escape(line)}</p>")
    style = (
        "body{font-family:sans-serif;margin:2em}table{border-collapse:collapse}td,th{border:1px solid #999;padding:4px}"
    )
    return (
        f"<!doctype html><html><head><meta charset='utf-8'><title>kadv leaderboard: {html.escape(title)}</title>"
        f"<style>{style}</style></head><body><h1>{html.escape(title)}</h1>{''.join(body)}"
        f"<img alt='suite score against the radius' src='data:image/png;base64,{picture}'></body></html>"
    )


def leaderboard(
    suite: Suite, entries: dict[str, Entry], pooled: dict[str, tuple[float, list[float]]] | None = None
) -> Leaderboard:
    """The leaderboard of ``entries`` (by file) on ``suite`` (see the module docstring), with the
    models' pooled worst case (:func:`kadv.bench.pooled_worst`) as a column of its own when given.

    Raises:
        BenchError: in one line naming the file and the field.
    """
    groups: dict[str, list[tuple[str, Entry]]] = {}
    warnings: list[str] = []
    builds = {(e.environment.get("torch"), e.environment.get("device")) for e in entries.values()}
    if len(builds) > 1:
        warnings.append(
            "entries come from other torch builds or devices: "
            + ", ".join(f"{torch} on {device}" for torch, device in sorted(builds, key=str))
        )
    for path, entry in entries.items():
        check_complete(entry, suite, f"entry {path}")
        if entry.bake_version != suite.bake_version:
            raise BenchError(
                f"entry {path}: bake_version {entry.bake_version} lights the scenes otherwise than the suite's "
                f"{suite.bake_version}"
            )
        if entry.kadv_version in DIVERGENT_VERSIONS:
            reason = DIVERGENT_VERSIONS[entry.kadv_version]
            raise BenchError(f"entry {path}: kadv_version {entry.kadv_version} gives other figures ({reason})")
        group = groups.setdefault(entry.model["name"], [])
        for other_path, other in group:
            for field in ("weights", "settings"):
                if other.model.get(field, {}) != entry.model.get(field, {}):
                    raise BenchError(
                        f"entry {path}: model.{field}: {entry.model['name']!r} has another identity in {other_path}"
                    )
            if set(other.seeds) & set(entry.seeds):
                raise BenchError(
                    f"entry {path}: seeds {sorted(set(other.seeds) & set(entry.seeds))} also in {other_path}"
                )
        group.append((path, entry))
    rows = []
    for name, group in groups.items():
        cells = pool_units(suite, [entry for _, entry in group])
        rows.append(
            Row(name, group[0][1].model, [p for p, _ in group], cells, suite_score(suite, cells), best_known(cells))
        )
    rows.sort(key=lambda row: (-row.score.overall, row.name))
    pairs = []
    for first, second in itertools.pairwise(rows):
        try:
            mean, se, _ = paired_difference(first.pooled, second.pooled)
        except ValueError:
            mean, se = first.score.overall - second.score.overall, float("nan")
        pairs.append((first.name, second.name, mean, se))
    return Leaderboard(suite, rows, pairs, warnings, pooled)


def read_entries(paths: list[str | Path]) -> dict[str, Entry]:
    """The entries in ``paths``, by path."""
    from kadv.bench.entry import load_entry

    return {str(path): load_entry(path) for path in paths}


def suite_table2(suite: Suite, entries: dict[str, Entry]) -> Table:
    """The study's Table 2 from suite entries: per model (rows) and scene (column pairs), the
    adversarial L_depth and delta1 at the largest radius, means over the scene's init views and the
    entries' seeds, then their averages over scenes."""
    largest = suite.protocol.radii[-1]
    protocol = suite.protocol
    table = Table(
        f"Table 2: adversarial views within {largest[0]:g}°, {largest[1]:g} m (suite {suite.name}, "
        f"{protocol.method}; delta1 after {protocol.fit_text})",
        ["model"]
        + [f"{s.name} {v}" for s in suite.scenes for v in ("L_depth", "delta1")]
        + ["Avg L_depth", "Avg delta1"],
    )
    models: dict[str, list[Entry]] = {}
    for entry in entries.values():
        models.setdefault(entry.model["name"], []).append(entry)
    for name, group in sorted(models.items()):
        row: list = [name]
        for scene in range(len(suite.scenes)):
            cells = [u.cells[-1] for e in group for u in e.units if u.scene == scene]
            row += [float(np.mean([c.l_depth for c in cells])), float(np.mean([c.delta1 for c in cells]))]
        row += [float(np.mean(row[1::2])), float(np.mean(row[2::2]))]
        table.rows.append(row)
    return table
