"""What the README's two commands cost: ``make demo`` and ``make test`` timed in a checkout (by
default this one; a fresh clone's first run also creates ``.venv`` and bakes, and says so).

Last line: ``make_timings demo_s= test_s= tests_passed= fresh=`` (seconds of wall time; ``fresh``:
whether the checkout had no ``.venv`` before).

Run: .venv/bin/python benchmarks/make_timings.py [--checkout DIR] [--record]
"""

from __future__ import annotations

import argparse
import re
import subprocess
import time
from pathlib import Path

import common  # noqa: F401  first: kadv's runtime settings, --record


def timed(target: str, checkout: Path) -> tuple[float, str]:
    """Seconds ``make target`` took in ``checkout``, and what it printed; a failure ends the script."""
    start = time.perf_counter()
    result = subprocess.run(["make", target], cwd=checkout, capture_output=True, text=True)
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"make {target} failed in {checkout} (exit {result.returncode}):\n{result.stdout[-2000:]}")
    return seconds, result.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--checkout", default=str(Path(__file__).resolve().parents[1]), help="the repository to time")
    args = parser.parse_args()
    checkout = Path(args.checkout).resolve()
    fresh = not (checkout / ".venv").exists()
    demo, _ = timed("demo", checkout)
    test, printed = timed("test", checkout)
    passed = re.findall(r"(\d+) passed", printed)
    print("| command | wall time | |\n|---|---|---|")
    print(f"| `make demo` | {demo / 60:.1f} min | {'creating .venv, baking' if fresh else '.venv made, bake cached'} |")
    print(f"| `make test` | {test / 60:.1f} min | {passed[-1] if passed else '?'} tests passed |")
    print(f"make_timings demo_s={demo:.0f} test_s={test:.0f} tests_passed={passed[-1] if passed else 0} fresh={fresh}")


if __name__ == "__main__":
    main()
