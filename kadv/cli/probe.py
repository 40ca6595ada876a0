"""``kadv-probe``: the probe scorecard of one or more depth models.

    kadv-probe model=kadv_tiny
    kadv-probe model=kadv_tiny,kadv_tiny_dpt probes=thin_structures,window budget=96

Each model is attacked on each probe scene (:mod:`kadv.probes`) from the probe's init views; the
scorecard (delta1 at the init views -> at the worst view found, per probe and model) is printed as
a Markdown table and written with a PNG of the worst views to ``out`` (``scorecard.md``,
``scorecard.png``, ``views/``).
"""

from __future__ import annotations

# before anything loads torch: the wait policy is read when torch starts its thread pool
from kadv.runtime import configure_runtime

configure_runtime()

import sys
from pathlib import Path

from kadv.cli.common import config_int
from kadv.io import atomic_write

__all__ = ["main"]

_KEYS = {
    "model": "kadv_tiny",
    "probes": "all",
    "seed": "0",
    "budget": None,
    "lighting": "baked",
    "out": "outputs/probe",
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


def main(argv: list[str] | None = None) -> None:
    from kadv.testing import DEFAULT_BUDGET, RobustnessInputError, scorecard

    try:
        values = _arguments(sys.argv[1:] if argv is None else argv)
        models = [name for name in values["model"].split(",") if name]
        probes = None if values["probes"] == "all" else [name for name in values["probes"].split(",") if name]
        seed = _int(values["seed"], "seed", 0)
        budget = DEFAULT_BUDGET if values["budget"] is None else _int(values["budget"], "budget", 2)
        if values["lighting"] not in ("baked", "direct"):
            raise ValueError(f"lighting must be 'baked' or 'direct', got {values['lighting']!r}")
        out = Path(values["out"])
        card = scorecard(
            models,
            probes,
            seed=seed,
            budget_evaluations=budget,
            artifacts=out / "views",
            lighting=values["lighting"],
            progress=True,
        )
    except (RobustnessInputError, ValueError) as error:
        print(f"kadv-probe: error: {' '.join(str(error).split())}", file=sys.stderr)
        sys.exit(2)
    table = card.markdown()
    atomic_write(out / "scorecard.md", lambda tmp: tmp.write_text(table + "\n"))
    card.save_png(out / "scorecard.png")
    print(f"\n{table}\n\nscorecard: {out / 'scorecard.md'}, {out / 'scorecard.png'}")


if __name__ == "__main__":
    main()
