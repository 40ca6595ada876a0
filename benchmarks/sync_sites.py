"""Where a gradient attack step still waits for the device: a short gradient run (kadv-tiny + SSIM,
two restarts, on the box room lit by every kind of emitter, Warp's backend; the whole-step
round-trip test's run) under ``torch.cuda.set_sync_debug_mode("warn")``, each wait traced to the
line of kadv that made it.

Prints each site with its waits per step, the steps counted being all but the first (which
compiles kernels and uploads tables). On the CPU there is nothing to wait for: it refuses in one line.

Run: .venv/bin/python benchmarks/sync_sites.py [--device cuda] [--edge-search compact|every_pair]
"""

from __future__ import annotations

import argparse
import sys
import traceback
import warnings
from collections import Counter
from pathlib import Path

import common  # noqa: F401  first: kadv's runtime settings, before torch starts its thread pool

import torch

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from tests.round_trips import corner_attack, gradient_measures  # noqa: E402

H, W, STEPS = 48, 64, 4


def kadv_site(stack: list[traceback.FrameSummary]) -> str:
    """The innermost frame of the kadv package's code in ``stack``, as kadv/...:line (function)."""
    for frame in reversed(stack):
        parts = Path(frame.filename).parts
        if "kadv" in parts[:-1]:
            package = len(parts) - 1 - parts[::-1].index("kadv")
            return f"{'/'.join(parts[package:])}:{frame.lineno} ({frame.name})"
    return "outside kadv"


def main() -> None:
    parser = argparse.ArgumentParser(description="Where a gradient attack step still waits for the device.")
    parser.add_argument("--device", default="cuda")
    parser.add_argument("--edge-search", default="compact", choices=("compact", "every_pair"))
    args = parser.parse_args()
    device = args.device
    if not device.startswith("cuda") or not torch.cuda.is_available():
        print(f"sync_sites: --device {device}: only a CUDA device waits (no CUDA here)", file=sys.stderr)
        sys.exit(2)
    objective, view, start = corner_attack(device, "/tmp/kadv-sync-sites")

    def run(steps: int) -> None:
        gradient_measures(objective, view, start, steps, (H, W), args.edge_search)

    run(1)  # kernels compiled, tables uploaded
    sites: Counter[str] = Counter()
    original = warnings.showwarning

    def record(message, category, *args, **kwargs) -> None:
        if "synchroniz" in str(message):
            sites[kadv_site(traceback.extract_stack()[:-1])] += 1
        else:
            original(message, category, *args, **kwargs)

    warnings.showwarning = record
    warnings.simplefilter("always")
    torch.cuda.set_sync_debug_mode("warn")
    try:
        run(STEPS)
    finally:
        torch.cuda.set_sync_debug_mode("default")
        warnings.showwarning = original
    print(
        f"waits per step of a {STEPS}-step gradient run (2 restarts, {H}x{W}, edge_search={args.edge_search}), "
        "by kadv's line that made them:"
    )
    for site, count in sites.most_common():
        print(f"  {count / (STEPS + 1):6.1f}  {site}")
    total = sum(sites.values())
    print(f"sync_sites steps={STEPS + 1} waits_per_step={total / (STEPS + 1):.1f} sites={len(sites)}")


if __name__ == "__main__":
    main()
