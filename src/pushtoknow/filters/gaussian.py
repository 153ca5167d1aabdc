"""Gaussian utilities on batched tensors (pure functions).

Conventions: a batch of Gaussians has mean (B, D) and covariance (B, D, D); a batch of weighted
point sets has points (B, C, D) and weights (B, C) summing to 1 over C. Leading batch axes may be
any shape where stated as (..., D).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import torch
from torch.distributions import MultivariateNormal, kl_divergence

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.errors import PushToKnowError, ShapeError
from pushtoknow.filters.tensor_shapes import expect_shape


class CovarianceError(PushToKnowError, ValueError):
    """A covariance is not (numerically) positive definite or not finite.

    The message names the batch index (or indices) of the offending matrix.
    """


@dataclass(frozen=True)
class CholeskyConfig:
    """Jitter schedule of `safe_cholesky`.

    The matrix is first equilibrated to its correlation matrix (unit diagonal), so the jitter is
    relative to each variance: Cholesky of A + j · diag(A) is tried for j = 0, then
    j = initial_jitter · growth^k while j ≤ max_jitter. initial_jitter None means 10 · eps of
    the dtype (2.2e-15 in float64, 1.2e-6 in float32). A matrix that needs more than max_jitter
    (its smallest correlation-matrix eigenvalue is below about -max_jitter) is an error.
    """

    initial_jitter: float | None = None
    growth: float = 10.0
    max_jitter: float = 1e-3


DEFAULT_CHOLESKY = CholeskyConfig()


def symmetrize(a: torch.Tensor) -> torch.Tensor:
    """(..., D, D) → ½ (A + Aᵀ)."""
    return 0.5 * (a + a.transpose(-1, -2))


def _check_gaussian(mean: torch.Tensor, cov: torch.Tensor, name: str) -> tuple[int, int]:
    expect_shape(mean, f"{name} mean", [("B", None), ("D", None)])
    b, d = mean.shape
    expect_shape(cov, f"{name} cov", [("B", b), ("D", d), ("D", d)])
    return b, d


def _check_points(points: torch.Tensor, weights: torch.Tensor | None) -> None:
    expect_shape(points, "points", [("B", None), ("C", None), ("D", None)])
    if weights is not None:
        expect_shape(weights, "weights", [("B", points.shape[0]), ("C", points.shape[1])])


def _bad_indices(mask: torch.Tensor) -> list:
    idx = torch.nonzero(mask, as_tuple=False).tolist()
    return [i[0] if len(i) == 1 else tuple(i) for i in idx][:10]


def safe_cholesky(
    a: torch.Tensor, config: CholeskyConfig = DEFAULT_CHOLESKY, name: str = "covariance"
) -> torch.Tensor:
    """Lower Cholesky factor L (..., D, D) of a symmetric PSD matrix A (..., D, D), L Lᵀ ≈ A.

    Symmetrises A, equilibrates it by its diagonal, and adds escalating jitter (see
    `CholeskyConfig`) only to the batch entries whose factorisation fails. Raises
    `CovarianceError` naming the batch indices of non-finite matrices, negative variances, or
    matrices that stay indefinite at the largest jitter. Differentiable.
    """
    if a.ndim < 2 or a.shape[-1] != a.shape[-2]:
        raise ShapeError(f"{name}: expected shape (..., D, D), got {tuple(a.shape)}")
    batch_shape = a.shape[:-2]
    a = symmetrize(a)
    diag = torch.diagonal(a, dim1=-2, dim2=-1)
    # Equilibrate: work on the correlation matrix; zero variances keep unit scale.
    scale = torch.sqrt(torch.where(diag > 0, diag, torch.ones_like(diag)))
    corr = a / (scale.unsqueeze(-1) * scale.unsqueeze(-2))
    # Fast path (one host sync): every entry factorises without jitter and is finite.
    chol, info = torch.linalg.cholesky_ex(corr)
    if not bool(info.any()) and bool(torch.isfinite(chol).all()):
        return scale.unsqueeze(-1) * chol
    finite = torch.isfinite(a).flatten(-2).all(-1)
    if not bool(finite.all()):
        raise CovarianceError(
            f"{name} has non-finite entries at batch index {_bad_indices(~finite)}"
        )
    eps = torch.finfo(a.dtype).eps
    neg = (diag < -eps * diag.abs().amax(-1, keepdim=True).clamp_min(eps)).any(-1)
    if bool(neg.any()):
        raise CovarianceError(
            f"{name} is not positive semi-definite (negative variance) at batch index "
            f"{_bad_indices(neg)}"
        )
    eye = torch.eye(a.shape[-1], dtype=a.dtype, device=a.device)
    # Slow path: find the smallest jitter that works for each entry without recording a graph,
    # then run one differentiable factorisation on matrices known to be PD (a failed partial
    # factor in the graph would put NaN into the backward pass).
    with torch.no_grad():
        corr_d = corr.detach()
        failed = torch.linalg.cholesky_ex(corr_d)[1] != 0
        jitter_used = torch.zeros(batch_shape, dtype=a.dtype, device=a.device)
        jitter = config.initial_jitter if config.initial_jitter is not None else 10.0 * eps
        while bool(failed.any()) and jitter <= config.max_jitter * (1 + 1e-9):
            ok = failed & (torch.linalg.cholesky_ex(corr_d + jitter * eye)[1] == 0)
            jitter_used = torch.where(ok, torch.full_like(jitter_used, jitter), jitter_used)
            failed = failed & ~ok
            jitter *= config.growth
    if bool(failed.any()):
        raise CovarianceError(
            f"{name} is not positive definite at batch index {_bad_indices(failed)} "
            f"(Cholesky failed with relative jitter up to {config.max_jitter:g}); "
            f"batch shape {tuple(batch_shape)}"
        )
    chol, info = torch.linalg.cholesky_ex(corr + jitter_used[..., None, None] * eye)
    if bool((info != 0).any()):  # pragma: no cover - same input as the successful trial
        raise CovarianceError(f"{name}: Cholesky failed at batch index {_bad_indices(info != 0)}")
    return scale.unsqueeze(-1) * chol


def cholesky_solve_spd(
    a: torch.Tensor,
    b: torch.Tensor,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
    name: str = "matrix",
) -> torch.Tensor:
    """Solve A X = B for symmetric PD A (..., D, D), B (..., D, K) → X (..., D, K)."""
    return torch.cholesky_solve(b, safe_cholesky(a, config, name))


def weighted_mean(points: torch.Tensor, weights: torch.Tensor | None = None) -> torch.Tensor:
    """points (B, C, D), weights (B, C) or None (uniform) → (B, D)."""
    _check_points(points, weights)
    if weights is None:
        return points.mean(dim=-2)
    return (weights.unsqueeze(-2) @ points).squeeze(-2)


def circular_weighted_mean(
    points: torch.Tensor,
    weights: torch.Tensor | None = None,
    angle_indices: Sequence[int] = (),
    reference: torch.Tensor | None = None,
) -> torch.Tensor:
    """Weighted mean (B, D) of points (B, C, D) with angle components averaged around a reference.

    For angle indices the mean is ref + Σ w_i wrap(p_i - ref), ref = `reference` (B, D) or the
    first point; exact for spreads below π, continuous across the ±π wrap.
    """
    mean = weighted_mean(points, weights)
    if not angle_indices:
        return mean
    idx = list(angle_indices)
    ref = points[:, 0, idx] if reference is None else reference[:, idx]
    dev = wrap_angle(points[..., idx] - ref.unsqueeze(-2))
    ang = ref + weighted_mean(dev, weights)
    out = mean.clone()
    out[:, idx] = ang
    return out


def wrap_residual(residual: torch.Tensor, angle_indices: Sequence[int] = ()) -> torch.Tensor:
    """(..., D) residual with the components at `angle_indices` wrapped to (-π, π]."""
    if not angle_indices:
        return residual
    idx = list(angle_indices)
    out = residual.clone()
    out[..., idx] = wrap_angle(residual[..., idx])
    return out


def weighted_cross_covariance(
    dev_a: torch.Tensor, dev_b: torch.Tensor, weights: torch.Tensor | None = None
) -> torch.Tensor:
    """Σ_i w_i a_i b_iᵀ for deviations a (B, C, Da), b (B, C, Db) → (B, Da, Db).

    Uniform weights (None) mean w_i = 1/C (the biased, moment-matching normalisation).
    """
    if weights is None:
        return dev_a.transpose(-1, -2) @ dev_b / dev_a.shape[-2]
    return (dev_a * weights.unsqueeze(-1)).transpose(-1, -2) @ dev_b


def weighted_covariance(
    points: torch.Tensor,
    weights: torch.Tensor | None = None,
    mean: torch.Tensor | None = None,
    angle_indices: Sequence[int] = (),
) -> torch.Tensor:
    """Weighted covariance (B, D, D) of points (B, C, D) about `mean` (default: weighted mean).

    Angle components of the deviations are wrapped. Weights (B, C) sum to 1; None is uniform 1/C.
    """
    _check_points(points, weights)
    if mean is None:
        mean = circular_weighted_mean(points, weights, angle_indices)
    dev = wrap_residual(points - mean.unsqueeze(-2), angle_indices)
    return symmetrize(weighted_cross_covariance(dev, dev, weights))


def condition_gaussian(
    mean: torch.Tensor,
    cov: torch.Tensor,
    split: int,
    value: torch.Tensor,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Condition N(mean, cov) over s = (a, b), a = s[:split], on b = value (paper eq. 14–15).

    mean (B, D), cov (B, D, D), value (B, D - split). Returns
    μ_a|b = μ_a + Σ_ab Σ_bb⁻¹ (value - μ_b) (B, split) and
    Σ_a|b = Σ_aa - Σ_ab Σ_bb⁻¹ Σ_ba (B, split, split), symmetrised.
    """
    b, d = _check_gaussian(mean, cov, "condition_gaussian")
    if not 0 < split < d:
        raise ShapeError(f"condition_gaussian: split must be in 1..{d - 1}, got {split}")
    expect_shape(value, "condition_gaussian value", [("B", b), ("D - split", d - split)])
    mu_a, mu_b = mean[:, :split], mean[:, split:]
    s_aa, s_ab, s_bb = cov[:, :split, :split], cov[:, :split, split:], cov[:, split:, split:]
    chol_bb = safe_cholesky(s_bb, config, "conditioning block Σ_bb")
    # gain = Σ_ab Σ_bb⁻¹, computed as (Σ_bb⁻¹ Σ_ba)ᵀ
    gain = torch.cholesky_solve(s_ab.transpose(-1, -2), chol_bb).transpose(-1, -2)
    mu = mu_a + (gain @ (value - mu_b).unsqueeze(-1)).squeeze(-1)
    sigma = symmetrize(s_aa - gain @ s_ab.transpose(-1, -2))
    return mu, sigma


def kl_gaussian(
    mean_p: torch.Tensor,
    cov_p: torch.Tensor,
    mean_q: torch.Tensor,
    cov_q: torch.Tensor,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """KL( N(mean_p, cov_p) ‖ N(mean_q, cov_q) ) (B,) in nats, closed form (torch.distributions)."""
    _check_gaussian(mean_p, cov_p, "kl_gaussian p")
    _check_gaussian(mean_q, cov_q, "kl_gaussian q")
    p = MultivariateNormal(mean_p, scale_tril=safe_cholesky(cov_p, config, "cov_p"))
    q = MultivariateNormal(mean_q, scale_tril=safe_cholesky(cov_q, config, "cov_q"))
    return kl_divergence(p, q)


def gaussian_log_prob(
    x: torch.Tensor,
    mean: torch.Tensor,
    cov: torch.Tensor,
    angle_indices: Sequence[int] = (),
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """log N(x; mean, cov) (B,) for x, mean (B, D), cov (B, D, D), angle residuals wrapped.

    Uses `safe_cholesky`, so it accepts the filters' (numerically PSD) covariances in float32,
    where `torch.distributions.MultivariateNormal`'s strict validation may reject them.
    """
    chol = safe_cholesky(cov, config, "covariance")
    residual = wrap_residual(x - mean, angle_indices)
    white = torch.linalg.solve_triangular(chol, residual.unsqueeze(-1), upper=False).squeeze(-1)
    log_det = 2.0 * torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)
    d = x.shape[-1]
    return -0.5 * (white.square().sum(-1) + log_det + d * math.log(2.0 * math.pi))


def sample_gaussian(mean: torch.Tensor, chol: torch.Tensor, eps: torch.Tensor) -> torch.Tensor:
    """Reparameterised samples χ = μ + L ε (B, C, D): mean (B, D), chol (B, D, D), eps (B, C, D)."""
    b, d = _check_gaussian(mean, chol, "sample_gaussian")
    expect_shape(eps, "sample_gaussian eps", [("B", b), ("C", None), ("D", d)])
    return mean.unsqueeze(-2) + eps @ chol.transpose(-1, -2)


def antithetic_noise(eps: torch.Tensor) -> torch.Tensor:
    """Antithetic pairs from draws eps (B, C, D): the first ⌊C/2⌋ draws and their negatives
    (and a zero draw if C is odd). All odd sample moments are then exactly zero."""
    half = eps.shape[-2] // 2
    parts = [eps[..., :half, :], -eps[..., :half, :]]
    if eps.shape[-2] % 2:
        parts.append(torch.zeros_like(eps[..., :1, :]))
    return torch.cat(parts, dim=-2)


def moment_match_noise(eps: torch.Tensor) -> torch.Tensor:
    """Standardise draws eps (B, C, D) to exactly zero sample mean and identity covariance.

    The covariance uses the 1/C normalisation of `weighted_covariance`, so samples
    μ + L ε then reproduce (μ, L Lᵀ) exactly. Needs C > D; otherwise only the mean is removed.
    A deterministic function of the draws (no gradient is needed through it).
    """
    centred = eps - eps.mean(dim=-2, keepdim=True)
    n, d = eps.shape[-2], eps.shape[-1]
    if n <= d:
        return centred
    cov = weighted_cross_covariance(centred, centred)
    chol = safe_cholesky(cov, name="noise sample covariance")
    # ε_w = centred L⁻ᵀ  ⇔  solve L ε_wᵀ = centredᵀ
    white_t = torch.linalg.solve_triangular(chol, centred.transpose(-1, -2), upper=False)
    return white_t.transpose(-1, -2)


def gaussian_log_likelihood_unnormalised(
    residual: torch.Tensor, noise: torch.Tensor, config: CholeskyConfig = DEFAULT_CHOLESKY
) -> torch.Tensor:
    """-½ rᵀ R⁻¹ r for residuals (B, C, M) with R diagonal (B, M) or full (B, M, M) → (B, C)."""
    if noise.ndim == residual.ndim - 1:
        return -0.5 * (residual.square() / noise.unsqueeze(-2)).sum(-1)
    chol = safe_cholesky(noise, config, "observation noise R")
    white = torch.linalg.solve_triangular(chol, residual.transpose(-1, -2), upper=False)
    return -0.5 * white.square().sum(-2)
