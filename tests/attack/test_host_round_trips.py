"""Whole gradient attack steps read nothing back to the host: on Warp's backend, on its CPU device
(and on CUDA, under ``torch.cuda.set_sync_debug_mode("error")``), every step of a batched Adam run
(differentiable render with edges searched pair by pair, model, loss, penalty, validity, backward,
update, step guard) runs under a guard that fails on any host round trip, and gives the records an
unguarded run gives."""

from __future__ import annotations

import dataclasses
from dataclasses import replace

import pytest
import torch

from tests.round_trips import DEVICES, corner_attack, gradient_measures, no_host_round_trips

H, W = 24, 32
STEPS = 3


@pytest.mark.parametrize("device", DEVICES)
def test_gradient_attack_steps_read_nothing_back_to_the_host(device: str, tmp_path) -> None:
    objective, view, start = corner_attack(device, str(tmp_path))
    # edges found without compacting: a compacted search waits for its counts on a GPU. Adam keeps
    # its step count on the host (torch's design, on every device): its reads wait for no device
    guard = no_host_round_trips(device, allow=((torch.optim.Adam, "step"),))
    # uncaptured: a captured step's replays run no Python at all (tests/attack/test_capture.py)
    runs = [
        gradient_measures(objective, view, start, STEPS, (H, W), "every_pair", around, cuda_graphs=False)
        for around in (None, guard)
    ]
    # the records are read once the runs have ended; the clock's seconds differ, everything else must not
    reference, records = ([replace(r, seconds=0.0) for step in run for r in step.records()] for run in runs)
    if device == "cpu":
        assert records == reference  # the guarded steps are the steps, bit for bit
    else:
        # CUDA's atomic sums reorder from run to run, and Adam's first moves are +-lr whatever a
        # gradient's size: a component near 0 may move either way. The same views at step 0, to rounding
        assert [(r.step, r.restart, r.verdict) for r in records] == [(r.step, r.restart, r.verdict) for r in reference]

        def step_0(run: list) -> torch.Tensor:
            return torch.tensor([[r.l_depth, r.abs_rel, *r.centre] for r in run[:2]])

        torch.testing.assert_close(step_0(records), step_0(reference), rtol=1e-4, atol=1e-5)
    assert len(records) == 2 * (STEPS + 1) and {r.step for r in records} == set(range(STEPS + 1))
    # the steps moved the cameras, and everything a record holds was measured
    assert records[-1].params != records[1].params and records[-2].params != records[0].params
    assert all(r.verdict == "valid" and r.refreshed for r in records)
    fields = ("l_depth", "loss", "objective", "delta1", "abs_rel", "coverage", "rgb_error", "depth_error")
    assert all(torch.isfinite(torch.tensor([getattr(r, f) for f in fields])).all() for r in records)
    assert all(0.0 <= r.guard_fraction <= 1.0 for r in records)
    assert dataclasses.asdict(records[0])["params"] == [0.0] * 6
