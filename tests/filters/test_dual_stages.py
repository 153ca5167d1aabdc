"""The dual update's stages on their own (`filters.dual`): the conditional pose against the
Gaussian conditioning formula, the total observation slope against a linear h, and the joint
reassembly's covariance structure."""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.filters import FilterConfig
from pushtoknow.filters.dual import (
    ParameterPosterior,
    conditional_pose,
    reassemble_joint,
    total_observation_slope,
)
from pushtoknow.filters.ukf import UKFUpdateResult

F64 = torch.float64
P, K, M = 3, 2, 4


def cfg(**kw) -> FilterConfig:
    return FilterConfig(pose_dim=P, param_dim=K, pose_angle_indices=(), **kw)


def random_spd(rng: np.random.Generator, b: int, d: int) -> torch.Tensor:
    a = rng.normal(size=(b, d, d))
    return torch.tensor(a @ a.transpose(0, 2, 1) + 0.5 * np.eye(d), dtype=F64)


@settings(max_examples=30, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_conditional_pose_is_gaussian_conditioning(seed):
    rng = np.random.default_rng(seed)
    cov = random_spd(rng, 2, P + K)
    mean = torch.tensor(rng.normal(size=(2, P + K)), dtype=F64)
    phi = torch.tensor(rng.normal(size=(2, K)), dtype=F64)
    cond = conditional_pose(cov, P, cfg())
    for i in range(2):
        s = cov[i].numpy()
        g = s[:P, P:] @ np.linalg.inv(s[P:, P:])
        np.testing.assert_allclose(cond.slope[i].numpy(), g, rtol=1e-9, atol=1e-12)
        np.testing.assert_allclose(
            cond.cov[i].numpy(), s[:P, :P] - g @ s[P:, :P], rtol=1e-9, atol=1e-12
        )
        expected = mean[i, :P].numpy() + g @ (phi[i] - mean[i, P:]).numpy()
        np.testing.assert_allclose(cond.mean_given(mean, phi)[i].numpy(), expected, rtol=1e-9)


@pytest.mark.parametrize("weighting", ["marginal", "joint_samples"])
def test_total_slope_of_a_linear_observation(weighting):
    """h(ψ, φ) = H_ψ ψ + H_φ φ: along ψ̂(φ) = μ̄_ψ + G (φ − μ̄_φ) the total slope is H_ψ G + H_φ,
    whichever way the stage-0 points were drawn."""
    rng = np.random.default_rng(0)
    h_pose = torch.tensor(rng.normal(size=(M, P)), dtype=F64)
    h_par = torch.tensor(rng.normal(size=(M, K)), dtype=F64)
    slope = torch.tensor(rng.normal(size=(1, P, K)), dtype=F64)
    phi = torch.tensor(rng.normal(size=(1, 50, K)), dtype=F64)
    if weighting == "marginal":
        pose = phi @ slope.mT  # the points lie on ψ̂(φ)
    else:
        pose = torch.tensor(rng.normal(size=(1, 50, P)), dtype=F64)
    points = torch.cat([pose, phi], -1)
    obs = pose @ h_pose.T + phi @ h_par.T
    total = total_observation_slope(points, obs, slope, P, cfg(param_weighting=weighting))
    torch.testing.assert_close(total[0], h_pose @ slope[0] + h_par, rtol=1e-9, atol=1e-10)


def _stage_results(rng):
    ukf_cov = random_spd(rng, 1, P)
    ukf = UKFUpdateResult(
        mean=torch.tensor(rng.normal(size=(1, P)), dtype=F64),
        cov=ukf_cov,
        predicted_obs=torch.zeros(1, M, dtype=F64),
        innovation_cov=torch.eye(M, dtype=F64)[None],
        gain=torch.tensor(rng.normal(size=(1, P, M)), dtype=F64),
        innovation=torch.zeros(1, M, dtype=F64),
    )
    params = ParameterPosterior(
        mean=torch.tensor(rng.normal(size=(1, K)), dtype=F64),
        cov=random_spd(rng, 1, K),
        weights=torch.full((1, 8), 1 / 8, dtype=F64),
        ess=torch.tensor([8.0], dtype=F64),
        stages=torch.ones(1, dtype=torch.long),
        first_points=torch.zeros(1, 8, P + K, dtype=F64),
        first_obs=torch.zeros(1, 8, M, dtype=F64),
    )
    return ukf, params


@settings(max_examples=20, deadline=None)
@given(seed=st.integers(0, 2**31 - 1))
def test_updated_reassembly_keeps_the_conditional_pose_posterior(seed):
    """Σ = [[Σ_ψ|φ⁺ + G⁺ Σ_φ G⁺ᵀ, G⁺ Σ_φ], [·, Σ_φ]] with G⁺ = G − K D: its Schur complement
    is the UKF's covariance, so Σ is PSD, and its means are the stages'."""
    rng = np.random.default_rng(seed)
    ukf, params = _stage_results(rng)
    slope = torch.tensor(rng.normal(size=(1, P, K)), dtype=F64)
    total = torch.tensor(rng.normal(size=(1, M, K)), dtype=F64)
    mean, cov = reassemble_joint(ukf, params, torch.zeros(1, P, K, dtype=F64), slope, total, cfg())
    torch.testing.assert_close(mean, torch.cat([ukf.mean, params.mean], -1))
    g_post = slope - ukf.gain @ total
    torch.testing.assert_close(cov[:, :P, P:], g_post @ params.cov)
    torch.testing.assert_close(cov[:, P:, P:], params.cov)
    schur = cov[:, :P, :P] - cov[:, :P, P:] @ torch.linalg.solve(params.cov, cov[:, P:, :P])
    torch.testing.assert_close(schur, ukf.cov, rtol=1e-8, atol=1e-10)
    assert torch.linalg.eigvalsh(cov).min() > -1e-10


def test_kept_reassembly_keeps_the_predicted_cross_covariance():
    rng = np.random.default_rng(1)
    ukf, params = _stage_results(rng)
    cross = torch.tensor(rng.normal(size=(1, P, K)), dtype=F64) * 0.1
    slope = torch.zeros(1, P, K, dtype=F64)
    _, cov = reassemble_joint(ukf, params, cross, slope, None, cfg(cross_covariance="kept"))
    torch.testing.assert_close(cov[:, :P, P:], cross)
    expected = ukf.cov + cross @ torch.linalg.solve(params.cov, cross.mT)
    torch.testing.assert_close(cov[:, :P, :P], expected, rtol=1e-9, atol=1e-12)
    with pytest.raises(ValueError, match="total observation slope"):
        reassemble_joint(ukf, params, cross, slope, None, cfg())
