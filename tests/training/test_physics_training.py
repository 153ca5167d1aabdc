"""The physics-structured models through the whole pipeline: train, save, load, infer with
an active policy choosing between constant and release pushes."""

import numpy as np
import pytest
import torch

from pushtoknow.inference import InferenceConfig, infer_object
from pushtoknow.inference.policies import make_policy
from pushtoknow.models.checkpoint import load_checkpoint
from pushtoknow.models.physics import PhysicsDynamics, PhysicsObservation
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.training.pipeline import TrainConfig, train_model
from tiny_training import SIM, TINY_TRAIN, tiny_dataset


@pytest.mark.parametrize("quasi_static", ["network", "limit-surface"])
def test_physics_structured_model_trains_reloads_and_estimates(
    tmp_path_factory, tmp_path, quasi_static
):
    data = tiny_dataset(tmp_path_factory)
    models = {**TINY_TRAIN["models"], "structure": "physics", "quasi_static": quasi_static}
    raw = {**TINY_TRAIN, "models": models}
    if quasi_static == "limit-surface":  # with the free slide, a prior widened to cover the
        raw["prior_coverage"] = 0.9  # catalogue ranges, and a dynamic-phase noise scale
        models["free_slide"] = True
        raw["sequence_calibration"] = {
            **TINY_TRAIN["sequence_calibration"],
            "dynamic_noise_scales": [0.5],
        }
    trained = train_model(data, tmp_path, TrainConfig.model_validate(raw), seed=0, progress=False)
    model = load_checkpoint(tmp_path)
    assert model.models_config.structure == "physics"
    assert model.models_config.quasi_static == quasi_static
    assert (model.models.dynamics.limit_surface is not None) == (quasi_static == "limit-surface")
    assert model.models.dynamics.free_slide == (quasi_static == "limit-surface")
    assert model.inference == trained.inference  # the calibrated settings are saved
    assert isinstance(model.models.dynamics, PhysicsDynamics)
    assert isinstance(model.models.observation, PhysicsObservation)
    for a, b in zip(
        trained.models.modules().state_dict().values(), model.models.modules().state_dict().values()
    ):
        assert torch.equal(a, b)
    assert set(model.info["profiles"]) == {"constant", "release"}
    if quasi_static == "limit-surface":
        low = model.prior.mean - 1.6449 * model.prior.cov.diagonal().sqrt()
        assert (low <= -1.0).all()

    spec = load_object_spec("catalogue:117")
    ex = SimulatedExecutor(spec, SIM, seed=0, recentre=True)
    try:
        ex.observe()
        cfg = InferenceConfig(
            estimator="vt-addf",
            pushes=2,
            policy="active-kl",
            candidates=4,
            profiles=("constant", "release"),
        )
        res = infer_object(
            model,
            ex,
            cfg,
            0,
            initial_pose=ex.initial_pose,
            policy=make_policy("active-kl"),
        )
    finally:
        ex.close()
    assert len(res.estimates) == 2
    for e in res.estimates:
        assert np.isfinite(e.mean).all() and np.isfinite(e.std).all()
        assert e.mean[[0, 1, 4]].min() > 0  # m, μ, I_z positive
    assert {r.push.profile for r in res.records} <= {"constant", "release"}
