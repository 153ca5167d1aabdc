"""The limit-surface step against the testbed: constant pushes of simulated objects, with the
outline the filter sees (`perception.footprint.footprint_seen`), explain most of the recorded
motion."""

import numpy as np
import pytest
import torch

from pushtoknow.geometry.affordances import sample_push_affordances
from pushtoknow.models.contact import limit_surface_push, radius_of_gyration
from pushtoknow.models.physics import CONTACT_REACH, CONTACT_SOFTNESS, GyrationArm
from pushtoknow.perception.footprint import footprint_seen
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import novel_objects
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim_config import SimConfig

F64 = torch.float64


def _true_outline(spec, n=64):
    """The spec's outline, counter-clockwise, resampled evenly by arc length (n, 2)."""
    ring = spec.footprint.polygon.exterior
    if not ring.is_ccw:
        ring = type(ring)(list(ring.coords)[::-1])
    return np.array([ring.interpolate(t, normalized=True).coords[0] for t in np.arange(n) / n])


def _steps(spec, seed, outline="s0", kappa=GyrationArm.initial_ratio):
    """(predicted, recorded) steps (T, 3) of two constant pushes of `spec`, with the outline
    `perception.footprint.footprint_seen` gives ("seen"), the one it gives from S_0 alone
    ("s0") or the true one ("true")."""
    cfg = SimConfig()
    ex = SimulatedExecutor(spec, cfg, seed=seed, recentre=True)
    rng = np.random.default_rng(seed)
    pred, rec = [], []
    try:
        for _ in range(2):
            view = ex.observe()
            cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
            r = ex.execute(Push(tuple(cp[0]), float(pd[0]), "constant", cfg.push.speed))
            if outline == "true":
                fp = torch.tensor(_true_outline(spec), dtype=F64)[None]
            else:
                mask = r.s0 if outline == "s0" else r.outline_mask
                fp = footprint_seen(r.s0, r.depth[0], mask, ex.camera, r.pose[0])
                fp = torch.tensor(fp, dtype=F64)[None]
            arm = kappa * radius_of_gyration(fp)
            com = torch.tensor([[[spec.params.com_x, spec.params.com_y]]], dtype=F64)
            pose = torch.as_tensor(r.pose, dtype=F64)
            pad = torch.as_tensor(r.pusher, dtype=F64)
            for t in range(len(pose) - 1):
                out = limit_surface_push(
                    pose[None, t : t + 1],
                    com,
                    pad[None, t],
                    pad[None, t + 1],
                    fp,
                    cfg.pad.radius,
                    arm,
                    CONTACT_REACH,
                    CONTACT_SOFTNESS,
                )
                pred.append(out.twist[0, 0].numpy())
            rec.append(np.diff(r.pose, axis=0))
    finally:
        ex.close()
    return np.array(pred), np.concatenate(rec)


def _fit(specs, outline, kappa=GyrationArm.initial_ratio):
    """Per-step xy error over the steps' xy RMS, and the turn's R², over `specs`."""
    pred, rec = [], []
    for seed, spec in enumerate(specs):
        p, r = _steps(spec, seed, outline, kappa)
        pred.append(p)
        rec.append(r)
    pred, rec = np.concatenate(pred), np.concatenate(rec)
    xy_err = np.sqrt(((pred[:, :2] - rec[:, :2]) ** 2).sum(1).mean())
    xy_rms = np.sqrt((rec[:, :2] ** 2).sum(1).mean())
    turn_r2 = 1 - ((pred[:, 2] - rec[:, 2]) ** 2).sum() / (rec[:, 2] ** 2).sum()
    return xy_err / xy_rms, turn_r2


@pytest.mark.slow
def test_limit_surface_explains_the_testbeds_quasi_static_pushes():
    specs = [load_object_spec(f"catalogue:{i}") for i in (100, 505, 300)]
    # measured 0.33, 0.87 (0.45 on its own for catalogue:100, whose CoM sits 34 mm off-centre:
    # as much with the true outline, the arm's limit, not the outline's)
    xy_share, turn_r2 = _fit(specs, "seen")
    assert xy_share < 0.4
    assert turn_r2 > 0.75


@pytest.mark.slow
def test_the_outline_seen_explains_nearly_all_that_the_true_one_does():
    """What the outline costs (docs/DESIGN.md §10): the step on the outline the filter sees (the
    256 px mask, smoothed by 5 mm) leaves about what the true outline leaves; on the 64 px S_0
    alone, two and a half times as much."""
    specs = novel_objects(8, seed=31)
    xy_share, turn_r2 = _fit(specs, "true", kappa=0.8)  # measured: 0.10, 0.96
    seen_share, seen_r2 = _fit(specs, "seen", kappa=0.8)  # measured: 0.105, 0.94
    s0_share, s0_r2 = _fit(specs, "s0")  # measured: 0.27, 0.81
    assert xy_share < 0.15 and turn_r2 > 0.9
    assert seen_share < 1.2 * xy_share and seen_r2 > turn_r2 - 0.05
    assert seen_share < 0.5 * s0_share and seen_r2 > s0_r2 + 0.08


def test_the_models_pad_is_the_testbeds():
    from pushtoknow.models.learned import PAD_RADIUS, LearnedModelsConfig

    assert PAD_RADIUS == SimConfig().pad.radius == LearnedModelsConfig().pad_radius
