"""ActivePolicy on the linear toy: candidates are pushes, the context builder maps them."""

import pytest
import torch
from active_toys import F64, CouplingContext, linear_filter, linear_prior
from pydantic import ValidationError

from pushtoknow.active.information_policy import (
    ActiveConfig,
    ActivePolicy,
    CandidateSelector,
    look_ahead_steps,
)
from pushtoknow.testbed.push import Push

REFERENCE_SPEED = 0.02  # m/s: coupling 1 in the toy


def _builder(calls: list):
    def build(pushes, step):
        calls.append((len(pushes), step))
        return CouplingContext(torch.tensor([p.speed / REFERENCE_SPEED for p in pushes], dtype=F64))

    return build


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_active_policy_picks_the_informative_push(score):
    filt = linear_filter()
    policy = ActivePolicy(filt, horizon_steps=20, score=score, horizon_fraction=0.25)
    assert policy.name == f"active-{score}" and policy.n_steps == 5
    assert isinstance(policy, CandidateSelector)
    candidates = [Push((0.0, 0.0), 0.0, speed=s) for s in (0.0, 0.01, 0.02, 0.005)]
    mean, cov = linear_prior()
    calls: list = []
    idx = policy.choose(candidates, mean, cov, _builder(calls), torch.Generator().manual_seed(0))
    assert idx == 2
    assert policy.last_scores.shape == (4,)
    assert calls == [(4, k) for k in range(5)]  # one batched context per look-ahead step


def test_from_config_and_steps():
    cfg = ActiveConfig(score="entropy", horizon_fraction=0.5)
    policy = ActivePolicy.from_config(linear_filter(), cfg, horizon_steps=100)
    assert policy.n_steps == 50 and policy.name == "active-entropy" == cfg.policy_name
    assert ActiveConfig().num_candidates == 16 and ActiveConfig().score == "kl"
    assert look_ahead_steps(0.2, 100) == 20 and look_ahead_steps(0.7, 150) == 105
    assert look_ahead_steps(0.01, 10) == 1
    with pytest.raises(ValidationError):
        ActiveConfig(horizon_fraction=1.5)
    with pytest.raises(ValidationError):
        ActiveConfig(score="variance")


def test_no_candidates_is_an_error():
    policy = ActivePolicy(linear_filter(), horizon_steps=10)
    mean, cov = linear_prior()
    with pytest.raises(ValueError, match="no candidate"):
        policy.choose([], mean, cov, _builder([]), torch.Generator())
