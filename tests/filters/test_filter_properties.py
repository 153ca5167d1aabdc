"""Property tests: any valid belief and observation gives a valid belief; long runs stay finite."""

import math

import torch
from filter_toys import (
    F64,
    ToyPushDynamics,
    ToyPushObservation,
    random_walk_toy,
)
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.filters import DualFilter, FilterConfig, JointFilter, default_object_constraints
from pushtoknow.models.analytic import ConstantObservationNoise

NOISE = ConstantObservationNoise([4e-6, 4e-6, 1e-3, 0.04, 0.04])
CONSTRAINT = default_object_constraints(with_footprint=False)


def belief(seed, pose_log_sd, param_log_sd, coupling, param_mean):
    gen = torch.Generator().manual_seed(seed)
    sd = torch.tensor([10**pose_log_sd] * 2 + [10 ** (pose_log_sd + 1)] + [10**param_log_sd] * 5)
    a = torch.randn(8, 8, generator=gen, dtype=F64)
    corr = torch.eye(8, dtype=F64) + coupling * (a @ a.T) / 8
    d = corr.diagonal().rsqrt()
    corr = d[:, None] * corr * d[None, :]
    cov = (sd[:, None] * corr * sd[None, :]).to(F64).unsqueeze(0)
    mean = torch.zeros(1, 8, dtype=F64)
    mean[0, 2] = math.pi * (2 * torch.rand(1, generator=gen, dtype=F64).item() - 1) * 3
    mean[0, 3:] = torch.tensor(param_mean, dtype=F64)
    return mean, cov


def assert_valid(mean, cov):
    assert torch.isfinite(mean).all() and torch.isfinite(cov).all()
    torch.testing.assert_close(cov, cov.transpose(-1, -2), rtol=0, atol=0)
    scale = torch.diagonal(cov, dim1=-2, dim2=-1).amax(-1, keepdim=True)
    assert (torch.linalg.eigvalsh(cov) >= -1e-9 * scale).all()


@settings(max_examples=40, deadline=None)
@given(
    seed=st.integers(0, 2**31 - 1),
    pose_log_sd=st.floats(-4.0, -1.0),
    param_log_sd=st.floats(-3.0, 0.3),
    coupling=st.floats(0.0, 20.0),
    # normalised parameters from just above the physical floors (mass, μ, I_z → 0) to 3
    param_mean=st.lists(st.floats(-1.39, 3.0), min_size=5, max_size=5),
    obs_offset=st.lists(st.floats(-1.0, 1.0), min_size=5, max_size=5),
    force_scale=st.floats(0.0, 30.0),
    num_sigma_points=st.sampled_from([9, 12, 23, 30, 100]),  # C > D = 8
)
def test_one_step_of_any_valid_belief_is_a_valid_belief(
    seed,
    pose_log_sd,
    param_log_sd,
    coupling,
    param_mean,
    obs_offset,
    force_scale,
    num_sigma_points,
):
    mean, cov = belief(seed, pose_log_sd, param_log_sd, coupling, param_mean)
    z = torch.tensor([obs_offset], dtype=F64) * torch.tensor(
        [[0.05, 0.05, 3.0, force_scale, force_scale]], dtype=F64
    )
    z[:, :3] += mean[:, :3]
    cfg = FilterConfig(num_sigma_points=num_sigma_points)
    for cls in (DualFilter, JointFilter):
        filt = cls(ToyPushDynamics(), ToyPushObservation(), NOISE, cfg, CONSTRAINT)
        post_mean, post_cov, info = filt(mean, cov, z, None, generator=torch.Generator())
        assert_valid(post_mean, post_cov)
        if info.weights is not None:
            torch.testing.assert_close(info.weights.sum(-1), torch.ones(1, dtype=F64))
            assert (info.weights >= 0).all()
            assert 1 - 1e-9 <= info.ess.item() <= num_sigma_points + 1e-9


def test_ten_thousand_steps_of_a_random_walk_stay_finite():
    """4 objects, pose random walk, constant parameter, both observed: over 10,000 dual-filter
    steps the parameter variance shrinks by ~10⁴ and the pose variance settles; nothing
    becomes NaN, every covariance stays PSD, and the result still matches the Kalman filter."""
    toy = random_walk_toy()
    _, obs = toy.simulate(4, 10_000, torch.Generator().manual_seed(0))
    filt = DualFilter(*toy.models(), toy.config(num_sigma_points=12))
    mean = toy.prior_mean.expand(4, -1).clone()
    cov = toy.prior_cov.expand(4, -1, -1).clone()
    gen = torch.Generator().manual_seed(1)
    with torch.inference_mode():
        for z in obs:
            mean, cov, _ = filt(mean, cov, z, None, generator=gen)
    assert_valid(mean, cov)
    kf_mean, kf_cov = toy.kalman(obs)
    assert (cov[:, 1, 1] < 1e-4).all()  # 0.25 / 10⁴ = 2.5e-5
    var, kf_var = (torch.diagonal(c, dim1=-2, dim2=-1) for c in (cov, kf_cov))
    torch.testing.assert_close(var, kf_var, rtol=0.1, atol=0.0)
    assert (cov[:, 0, 1].abs() < 1e-3 * (var[:, 0] * var[:, 1]).sqrt()).all()  # KF: exactly 0
    assert ((mean - kf_mean).abs() < 0.5 * torch.diagonal(kf_cov, dim1=-2, dim2=-1).sqrt()).all()
