"""Dual filter (VT-DDF): calibration on a pushed block, ESS guard, NaN handling, bad input."""

import pytest
import torch
from filter_toys import F64, pushed_block, random_walk_toy

from pushtoknow.common.errors import ShapeError
from pushtoknow.filters import DualFilter, FilterConfig, FilterNoise
from pushtoknow.filters.gaussian import CovarianceError
from pushtoknow.filters.liu_west import (
    _log_ess,
    effective_sample_size,
    liu_west_moments,
    tempering_exponent,
)

Z90 = 1.6448536269514722  # two-sided 90 % interval of a Gaussian: ± 1.645 σ


def run(filt, toy, observations, seed=1):
    b = observations.shape[1]
    mean = toy.prior_mean.expand(b, -1).clone()
    cov = toy.prior_cov.expand(b, -1, -1).clone()
    gen = torch.Generator().manual_seed(seed)
    infos = []
    for z in observations:
        mean, cov, info = filt(mean, cov, z, None, generator=gen)
        infos.append(info)
    return mean, cov, infos


def test_pushed_block_posterior_converges_and_is_calibrated():
    """200 seeded runs batched: truth drawn from the prior, 30 steps of noisy force and pose."""
    toy = pushed_block()
    states, obs = toy.simulate(200, 30, torch.Generator().manual_seed(0))
    filt = DualFilter(*toy.models(), toy.config())
    mean, cov, infos = run(filt, toy, obs)
    truth = states[-1, :, 1]
    sd = cov[:, 1, 1].sqrt()
    # converges: posterior sd 25× below the prior's 0.5, error of the order of the sd
    assert sd.max() < 0.03
    assert (mean[:, 1] - truth).pow(2).mean().sqrt() < 0.03
    coverage = ((mean[:, 1] - truth).abs() <= Z90 * sd).double().mean().item()
    assert 0.85 <= coverage <= 0.95, coverage
    # and agrees with the exact (Kalman) posterior of this linear-Gaussian toy
    kf_mean, kf_cov = toy.kalman(obs)
    kf_sd = kf_cov[:, 1, 1].sqrt()
    assert abs((cov[:, 1, 1] / kf_cov[:, 1, 1]).mean().item() - 1) < 0.05
    assert ((mean[:, 1] - kf_mean[:, 1]).abs() / kf_sd).mean() < 0.3
    # the guard was exercised (first steps are sharper than the prior)
    assert any((i.stages > 1).any() for i in infos)


def test_kept_cross_covariance_inflates_the_pose_variance():
    """The paper's literal reassembly (C kept) vs the default: see DualFilter's docstring."""
    toy = pushed_block()
    _, obs = toy.simulate(16, 4, torch.Generator().manual_seed(0))
    _, kf_cov = toy.kalman(obs)
    kept = DualFilter(*toy.models(), toy.config(cross_covariance="kept"))
    updated = DualFilter(*toy.models(), toy.config())
    _, cov_kept, _ = run(kept, toy, obs)
    _, cov_upd, _ = run(updated, toy, obs)
    ratio_kept = (cov_kept[:, 0, 0] / kf_cov[:, 0, 0]).median()
    ratio_upd = (cov_upd[:, 0, 0] / kf_cov[:, 0, 0]).median()
    assert ratio_kept > 100
    assert 0.8 < ratio_upd < 1.25
    assert torch.isfinite(cov_kept).all()  # PSD and finite, just wrong


def test_ess_guard_tempers_a_sharp_update_and_stays_accurate():
    toy = pushed_block(force_std=0.01)  # one force reading pins φ̃ to ±0.006, prior ±0.5
    _, obs = toy.simulate(64, 1, torch.Generator().manual_seed(3))
    kf_mean, kf_cov = toy.kalman(obs)
    guarded = DualFilter(*toy.models(), toy.config(max_tempering_stages=6))
    plain = DualFilter(*toy.models(), toy.config(max_tempering_stages=1))
    m_g, c_g, (info_g,) = run(guarded, toy, obs)
    m_p, c_p, (info_p,) = run(plain, toy, obs)
    assert (info_g.stages > 1).all()
    torch.testing.assert_close(info_g.weights.sum(-1), torch.ones(64, dtype=F64))
    assert (info_p.ess < 10).float().mean() > 0.5  # plain importance weights degenerate
    err_g = ((m_g[:, 1] - kf_mean[:, 1]).abs() / kf_cov[:, 1, 1].sqrt()).mean()
    err_p = ((m_p[:, 1] - kf_mean[:, 1]).abs() / kf_cov[:, 1, 1].sqrt()).mean()
    assert err_g < 0.5 < err_p
    var_ratio = (c_g[:, 1, 1] / kf_cov[:, 1, 1]).median()
    assert 0.6 < var_ratio < 1.5


def test_tempering_exponent_hits_the_target_and_has_the_implicit_gradient():
    gen = torch.Generator().manual_seed(4)
    ll = -50 * torch.rand(3, 40, generator=gen, dtype=F64) ** 2
    remaining = torch.tensor([1.0, 0.4, 1e-3], dtype=F64)
    beta = tempering_exponent(ll, remaining, 20.0)
    ess = _log_ess(ll, beta).exp()
    torch.testing.assert_close(ess[:2], torch.full((2,), 20.0, dtype=F64))
    assert beta[2] == remaining[2]  # the small remainder fits: whole remainder used
    ll.requires_grad_(True)
    assert torch.autograd.gradcheck(
        lambda x: tempering_exponent(x, remaining, 20.0)[:2], (ll,), eps=1e-7, atol=1e-6
    )


def test_liu_west_moments_preserve_mean_and_covariance():
    gen = torch.Generator().manual_seed(5)
    pts = torch.randn(2, 50, 3, generator=gen, dtype=F64)
    w = torch.softmax(torch.randn(2, 50, generator=gen, dtype=F64), -1)
    for h in (0.01, 0.3, 0.9):
        mean, cov, loc = liu_west_moments(pts, w, h)
        torch.testing.assert_close(mean, torch.einsum("bc,bcd->bd", w, pts))
        dev = pts - mean.unsqueeze(1)
        torch.testing.assert_close(cov, torch.einsum("bc,bci,bcj->bij", w, dev, dev))
        a = (1 - h * h) ** 0.5
        torch.testing.assert_close(loc, a * pts + (1 - a) * mean.unsqueeze(1))
    assert effective_sample_size(
        torch.full((1, 8), 1 / 8, dtype=F64).log()
    ).item() == pytest.approx(8)


def test_nan_observation_skips_the_update_for_that_object_only():
    toy = pushed_block()
    dyn, obs_model, noise_model = toy.models(learnable=True)
    filt = DualFilter(dyn, obs_model, noise_model, toy.config())
    _, obs = toy.simulate(3, 1, torch.Generator().manual_seed(6))
    z = obs[0].clone()
    z[1, 1] = float("nan")
    mean = toy.prior_mean.expand(3, -1).clone()
    cov = toy.prior_cov.expand(3, -1, -1).clone()
    noise = filt.draw_noise(3, torch.Generator().manual_seed(7), F64)
    post_mean, post_cov, info = filt(mean, cov, z, None, noise=noise)
    pred_mean, pred_cov = filt.predict(mean, cov, None, noise)
    assert info.skipped.tolist() == [False, True, False]
    torch.testing.assert_close(post_mean[1], pred_mean[1])
    torch.testing.assert_close(post_cov[1], pred_cov[1])
    assert not torch.allclose(post_cov[0], pred_cov[0])
    (post_mean.sum() + post_cov.sum()).backward()
    for p in filt.parameters():
        assert torch.isfinite(p.grad).all()


def test_one_step_is_a_deterministic_function_of_the_noise():
    toy = pushed_block()
    filt = DualFilter(*toy.models(), toy.config())
    _, obs = toy.simulate(4, 1, torch.Generator().manual_seed(8))
    mean = toy.prior_mean.expand(4, -1)
    cov = toy.prior_cov.expand(4, -1, -1)
    a = filt(mean, cov, obs[0], None, generator=torch.Generator().manual_seed(9))
    b = filt(mean, cov, obs[0], None, generator=torch.Generator().manual_seed(9))
    assert torch.equal(a[0], b[0]) and torch.equal(a[1], b[1])


def test_float32_step():
    toy = pushed_block()
    dyn, obs_model, noise_model = toy.models()
    filt = DualFilter(dyn, obs_model, noise_model, toy.config())
    _, obs = toy.simulate(8, 5, torch.Generator().manual_seed(10))
    mean = toy.prior_mean.float().expand(8, -1).clone()
    cov = toy.prior_cov.float().expand(8, -1, -1).clone()
    gen = torch.Generator().manual_seed(11)
    for z in obs.float():
        mean, cov, _ = filt(mean, cov, z, None, generator=gen)
    assert mean.dtype == torch.float32 and torch.isfinite(cov).all()
    assert (torch.linalg.eigvalsh(cov.double()) > 0).all()


def test_bad_input_is_rejected_with_clear_errors():
    toy = pushed_block()
    filt = DualFilter(*toy.models(), toy.config())
    mean = toy.prior_mean.expand(2, -1)
    cov = toy.prior_cov.expand(2, -1, -1)
    z = torch.zeros(2, 2, dtype=F64)
    gen = torch.Generator().manual_seed(0)
    with pytest.raises(ShapeError, match=r"mean: expected shape \(B, D=2\), got \(2, 3\)"):
        filt(torch.zeros(2, 3, dtype=F64), cov, z, None, generator=gen)
    with pytest.raises(ShapeError, match=r"cov: expected shape \(B=2, D=2, D=2\)"):
        filt(mean, cov[:1], z, None, generator=gen)
    with pytest.raises(ShapeError, match=r"observation z: expected shape \(B=2, M=2\)"):
        filt(mean, cov, z[:, :1], None, generator=gen)
    noise = filt.draw_noise(2, gen, F64)
    bad_noise = FilterNoise(noise.predict[:, :, :1], noise.process, noise.update)
    with pytest.raises(ShapeError, match="noise.predict"):
        filt(mean, cov, z, None, noise=bad_noise)
    with pytest.raises(ValueError, match="generator"):
        filt(mean, cov, z, None)
    with pytest.raises(ValueError, match="need C > D = 2"):
        filt(mean, cov, z, None, noise=filt.draw_noise(2, gen, F64, num_sigma_points=2))
    not_pd = cov.clone()
    not_pd[1] = torch.tensor([[1.0, 2.0], [2.0, 1.0]], dtype=F64)
    with pytest.raises(CovarianceError, match=r"batch index \[1\]"):
        filt(mean, not_pd, z, None, generator=gen)
    with pytest.raises(ValueError, match="liu_west_h"):
        FilterConfig(liu_west_h=1.5)


def test_joint_sample_weighting_degrades_over_long_runs():
    """The paper's literal weights (sampled poses) vs the default marginal weights, 300 steps."""
    toy = random_walk_toy()
    _, obs = toy.simulate(16, 300, torch.Generator().manual_seed(12))
    kf_mean, kf_cov = toy.kalman(obs)
    results = {}
    for weighting in ("marginal", "joint_samples"):
        filt = DualFilter(*toy.models(), toy.config(param_weighting=weighting))
        with torch.inference_mode():
            mean, cov, _ = run(filt, toy, obs)
        ratio = (cov[:, 1, 1] / kf_cov[:, 1, 1]).median().item()
        err = ((mean[:, 1] - kf_mean[:, 1]).abs() / kf_cov[:, 1, 1].sqrt()).mean().item()
        results[weighting] = (ratio, err)
    assert 0.9 < results["marginal"][0] < 1.1 and results["marginal"][1] < 0.2
    assert results["joint_samples"][0] < 0.7 and results["joint_samples"][1] > 0.5
