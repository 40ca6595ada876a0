"""``kadv-probe``: the probe scorecard of one or more depth models, ranked.

    kadv-probe model=kadv_tiny
    kadv-probe model=kadv_tiny,kadv_tiny_dpt seeds=0,1,2 envelope=upright
    kadv-probe model=kadv_tiny search_seeds=3          (the search noise, apart from the init views)
    kadv-probe model=kadv_tiny restarts=3 budget=144   (three runs a search: the agreement of each worst)
    kadv-probe model=kadv_tiny probes=thin_structures,window budget=96 out=outputs/probe_tiny
    kadv-probe model=kadv_tiny radius_shares=1,1,1     (the passes split equally over the radii)

Each model is profiled on each probe scene (:mod:`kadv.probes`), the probe built at each seed:
the worst delta1 within each nested radius of the camera's move and the camera envelope, the
failure rate of views drawn at the largest radius, and the score (mean ± spread over the seeds).
It is a suite run (:mod:`kadv.bench`): the probes at the seeds are frozen into a suite with
model-free init views, and each model's run is an entry that ``kadv-bench verify`` checks; each
model's suite score stands beside its areas. The table ends with ``ranking:`` lines; it is printed
as Markdown and written with a PNG of the profile curves to ``out`` (``scorecard.md``,
``scorecard.json``: every profile, to rank again with :meth:`kadv.testing.Scorecard.from_dict`;
``scorecard.png``; ``views/``: the worst views' pictures, the suite file and the entries). Run
again with the same ``out``, it resumes from the run units already written.

A plain command rather than a Hydra app: a scorecard is one job over its models and probes (the
sweep is inside it), so it needs neither launchers nor a run directory per override. Its keys are
written as Hydra's are (``key=value``), and ``hydra.run.dir=`` names the output folder as ``out=``
does, so that the commands' habits carry over.
"""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import json
import sys
from pathlib import Path

from kadv.cli.common import config_int
from kadv.io import atomic_write

__all__ = ["main"]

_KEYS = {
    "model": "kadv_tiny",
    "probes": "all",
    "seeds": "0",
    "seed": None,
    "envelope": "upright",
    "budget": None,
    "search_seeds": "1",
    "restarts": "1",
    "radius_shares": None,
    "alignment": None,
    "lighting": "baked",
    "out": "outputs/probe",
    "hydra.run.dir": None,
}


def _arguments(argv: list[str]) -> dict[str, str]:
    values = dict(_KEYS)
    for argument in argv:
        key, equals, value = argument.partition("=")
        if argument in ("-h", "--help"):
            print(
                __doc__.strip() + f"\n\nkeys (key=value): {', '.join(f'{k} (default {v})' for k, v in _KEYS.items())}"
            )
            sys.exit(0)
        if not equals or key not in _KEYS:
            raise ValueError(f"{argument!r}: expected key=value with a key of {', '.join(_KEYS)}")
        values[key] = value
    return values


def _int(text: str, key: str, minimum: int) -> int:
    try:
        number = int(text)
    except ValueError:
        number = text
    return config_int(number, key, minimum)


def _seeds(values: dict[str, str | None]) -> tuple[int, ...]:
    if values["seed"] is not None:  # one seed, as the other commands take it
        return (_int(values["seed"], "seed", 0),)
    seeds = tuple(_int(text, "seeds", 0) for text in (values["seeds"] or "").split(",") if text)
    if not seeds:
        raise ValueError("seeds is empty: give one or more integers >= 0, e.g. seeds=0,1,2")
    return seeds


def _shares(text: str | None) -> tuple[float, ...] | None:
    """``radius_shares=1,2,3``: one positive share a radius (None: the default split)."""
    if text is None:
        return None
    try:
        return tuple(float(v) for v in text.split(","))
    except ValueError:
        raise ValueError(
            f"radius_shares must be numbers, one a radius, e.g. radius_shares=1,2,3, got {text!r}"
        ) from None


def main(argv: list[str] | None = None) -> None:
    from kadv.penalties import get_envelope
    from kadv.testing import DEFAULT_BUDGET, RobustnessInputError, scorecard

    try:
        values = _arguments(sys.argv[1:] if argv is None else argv)
        models = [name for name in values["model"].split(",") if name]
        probes = None if values["probes"] == "all" else [name for name in values["probes"].split(",") if name]
        seeds = _seeds(values)
        envelope = get_envelope(values["envelope"])
        # 2: the default search's own floor (the init view and one more)
        budget = DEFAULT_BUDGET if values["budget"] is None else _int(values["budget"], "budget", 2)
        if values["lighting"] not in ("baked", "direct"):
            raise ValueError(f"lighting must be 'baked' or 'direct', got {values['lighting']!r}")
        out = Path(values["hydra.run.dir"] or values["out"])
        card = scorecard(
            models,
            probes,
            seeds=seeds,
            envelope=envelope,
            budget_passes=budget,
            search_seeds=_int(values["search_seeds"], "search_seeds", 1),
            restarts=_int(values["restarts"], "restarts", 1),
            radius_shares=_shares(values["radius_shares"]),
            alignment=values["alignment"],
            artifacts=out / "views",
            lighting=values["lighting"],
            progress=True,
        )
    except (RobustnessInputError, ValueError) as error:
        print(f"kadv-probe: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    table, data = card.markdown(), json.dumps(card.to_dict())
    atomic_write(out / "scorecard.md", lambda tmp: tmp.write_text(table + "\n"))
    atomic_write(out / "scorecard.json", lambda tmp: tmp.write_text(data + "\n"))
    card.save_png(out / "scorecard.png")
    views, short = out / "views", card.suite["hash"][:12]
    print(f"\n{table}\n\nscorecard: {out / 'scorecard.md'}, {out / 'scorecard.json'}, {out / 'scorecard.png'}")
    print(
        f"suite and entries: {views / f'suite-{short}.json'}, {views / 'entries'}/<model>-{short}/entry.json "
        f"(kadv-bench verify ENTRY suite={views / f'suite-{short}.json'} model=MODEL checks one)"
    )


if __name__ == "__main__":
    main()
