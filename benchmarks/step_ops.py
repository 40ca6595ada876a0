"""How many tensor operations a gradient attack step dispatches, phase by phase: kadv-tiny + SSIM,
one restart, on grey_white_room at 240x320.

On a GPU most operations are kernel launches (views are not) that the host dispatches one after
another; at a few microseconds each, their number sets a floor under a step that the device's
speed cannot lower (an H100 ran the step's kernels in a quarter of its time, 2026-11-26). The
count is the same on every device but for a few choices made per device, so this CPU measures
nearly what a GPU's host would dispatch: run it with ``--backend warp``, the caster CUDA gets. The
CPU's own choices, where it pays per element rather than per operation: the warp's taps in bands,
the silhouette bisection's one step a cast, textures sampled on the textured hits only.

Operations are counted as torch dispatches them (``TorchDispatchMode``), the backward pass's
included, between two consecutive optimiser updates (the steps after the first, whose count
includes the start's), and put to the phase of profile_step.py's whose function called them
("rest": the step's own, the objective's pose algebra, the backward pass, the optimiser). Then
what a captured step launches instead: one graph, a copy of each tensor it hands out, and the
operations the run dispatches outside the captured step.

Run: .venv/bin/python benchmarks/step_ops.py [--backend auto|open3d|warp] [--edge-search auto|compact|every_pair]
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable

from profile_step import HEIGHT, WIDTH, tiny_attack, wrap_phases

import torch
from torch.optim.optimizer import register_optimizer_step_post_hook
from torch.utils._python_dispatch import TorchDispatchMode

from kadv.attack import AttackConfig, GradientSettings, attack
from kadv.attack.capture import StepGraph, map_tensors

STEPS = 4


class _Counter(TorchDispatchMode):
    """Counts each operation (and, apart, the views among them) under the innermost phase running,
    and the operations dispatched outside the step that a CUDA graph captures
    (:class:`~kadv.attack.capture.StepGraph`)."""

    def __init__(self) -> None:
        super().__init__()
        self.phases = ["rest"]
        self.operations: Counter[str] = Counter()
        self.views: Counter[str] = Counter()
        self.in_graph = 0
        self.outside = 0
        self.outputs = 0

    def __torch_dispatch__(self, func, types, args=(), kwargs=None):
        self.operations[self.phases[-1]] += 1
        self.views[self.phases[-1]] += func.is_view
        self.outside += not self.in_graph
        return func(*args, **(kwargs or {}))

    def graph_step(self, call: Callable) -> Callable:
        """Wraps ``StepGraph.__call__``: what it dispatches a graph would hold; it counts the tensors
        a replay copies out."""

        def run(graph: StepGraph):
            self.in_graph += 1
            try:
                outputs = call(graph)
            finally:
                self.in_graph -= 1
            self.outputs = 0
            map_tensors(self._count_output, outputs)
            return outputs

        return run

    def _count_output(self, tensor: torch.Tensor) -> torch.Tensor:
        self.outputs += 1
        return tensor

    def attributed(self, fn: Callable, phase: str) -> Callable:
        """A :func:`~profile_step.wrap_phases` wrapper: what ``fn`` dispatches counts under ``phase``."""

        def run(*args, **kwargs):
            self.phases.append(phase)
            try:
                return fn(*args, **kwargs)
            finally:
                self.phases.pop()

        return run


def main() -> None:
    device, backend, args, study, view = tiny_attack(
        "Count the tensor operations of a gradient attack step, phase by phase."
    )
    objective, differentiable = study.objective, study.differentiable
    config = AttackConfig("gradient", GradientSettings(steps=STEPS, restarts=1), budget_passes=None)

    def run() -> None:
        attack(objective, differentiable, [view], HEIGHT, WIDTH, config, 0, progress=False)

    run()  # warm-up: kernels compiled, tables uploaded
    counter = _Counter()
    steps: list[tuple[Counter, Counter]] = []
    outside: list[int] = []

    def hook(*_) -> None:  # an update ends a step: its counts are put aside, the next one's start
        steps.append((counter.operations.copy(), counter.views.copy()))
        outside.append(counter.outside)
        counter.operations.clear()
        counter.views.clear()
        counter.outside = 0

    put_back = wrap_phases(counter.attributed)
    handle = register_optimizer_step_post_hook(hook)
    call = StepGraph.__call__
    StepGraph.__call__ = counter.graph_step(call)
    try:
        with counter:
            run()
    finally:
        StepGraph.__call__ = call
        handle.remove()
        put_back()
    counted = steps[1:]  # the first update closes the run's start as well as its first step
    operations = sum((ops for ops, _ in counted), Counter())
    views = sum((v for _, v in counted), Counter())
    per_step = {phase: operations[phase] / len(counted) for phase in operations}
    print(f"\ntensor operations per gradient step (mean of {len(counted)}), kadv-tiny + SSIM, {HEIGHT}x{WIDTH},")
    print(f"backend {backend}, edge_search={args.edge_search}: all of them, and the views among them")
    for phase, count in sorted(per_step.items(), key=lambda item: -item[1]):
        print(f"  {phase:<28} {count:>7.0f} {views[phase] / len(counted):>7.0f}")
    total = sum(per_step.values())
    print(f"  {'whole step':<28} {total:>7.0f} {sum(views.values()) / len(counted):>7.0f}")
    beside = sum(outside[1:]) / len(counted)
    print(
        f"captured (CUDA, render.differentiable.cuda_graphs): one graph launch a step, {counter.outputs} copies "
        f"of its outputs, and {beside:.0f} operations outside it"
    )
    print(
        f"step_ops total={total:.0f} non_view={total - sum(views.values()) / len(counted):.0f} "
        f"silhouette_search={per_step.get('silhouette search', 0.0):.0f} "
        f"captured_launches={1 + counter.outputs + beside:.0f} "
        f"device={device.type} backend={backend} edge_search={args.edge_search}"
    )


if __name__ == "__main__":
    main()
