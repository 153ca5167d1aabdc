"""Joint filter (VT-JDF) and vision-only configuration (V-DDF)."""

import math

import pytest
import torch
from filter_toys import F64, planar_toy, pushed_block

from pushtoknow.filters import JointFilter, PoseObservation, vision_only_filter
from pushtoknow.models.analytic import ConstantObservationNoise


def run(filt, toy, observations, seed=1, context=None):
    b = observations.shape[1]
    mean = toy.prior_mean.expand(b, -1).clone()
    cov = toy.prior_cov.expand(b, -1, -1).clone()
    gen = torch.Generator().manual_seed(seed)
    for z in observations:
        mean, cov, info = filt(mean, cov, z, context, generator=gen)
    return mean, cov


def test_joint_filter_equals_kalman_on_linear_gaussian_with_moment_matched_noise():
    """Antithetic, moment-matched draws make the Monte-Carlo prediction exact for linear
    dynamics, and the UKF update is exact for linear observations."""
    toy = planar_toy()
    _, obs = toy.simulate(8, 25, torch.Generator().manual_seed(0))
    mean, cov = run(JointFilter(*toy.models(), toy.config(num_sigma_points=40)), toy, obs)
    kf_mean, kf_cov = toy.kalman(obs)
    torch.testing.assert_close(mean, kf_mean, atol=1e-8, rtol=1e-6)
    torch.testing.assert_close(cov, kf_cov, atol=1e-10, rtol=1e-6)


def test_joint_filter_matches_kalman_within_monte_carlo_error_with_plain_draws():
    toy = planar_toy()
    _, obs = toy.simulate(32, 25, torch.Generator().manual_seed(1))
    cfg = toy.config(num_sigma_points=400, antithetic_noise=False, moment_matched_noise=False)
    mean, cov = run(JointFilter(*toy.models(), cfg), toy, obs)
    kf_mean, kf_cov = toy.kalman(obs)
    sd = torch.diagonal(kf_cov, dim1=-2, dim2=-1).sqrt()
    z_err = (mean - kf_mean) / sd
    assert z_err.abs().mean() < 0.3  # the posterior means differ by a fraction of a sd
    ratio = torch.diagonal(cov, dim1=-2, dim2=-1) / torch.diagonal(kf_cov, dim1=-2, dim2=-1)
    # Resampling a constant parameter each step makes its variance a multiplicative random
    # walk (±7 % per step at C = 400, drifting down by 1/C): the reason the default draws are
    # moment-matched (previous test: exact).
    assert (ratio.mean(0) - 1).abs().max() < 0.25


def test_vision_only_filter_uses_pose_only_and_learns_from_coupling():
    """z = pose: parameters are learnt only through the ψ–φ coupling of the dynamics."""
    toy = pushed_block(lag_m=0.01, pos_std=0.001, steps_q=1e-4)
    states, obs = toy.simulate(64, 20, torch.Generator().manual_seed(2))
    dyn, _, _ = toy.models()
    noise = ConstantObservationNoise(toy.r_diag[:1])
    filt = vision_only_filter(dyn, noise, toy.config())
    assert isinstance(filt.observation, PoseObservation)
    mean, cov = run(filt, toy, obs[..., :1])
    sd = cov[:, 1, 1].sqrt()
    assert sd.max() < 0.25  # prior sd 0.5
    err = (mean[:, 1] - states[-1, :, 1]).abs() / sd
    assert err.mean() < 1.2


def test_joint_filter_skips_nan_observations_and_checks_angles():
    toy = planar_toy()
    filt = JointFilter(*toy.models(), toy.config())
    _, obs = toy.simulate(2, 1, torch.Generator().manual_seed(3))
    z = obs[0].clone()
    z[0, 2] = float("inf")
    mean = toy.prior_mean.expand(2, -1)
    cov = toy.prior_cov.expand(2, -1, -1)
    noise = filt.draw_noise(2, torch.Generator().manual_seed(4), F64)
    post_mean, post_cov, info = filt(mean, cov, z, None, noise=noise)
    pred_mean, pred_cov = filt.predict(mean, cov, None, noise)
    assert info.skipped.tolist() == [True, False]
    torch.testing.assert_close(post_mean[0], pred_mean[0])
    torch.testing.assert_close(post_cov[0], pred_cov[0])


@pytest.mark.parametrize("offset", [0.0, 2 * math.pi])
def test_theta_residual_wrapped_in_updates(offset):
    """An observed θ that differs from the state's unwrapped θ by 2π is the same observation."""
    toy = planar_toy()
    obs_model = PoseObservation(3, (2,))
    noise = ConstantObservationNoise(toy.r_diag[:3])
    filt = JointFilter(toy.models()[0], obs_model, noise, toy.config())
    mean = toy.prior_mean.expand(1, -1).clone()
    mean[:, 2] = math.pi - 0.01
    cov = toy.prior_cov.expand(1, -1, -1)
    z = torch.tensor([[0.005, 0.0, -math.pi + 0.02]], dtype=F64) + torch.tensor(
        [[0.0, 0.0, offset]], dtype=F64
    )
    noise_draws = filt.draw_noise(1, torch.Generator().manual_seed(5), F64)
    post, _, _ = filt(mean, cov, z, None, noise=noise_draws)
    assert abs(post[0, 2].item() - (math.pi + 0.02)) < 0.02  # moved forward, not by -2π
