"""Smoke test of the active-selection benchmark (tiny sizes; the real numbers come from the
CLI) and of its candidate contexts."""

import math

import numpy as np
import torch

from pushtoknow.bench.active import (
    DISC_RADIUS_M,
    candidate_pushes,
    context_builder_for,
    run_active_bench,
)
from pushtoknow.common.camera import CameraModel
from pushtoknow.testbed.sim_config import PadConfig, PushConfig


def test_run_active_bench_reports_both_scores():
    out = run_active_bench(
        seed=0, num_candidates=2, num_sigma_points=20, repeats=1, horizon_fraction=0.04
    )
    assert set(out.decision_s_median) == {"kl", "entropy"}
    assert all(v > 0 for v in out.decision_s_median.values())
    assert out.n_steps == 2 and out.num_candidates == 2 and out.num_sigma_points == 20
    assert isinstance(out.machine, str) and out.machine
    for r in out.per_score.values():
        assert 0 <= r["chosen"][0] < 2
        assert r["breakdown_s"]["process_net"] > 0


def test_candidate_contexts_follow_the_pad():
    push_cfg = PushConfig()
    pushes = candidate_pushes(4, np.random.default_rng(0), push_cfg)
    assert [p.profile for p in pushes] == ["constant", "release"] * 2
    for i, p in enumerate(pushes):  # inward normal ± 5°
        inward = 2 * math.pi * i / 4 + math.pi
        assert abs(math.remainder(p.direction - inward, 2 * math.pi)) <= math.radians(5.0)
    build = context_builder_for(CameraModel(), push_cfg, 10.0, 3)
    ctx = build(pushes, 0)
    ctx.validate(4)
    # step 0 ends at t = 0.1 s: the constant push has moved 2 mm from its start
    start = np.array(pushes[0].contact) - pushes[0].unit * (
        PadConfig().radius + push_cfg.approach_gap
    )
    want = start + pushes[0].unit * push_cfg.speed * 0.1
    torch.testing.assert_close(ctx.contact_xy[0], torch.tensor(want, dtype=torch.float32))
    assert (
        ctx.mask0[0, 0].sum() > 0
        and float(ctx.footprint[0].norm(dim=-1).max()) <= DISC_RADIUS_M + 1e-6
    )
