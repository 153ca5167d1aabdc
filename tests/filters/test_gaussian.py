"""Gaussian utilities: moments, safe Cholesky, conditioning, KL, angle residuals, noise."""

import math

import numpy as np
import pytest
import torch

from pushtoknow.common.errors import PushToKnowError, ShapeError
from pushtoknow.filters.gaussian import (
    CovarianceError,
    antithetic_noise,
    circular_weighted_mean,
    condition_gaussian,
    gaussian_log_likelihood_unnormalised,
    gaussian_log_prob,
    kl_gaussian,
    moment_match_noise,
    safe_cholesky,
    weighted_covariance,
    weighted_mean,
    wrap_residual,
)

F64 = torch.float64


def random_spd(b, d, gen, dtype=F64, scale=1.0):
    a = torch.randn(b, d, d, generator=gen, dtype=dtype)
    return scale * (a @ a.transpose(-1, -2) + 0.1 * torch.eye(d, dtype=dtype))


def test_weighted_moments_match_numpy():
    gen = torch.Generator().manual_seed(0)
    x = torch.randn(3, 50, 4, generator=gen, dtype=F64)
    w = torch.softmax(torch.randn(3, 50, generator=gen, dtype=F64), -1)
    mean = weighted_mean(x, w)
    cov = weighted_covariance(x, w)
    for i in range(3):
        xi, wi = x[i].numpy(), w[i].numpy()
        np.testing.assert_allclose(mean[i].numpy(), np.average(xi, axis=0, weights=wi))
        ref = np.cov(xi.T, aweights=wi, bias=True)
        np.testing.assert_allclose(cov[i].numpy(), ref, atol=1e-12)
    # uniform weights = 1/C
    np.testing.assert_allclose(
        weighted_covariance(x)[0].numpy(), np.cov(x[0].numpy().T, bias=True), atol=1e-12
    )


def test_safe_cholesky_pd_and_semidefinite():
    gen = torch.Generator().manual_seed(1)
    a = random_spd(4, 6, gen)
    chol = safe_cholesky(a)
    torch.testing.assert_close(chol @ chol.transpose(-1, -2), a)
    # rank-deficient PSD (rank 2 in 5-D): repaired by a relative jitter
    v = torch.randn(2, 5, 2, generator=gen, dtype=F64)
    psd = v @ v.transpose(-1, -2)
    chol = safe_cholesky(psd)
    assert torch.isfinite(chol).all()
    torch.testing.assert_close(chol @ chol.transpose(-1, -2), psd, atol=1e-6, rtol=1e-6)


def test_safe_cholesky_float32_disparate_scales():
    # pose variances ~1e-8 m², parameter variances ~1, correlation 0.999: equilibration copes
    sd = torch.tensor([1e-4, 1.0])
    corr = torch.tensor([[1.0, 0.999], [0.999, 1.0]])
    a = (sd[:, None] * corr * sd[None, :]).unsqueeze(0)
    chol = safe_cholesky(a)
    torch.testing.assert_close(chol @ chol.transpose(-1, -2), a, rtol=1e-4, atol=1e-12)


def test_safe_cholesky_errors_name_the_batch_index():
    good = torch.eye(2, dtype=F64)
    bad = torch.tensor([[1.0, 2.0], [2.0, 1.0]], dtype=F64)  # eigenvalues 3, -1
    with pytest.raises(CovarianceError, match=r"batch index \[1\]") as info:
        safe_cholesky(torch.stack([good, bad, good]))
    assert isinstance(info.value, PushToKnowError)
    nan = good.clone()
    nan[0, 1] = float("nan")
    with pytest.raises(CovarianceError, match=r"non-finite.*\[2\]"):
        safe_cholesky(torch.stack([good, good, nan]))
    with pytest.raises(CovarianceError, match="negative variance"):
        safe_cholesky(-good.unsqueeze(0))
    with pytest.raises(ShapeError, match=r"\(\.\.\., D, D\).*\(2, 3\)"):
        safe_cholesky(torch.zeros(2, 3))


def test_safe_cholesky_gradient_finite_on_jitter_path():
    v = torch.randn(1, 4, 2, dtype=F64, generator=torch.Generator().manual_seed(2))
    v.requires_grad_(True)
    chol = safe_cholesky(v @ v.transpose(-1, -2) + 0.0)
    chol.sum().backward()
    assert torch.isfinite(v.grad).all()


def test_condition_gaussian_matches_closed_form():
    gen = torch.Generator().manual_seed(3)
    cov = random_spd(2, 5, gen)
    mean = torch.randn(2, 5, generator=gen, dtype=F64)
    value = torch.randn(2, 2, generator=gen, dtype=F64)
    mu, sigma = condition_gaussian(mean, cov, 3, value)
    for i in range(2):
        s = cov[i].numpy()
        s_aa, s_ab, s_bb = s[:3, :3], s[:3, 3:], s[3:, 3:]
        g = s_ab @ np.linalg.inv(s_bb)
        np.testing.assert_allclose(
            mu[i].numpy(), mean[i, :3].numpy() + g @ (value[i].numpy() - mean[i, 3:].numpy())
        )
        np.testing.assert_allclose(sigma[i].numpy(), s_aa - g @ s_ab.T, atol=1e-12)


def test_kl_gaussian_closed_form_and_zero_for_equal():
    gen = torch.Generator().manual_seed(4)
    p, q = random_spd(3, 4, gen), random_spd(3, 4, gen)
    mp, mq = (
        torch.randn(3, 4, generator=gen, dtype=F64),
        torch.randn(3, 4, generator=gen, dtype=F64),
    )
    kl = kl_gaussian(mp, p, mq, q)
    qi = torch.linalg.inv(q)
    dm = (mq - mp).unsqueeze(-1)
    ref = 0.5 * (
        torch.einsum("bii->b", qi @ p)
        + (dm.transpose(-1, -2) @ qi @ dm).squeeze()
        - 4
        + torch.logdet(q)
        - torch.logdet(p)
    )
    torch.testing.assert_close(kl, ref)
    torch.testing.assert_close(kl_gaussian(mp, p, mp, p), torch.zeros(3, dtype=F64))


def test_angle_residuals_and_circular_mean_across_the_wrap():
    r = torch.tensor([[0.1, 2 * math.pi - 0.1, 3 * math.pi]], dtype=F64)
    out = wrap_residual(r, (1, 2))
    torch.testing.assert_close(out, torch.tensor([[0.1, -0.1, math.pi]], dtype=F64))
    pts = torch.tensor([[[math.pi - 0.1], [-math.pi + 0.1], [math.pi - 0.05], [-math.pi + 0.05]]])
    mean = circular_weighted_mean(pts.double(), None, (0,))
    assert abs(math.remainder(mean.item() - math.pi, 2 * math.pi)) < 1e-12
    cov = weighted_covariance(pts.double(), None, mean, (0,))
    torch.testing.assert_close(cov.squeeze(), torch.tensor((0.01 + 0.0025) / 2, dtype=F64))


def test_noise_standardisation_is_exact():
    eps = torch.randn(2, 30, 5, generator=torch.Generator().manual_seed(5), dtype=F64)
    anti = antithetic_noise(eps)
    torch.testing.assert_close(anti[:, :15], eps[:, :15])
    torch.testing.assert_close(anti[:, 15:], -eps[:, :15])
    white = moment_match_noise(anti)
    torch.testing.assert_close(white.mean(1), torch.zeros(2, 5, dtype=F64))
    eye = torch.eye(5, dtype=F64).expand(2, 5, 5)
    torch.testing.assert_close(white.transpose(1, 2) @ white / 30, eye)
    # third moments of antithetic draws vanish
    torch.testing.assert_close((white**3).mean(1), torch.zeros(2, 5, dtype=F64))


def test_log_likelihood_diagonal_equals_full():
    gen = torch.Generator().manual_seed(6)
    res = torch.randn(2, 7, 3, generator=gen, dtype=F64)
    r = torch.rand(2, 3, generator=gen, dtype=F64) + 0.1
    torch.testing.assert_close(
        gaussian_log_likelihood_unnormalised(res, r),
        gaussian_log_likelihood_unnormalised(res, torch.diag_embed(r)),
    )


def test_gaussian_log_prob_matches_torch_distributions():
    gen = torch.Generator().manual_seed(7)
    cov = random_spd(3, 4, gen)
    mean = torch.randn(3, 4, generator=gen, dtype=F64)
    x = torch.randn(3, 4, generator=gen, dtype=F64)
    ref = torch.distributions.MultivariateNormal(mean, covariance_matrix=cov).log_prob(x)
    torch.testing.assert_close(gaussian_log_prob(x, mean, cov), ref)
    shifted = x.clone()
    shifted[:, 2] += 2 * math.pi
    torch.testing.assert_close(gaussian_log_prob(shifted, mean, cov, angle_indices=(2,)), ref)


def test_pure_functions_check_shapes():
    with pytest.raises(ShapeError, match=r"weights: expected shape \(B=2, C=5\), got \(2, 4\)"):
        weighted_mean(torch.zeros(2, 5, 3), torch.zeros(2, 4))
    with pytest.raises(ShapeError, match="condition_gaussian value"):
        condition_gaussian(torch.zeros(1, 4), torch.eye(4).unsqueeze(0), 3, torch.zeros(1, 2))
    with pytest.raises(ShapeError, match="kl_gaussian q cov"):
        kl_gaussian(torch.zeros(1, 2), torch.eye(2)[None], torch.zeros(1, 2), torch.eye(3)[None])
