"""The gradient step captured in a CUDA graph (:mod:`kadv.attack.capture`): a captured run gives
the uncaptured run's records in the lit box room and in grey_white_room (bit for bit on the CPU,
where nothing is captured; to rounding on CUDA, where the capture must succeed); the fixed-shape
edge search steps as the compacted one, bit for bit on the CPU; and the pieces: uploads recognised
and served by value, outputs copied."""

from __future__ import annotations

import dataclasses
import warnings
from dataclasses import dataclass, replace

import pytest
import torch

from kadv import ExactRenderer, load_model
from kadv.attack import InitView, Objective, PenaltyConfig, file_init_views
from kadv.attack.capture import HostUploads, StepGraph, _copied, _upload_target
from kadv.geometry import intrinsics_from_fov
from kadv.losses import depth_loss
from kadv.render import DifferentiableRenderer, DiffRenderConfig, Shading
from tests.conftest import cached_real_scene
from tests.round_trips import DEVICES, corner_attack, gradient_measures

H, W = 24, 32
STEPS = 4


def _records(measures: list) -> list:
    return [replace(r, seconds=0.0) for step in measures for r in step.records()]


def _numbers(records: list) -> torch.Tensor:
    return torch.tensor([[r.l_depth, r.loss, r.objective, r.guard_fraction, *r.params, *r.centre] for r in records])


def _grey_white_room_attack(device: str) -> tuple[Objective, InitView, torch.Tensor]:
    """kadv-tiny + SSIM on grey_white_room (alpha-masked plant and windows; direct lighting), from
    its file view and from a view turned and moved 10 cm."""
    renderer = ExactRenderer(cached_real_scene("grey_white_room"), Shading(), False, "warp", device)
    objective = Objective(load_model("kadv_tiny"), depth_loss("ssim"), renderer, PenaltyConfig(), device=device)
    start = torch.tensor([[0.0] * 6, [0.02, 0.03, -0.01, 0.1, 0.0, -0.05]], dtype=torch.float64)
    return objective, file_init_views(renderer, objective.penalty.margin)[0], start


@pytest.mark.parametrize("device", DEVICES)
@pytest.mark.parametrize("scene", ["box_room", "grey_white_room"])
def test_a_captured_run_gives_the_uncaptured_runs_records(scene: str, device: str, tmp_path) -> None:
    if scene == "box_room":
        objective, view, start = corner_attack(device, str(tmp_path))
    else:
        objective, view, start = _grey_white_room_attack(device)
    runs = {}
    for captured in (False, True):
        with warnings.catch_warnings():
            warnings.simplefilter("error", RuntimeWarning)  # a capture that fails warns: here it fails the test
            measures = gradient_measures(objective, view, start, STEPS, (H, W), "every_pair", cuda_graphs=captured)
        runs[captured] = _records(measures)
    eager, captured = runs[False], runs[True]
    assert len(captured) == 2 * (STEPS + 1) and [r.step for r in captured] == [r.step for r in eager]
    assert captured[-1].params != captured[1].params  # the cameras moved
    if device == "cpu":
        assert captured == eager
    else:
        assert [r.verdict for r in captured] == [r.verdict for r in eager]
        # to rounding up to the views the first replayed update reached (step 2): from there Adam's
        # moves, +-lr for a gradient component near 0 whatever its size, may part runs that differ
        # in rounding (as two uncaptured CUDA runs may); the step itself is compared below
        torch.testing.assert_close(_numbers(captured[:6]), _numbers(eager[:6]), rtol=1e-4, atol=1e-5)


@pytest.mark.parametrize("device", DEVICES)
def test_a_captured_render_objective_and_gradient_equal_the_uncaptured_ones_at_every_pose(
    device: str, tmp_path
) -> None:
    """The captured part of a step, replayed at several poses, against the same calls uncaptured."""
    objective, view, start = corner_attack(device, str(tmp_path))
    differentiable = DifferentiableRenderer(objective.renderer, DiffRenderConfig(edge_search="every_pair"), device)
    K = intrinsics_from_fov(view.fov_x_deg, H, W)
    base = view.world_T_cam.double().to(device)[None].expand(len(start), 4, 4)
    params = torch.zeros_like(start, device=device).requires_grad_(True)

    def step() -> tuple[torch.Tensor, torch.Tensor]:
        params.grad = None
        out = differentiable(params, base, K, H, W)
        objective_values = objective(out.rgb, out.depth, out.mask, out.world_T_cam, K).objective
        objective_values.sum().backward()
        return objective_values.detach(), params.grad

    poses = [start * k for k in (1.0, 0.5, -1.0, 2.0)]

    def run(graph: StepGraph) -> list[tuple[torch.Tensor, torch.Tensor]]:
        results = []
        for pose in poses:
            with torch.no_grad():
                params.copy_(pose)
            results.append(tuple(value.cpu() for value in graph()))
        return results

    eager = run(StepGraph(step, device, enabled=False))
    graph = StepGraph(step, device)
    with warnings.catch_warnings():
        warnings.simplefilter("error", RuntimeWarning)
        captured = run(graph)
    assert graph.captured == (device == "cuda")
    for (value, gradient), (value_eager, gradient_eager) in zip(captured, eager):
        assert gradient_eager.abs().sum() > 0
        if device == "cpu":
            assert torch.equal(value, value_eager) and torch.equal(gradient, gradient_eager)
        else:
            torch.testing.assert_close(value, value_eager, rtol=1e-4, atol=1e-6)
            assert (gradient - gradient_eager).norm() <= 1e-3 * gradient_eager.norm()


def test_the_fixed_shape_edge_search_steps_as_the_compacted_one_bit_for_bit_on_the_cpu(tmp_path) -> None:
    objective, view, start = corner_attack("cpu", str(tmp_path))
    compact, every_pair = (
        _records(gradient_measures(objective, view, start, STEPS, (H, W), search))
        for search in ("compact", "every_pair")
    )
    assert every_pair == compact
    assert compact[-1].params != compact[1].params


def test_uploads_are_recognised_with_their_target() -> None:
    host = torch.arange(6.0).reshape(2, 3)
    cuda = torch.device("cuda")
    assert _upload_target(torch.Tensor.to, (host, "cuda", torch.float64), {}) == (cuda, torch.float64)
    assert _upload_target(torch.Tensor.to, (host,), {"device": "cuda:0", "non_blocking": True}) == (
        torch.device("cuda:0"),
        None,
    )
    assert _upload_target(torch.as_tensor, ([1.0, 2.0],), {"device": "cuda"}) == (cuda, None)
    assert _upload_target(torch.tensor, ([1.0],), {"dtype": torch.float32, "device": cuda}) == (cuda, torch.float32)
    # no host data leaves for a CUDA device: none of these is an upload
    assert _upload_target(torch.Tensor.to, (host, torch.float32), {}) is None
    assert _upload_target(torch.Tensor.to, (host, "cpu"), {}) is None
    assert _upload_target(torch.as_tensor, ([1.0],), {}) is None
    assert _upload_target(torch.Tensor.add, (host, host), {}) is None


def test_recorded_uploads_are_served_by_value(monkeypatch) -> None:
    """Without CUDA, a CPU "device" copy stands in: what matters is which calls are served."""
    made = []
    monkeypatch.setattr(
        "kadv.attack.capture._upload_target",
        lambda func, args, kwargs: ("to", None) if func is torch.Tensor.to else None,
    )
    uploads = HostUploads()
    with uploads:
        first = torch.ones(3).to("cpu", torch.float64)
        made.append(first)
    uploads.recording = False
    with uploads:
        again = torch.ones(3).to("cpu", torch.float64)  # the same values: served from the record
        other = torch.full((3,), 2.0).to("cpu", torch.float64)  # values never recorded: copied as asked
    assert len(uploads.uploads) == 1
    assert torch.equal(again, first) and again.data_ptr() != next(iter(uploads.uploads.values())).data_ptr()
    assert torch.equal(other, torch.full((3,), 2.0, dtype=torch.float64))


def test_outputs_are_copied_through_dataclasses_lists_and_dicts() -> None:
    @dataclass(frozen=True)
    class Inner:
        values: torch.Tensor
        label: str

    @dataclass
    class Outer:
        inner: Inner
        rows: list
        named: dict

    tensor = torch.zeros(2)
    outputs = Outer(Inner(tensor, "a"), [tensor, 3], {"t": tensor})
    copied = _copied(outputs)
    tensor += 1.0  # as a replay overwrites a graph's outputs
    assert copied.inner.label == "a" and copied.rows[1] == 3
    for kept in (copied.inner.values, copied.rows[0], copied.named["t"]):
        assert torch.equal(kept, torch.zeros(2))
    assert dataclasses.is_dataclass(copied.inner)


def test_steps_run_as_written_where_nothing_is_captured() -> None:
    calls = []
    graph = StepGraph(lambda: calls.append(1) or len(calls), torch.device("cpu"))
    assert not graph.enabled and [graph(), graph(), graph()] == [1, 2, 3] and not graph.captured
    assert not StepGraph.available("cuda", enabled=False) and StepGraph.available("cuda")
