"""The limit-surface step against the testbed: constant pushes of simulated objects, with the
outline seen in S_0 (as the filter sees it), explain most of the recorded motion."""

import numpy as np
import pytest
import torch

from pushtoknow.geometry.affordances import sample_push_affordances
from pushtoknow.models.contact import limit_surface_push, radius_of_gyration
from pushtoknow.models.physics import CONTACT_REACH, CONTACT_SOFTNESS, MOMENT_ARM_RATIO
from pushtoknow.perception.footprint import footprint_from_mask
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.objects import load_object_spec
from pushtoknow.testbed.push import Push

F64 = torch.float64


def _steps(spec, seed):
    """(predicted, recorded) steps (T, 3) of two constant pushes of `spec`."""
    cfg = SimConfig()
    ex = SimulatedExecutor(spec, cfg, seed=seed, recentre=True)
    rng = np.random.default_rng(seed)
    pred, rec = [], []
    try:
        for _ in range(2):
            view = ex.observe()
            cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
            r = ex.execute(Push(tuple(cp[0]), float(pd[0]), "constant", cfg.push.speed))
            fp = torch.tensor(footprint_from_mask(r.s0, ex.camera, r.pose[0]), dtype=F64)[None]
            arm = MOMENT_ARM_RATIO * radius_of_gyration(fp)
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


@pytest.mark.slow
def test_limit_surface_explains_the_testbeds_quasi_static_pushes():
    pred, rec = [], []
    for seed, source in enumerate(("catalogue:100", "catalogue:505", "catalogue:300")):
        p, r = _steps(load_object_spec(source), seed)
        pred.append(p)
        rec.append(r)
    pred, rec = np.concatenate(pred), np.concatenate(rec)
    xy_err = np.sqrt(((pred[:, :2] - rec[:, :2]) ** 2).sum(1).mean())
    xy_rms = np.sqrt((rec[:, :2] ** 2).sum(1).mean())
    turn_r2 = 1 - ((pred[:, 2] - rec[:, 2]) ** 2).sum() / (rec[:, 2] ** 2).sum()
    assert xy_err < 0.4 * xy_rms
    assert turn_r2 > 0.4


def test_the_models_pad_is_the_testbeds():
    from pushtoknow.models.learned import PAD_RADIUS, LearnedModelsConfig

    assert PAD_RADIUS == SimConfig().pad.radius == LearnedModelsConfig().pad_radius
