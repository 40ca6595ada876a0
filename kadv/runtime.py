"""Process settings that every entry point (the commands, the benchmarks, the tests) makes first."""

from __future__ import annotations

import os

__all__ = ["configure_runtime"]


def configure_runtime() -> None:
    """Settings for a process that renders and runs networks on the CPU.

    - ``OMP_WAIT_POLICY=PASSIVE`` (unless set): idle OpenMP threads (torch's) sleep instead of
      spinning, so they leave the cores to Open3D's ray casts between network calls. libgomp reads
      it when torch is first imported, so it takes effect only when this runs before that: the
      commands that render (``kadv-attack``, ``kadv-render``, ``kadv-report``), the tests and the
      benchmarks call it first (``import kadv`` itself loads no torch). ``kadv-train-tiny`` does
      not: training is all torch, and with passive threads it ran at about half the steps per
      second (1.4-1.8 against 3.3 for the DPT). A program of your own that imports torch before
      kadv sets ``OMP_WAIT_POLICY=PASSIVE`` in its shell instead.
    - matplotlib's Agg backend: figures go to files and no display is needed.
    """
    os.environ.setdefault("OMP_WAIT_POLICY", "PASSIVE")
    import matplotlib

    matplotlib.use("Agg")
