"""What the README's two commands cost a newcomer: this repository's HEAD cloned into a temporary
folder, then ``make demo`` and ``make test`` timed there (the first creates ``.venv`` and bakes);
``--checkout DIR`` times an existing checkout instead.

Last line: ``make_timings demo_s= test_s= tests_passed= fresh=`` (seconds of wall time; ``fresh``:
whether the checkout had no ``.venv`` before).

Run: .venv/bin/python benchmarks/make_timings.py [--checkout DIR] [--record]
"""

from __future__ import annotations

import argparse
import os
import re
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import common  # first: kadv's runtime settings, --record


def timed(target: str, checkout: Path) -> tuple[float, str]:
    """Seconds ``make target`` took in ``checkout``, and what it printed; a failure ends the script."""
    print(f"make {target} in {checkout} ...", file=sys.stderr, flush=True)
    start = time.perf_counter()
    scenes = {"KADV_TEST_SCENES": os.environ.get("KADV_TEST_SCENES", str(common.scenes_root()))}
    result = subprocess.run(
        ["make", target], cwd=checkout, capture_output=True, text=True, env={**os.environ, **scenes}
    )
    seconds = time.perf_counter() - start
    if result.returncode != 0:
        raise SystemExit(f"make {target} failed in {checkout} (exit {result.returncode}):\n{result.stdout[-2000:]}")
    return seconds, result.stdout


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--checkout", default=None, help="an existing checkout to time (default: a fresh clone)")
    args = parser.parse_args()
    clone = None
    if args.checkout is None:
        clone = Path(tempfile.mkdtemp(prefix="kadv-timings-")) / "kadv"
        subprocess.run(["git", "clone", "--quiet", str(Path(__file__).resolve().parents[1]), str(clone)], check=True)
    checkout = clone or Path(args.checkout).resolve()
    fresh = not (checkout / ".venv").exists()
    try:
        demo, _ = timed("demo", checkout)
        test, printed = timed("test", checkout)
    finally:
        if clone is not None:
            shutil.rmtree(clone.parent, ignore_errors=True)
    passed = re.findall(r"(\d+) passed", printed)
    print("| command | wall time | |\n|---|---|---|")
    print(f"| `make demo` | {demo / 60:.1f} min | {'creating .venv, baking' if fresh else '.venv made, bake cached'} |")
    print(f"| `make test` | {test / 60:.1f} min | {passed[-1] if passed else '?'} tests passed |")
    print(f"make_timings demo_s={demo:.0f} test_s={test:.0f} tests_passed={passed[-1] if passed else 0} fresh={fresh}")


if __name__ == "__main__":
    main()
