"""Supervised warm-up of the filter networks on a tiny dataset: losses fall."""

import pytest
import torch

from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
from pushtoknow.models.learned import build_learned_models
from pushtoknow.testbed.sim_config import PushConfig, SimConfig
from pushtoknow.training.push_tensors import load_push_tensors
from pushtoknow.training.supervised import (
    SupervisedConfig,
    evaluate_supervised,
    push_context,
    train_supervised,
    true_state,
)


@pytest.fixture(scope="module")
def pushes(tmp_path_factory):
    out = tmp_path_factory.mktemp("sup")
    cfg = GenerationConfig(
        objects=4,
        pushes=2,
        seed=11,
        objects_per_shard=4,
        sim=SimConfig(push=PushConfig(horizon=4.0)),
    )
    generate_dataset(out, cfg, progress=False)
    return load_push_tensors(out)


def test_context_puts_the_pad_where_it_was(pushes):
    idx, t = torch.tensor([0, 3]), torch.tensor([5, 20])
    ctx = push_context(pushes, idx, t)
    assert torch.equal(ctx.contact_xy, pushes.pusher[idx, t])
    assert true_state(pushes, idx, t).shape == (2, 1, 8)


def test_supervised_losses_fall_on_the_training_data(pushes):
    torch.manual_seed(0)
    models = build_learned_models()
    cfg = SupervisedConfig(steps=150, batch_size=64, log_every=150)
    before = evaluate_supervised(models, pushes, cfg, n=512)
    train_supervised(models, pushes, None, cfg, seed=0)
    after = evaluate_supervised(models, pushes, cfg, n=512)
    assert after["val_process_nll"] < before["val_process_nll"] - 1.0
    assert after["val_force_mse"] < 0.5 * before["val_force_mse"]
    assert all(torch.isfinite(p).all() for p in models.modules().parameters())
