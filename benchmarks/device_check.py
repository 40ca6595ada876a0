"""The device check: kadv's CUDA tests, the attack step's figures and a short attack, in one run.

1. the CUDA tests: ``tests/test_device.py`` (render, objective and training on the device against
   the CPU), the Warp/Open3D equivalence of ``tests/render/test_casting.py`` on the device's
   Warp caster against Open3D's CPU renders (box room, a generated room, grey_white_room), the
   host-round-trip guards of a render (``tests/render/``) and of whole attack steps (``tests/attack/``),
   and the captured step against the uncaptured one (``tests/attack/test_capture.py``);
2. ``benchmarks/attack_step.py --device <device> --backend warp`` (with ``--baseline``, first the
   step as it was before capture: ``--cuda-graphs off --edge-search compact``);
3. a short ``kadv-attack device=<device> render.backend=warp`` on grey_white_room that writes its
   run directory, pictures included;
4. the peak memory: of the GPU (sampled with nvidia-smi) on CUDA, of the largest process on the CPU.

Its last line: ``device_check overhead= overhead_tiny= evals_per_s= equivalence=ok|fail peak_gib=
device=<name>``. Each part's last line is appended to ``figures.txt`` in the output folder as soon as
it ends, so that a call cut short still brings back what ran. ``--device cuda`` on a machine without
CUDA is refused in one line (exit status 2); ``--device cpu`` runs the same path on the CPU (Warp's CPU device).

Run: benchmarks/device_check.sh --device cuda|cpu [--out DIR] [--attack-dir DIR] [--baseline] [--capture-only]
(the .sh unpacks what was carried first)
"""

from __future__ import annotations

import argparse
import os
import re
import resource
import shutil
import subprocess
import sys
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
# the shared scenes a device check carries: grey_white_room alone (benchmarks/device_pack.sh)
CARRIED = "not modern_hall and not japanese_classroom"
TEST_FILES = (
    "tests/test_device.py",
    "tests/render/test_casting.py",
    "tests/render/test_host_round_trips.py",
    "tests/attack/test_host_round_trips.py",
    "tests/attack/test_capture.py",
)


class GpuMemory:
    """The most memory nvidia-smi reports in use on the GPU while the block runs, in GiB."""

    def __enter__(self) -> GpuMemory:
        self.peak_mib, self._stop = 0.0, threading.Event()
        self._thread = threading.Thread(target=self._sample, daemon=True)
        self._thread.start()
        return self

    def _sample(self) -> None:
        while not self._stop.is_set():
            out = subprocess.run(
                ["nvidia-smi", "--query-gpu=memory.used", "--format=csv,noheader,nounits"],
                capture_output=True,
                text=True,
                check=False,
            ).stdout.split()
            if out:
                self.peak_mib = max(self.peak_mib, float(out[0]))
            self._stop.wait(0.25)

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    @property
    def gib(self) -> float:
        return self.peak_mib / 1024


def _run(
    label: str, command: list[str], env: dict[str, str], log: Path, cwd: Path = ROOT
) -> subprocess.CompletedProcess:
    """Run ``command``, echo its output to the log and the console's tail, time it, and append its
    last line to ``figures.txt`` beside the log."""
    start = time.perf_counter()
    result = subprocess.run(command, cwd=cwd, env=env, capture_output=True, text=True, check=False)
    seconds = time.perf_counter() - start
    with log.open("a") as handle:
        handle.write(f"\n$ {' '.join(command)}\n{result.stdout}{result.stderr}\n")
        handle.write(f"[exit {result.returncode}, {seconds:.0f} s]\n")
    tail = (result.stdout + result.stderr).strip().splitlines()[-3:]
    with (log.parent / "figures.txt").open("a") as handle:
        handle.write(f"{label}: exit {result.returncode} in {seconds:.0f} s: {tail[-1] if tail else ''}\n")
    print(f"{label}: exit {result.returncode} in {seconds:.0f} s", *(f"  {line}" for line in tail), sep="\n")
    sys.stdout.flush()
    return result


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--device", default="cuda", choices=["cuda", "cpu"])
    parser.add_argument("--out", default=str(ROOT / "outputs" / "device_check"), help="folder for the log and figures")
    parser.add_argument("--attack-dir", default=None, help="the short attack's run directory (default: OUT/attack)")
    parser.add_argument("--baseline", action="store_true", help="also time the step uncaptured, edges compacted")
    parser.add_argument(
        "--capture-only", action="store_true", help="run only tests/attack/test_capture.py: whether the step captures"
    )
    args = parser.parse_args()
    import torch

    if args.device == "cuda" and not torch.cuda.is_available():
        parser.exit(2, f"{parser.prog}: error: --device cuda, but this machine has no CUDA device (use --device cpu)\n")
    name = torch.cuda.get_device_name(0) if args.device == "cuda" else "cpu"
    out = Path(args.out)
    attack_dir = Path(args.attack_dir) if args.attack_dir else out / "attack"
    shutil.rmtree(out, ignore_errors=True)
    shutil.rmtree(attack_dir, ignore_errors=True)
    out.mkdir(parents=True)
    log = out / "device_check.log"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    python = sys.executable
    scene = Path(env.get("KADV_TEST_SCENES", ROOT.parent / "shared" / "scenes")) / "grey_white_room" / "scene.xml"
    with GpuMemory() if args.device == "cuda" and shutil.which("nvidia-smi") else _NoMemory() as memory:
        tests = _run(
            "CUDA tests" if args.device == "cuda" else "device tests on the CPU",
            [
                python,
                "-m",
                "pytest",
                "-q",
                "-p",
                "no:cacheprovider",
                "-o",
                "addopts=",
                *(TEST_FILES[-1:] if args.capture_only else TEST_FILES),
                "-k",
                CARRIED,
            ],
            env,
            log,
        )
        if args.capture_only:
            print(f"tests {'passed' if tests.returncode == 0 else 'FAILED'}; log: {log}")
            return
        step_command = [python, "benchmarks/attack_step.py", "--device", args.device, "--backend", "warp"]
        if args.baseline:
            before = [*step_command, "--cuda-graphs", "off", "--edge-search", "compact"]
            _run("attack_step uncaptured", before, env, log)
        step = _run("attack_step", step_command, env, log)
        # kadv-attack as installed (its configs ship as kadv.conf), run outside the checkout
        overrides = [
            f"device={args.device}",
            "render.backend=warp",
            "scene=file",
            f"scene.path={scene}",
            "init.count=1",
            "attack.budget_passes=24",
            "video=false",
            "progress=false",
            f"hydra.run.dir={attack_dir}",
        ]
        attack = _run(
            "kadv-attack", [python, "-c", "from kadv.cli.attack import main; main()", *overrides], env, log, cwd=out
        )
    peak = memory.gib if args.device == "cuda" else resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 2**20
    figures = dict(re.findall(r"(\w+)=(\S+)", (step.stdout.strip().splitlines() or [""])[-1]))
    pictures = sorted((attack_dir / "views").glob("*.png")) if attack.returncode == 0 else []
    print(f"tests {'passed' if tests.returncode == 0 else 'FAILED'}; attack pictures: {len(pictures)}; log: {log}")
    line = (
        f"device_check overhead={figures.get('overhead', 'nan')} overhead_tiny={figures.get('overhead_tiny', 'nan')} "
        f"evals_per_s={figures.get('evals_per_s', 'nan')} equivalence={'ok' if tests.returncode == 0 else 'fail'} "
        f"peak_gib={peak:.1f} device={name.replace(' ', '_')}"
    )
    with (out / "figures.txt").open("a") as handle:
        handle.write(line + "\n")
    print(line)


class _NoMemory:
    gib = 0.0

    def __enter__(self) -> _NoMemory:
        return self

    def __exit__(self, *exc) -> None:
        return None


if __name__ == "__main__":
    main()
