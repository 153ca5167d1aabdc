"""Sigma points: Merwe scaled (deterministic, UKF) and Monte-Carlo (reparameterised, DDF)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pushtoknow.filters.gaussian import (
    DEFAULT_CHOLESKY,
    CholeskyConfig,
    moment_match_noise,
    safe_cholesky,
    sample_gaussian,
)


@dataclass(frozen=True)
class MerweScaledSigmaPoints:
    """Van der Merwe's scaled sigma points (2n + 1 points for an n-D Gaussian).

    λ = α² (n + κ) - n; points μ, μ ± columns of chol((n + λ) Σ). Weights
    Wm_0 = λ / (n + λ), Wc_0 = Wm_0 + 1 - α² + β, Wm_i = Wc_i = 1 / (2 (n + λ)).
    Same convention as filterpy's `MerweScaledSigmaPoints` (point order included).

    Defaults α = 1, β = 2, κ = 0 give λ = 0: points at ±√n σ, no negative weights, which keeps
    float32 covariances PSD. The classic α = 1e-3 works in float64 but has Wm_0 ≈ -10⁶.
    """

    alpha: float = 1.0
    beta: float = 2.0
    kappa: float = 0.0

    def num_points(self, dim: int) -> int:
        return 2 * dim + 1

    def lambda_(self, dim: int) -> float:
        return self.alpha**2 * (dim + self.kappa) - dim

    def weights(
        self, dim: int, dtype: torch.dtype = torch.float64, device: torch.device | None = None
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Mean and covariance weights, each (2 dim + 1,)."""
        lam = self.lambda_(dim)
        c = 0.5 / (dim + lam)
        wm = torch.full((2 * dim + 1,), c, dtype=dtype, device=device)
        wc = wm.clone()
        wm[0] = lam / (dim + lam)
        wc[0] = lam / (dim + lam) + (1.0 - self.alpha**2 + self.beta)
        return wm, wc

    def points(
        self, mean: torch.Tensor, cov: torch.Tensor, config: CholeskyConfig = DEFAULT_CHOLESKY
    ) -> torch.Tensor:
        """mean (B, n), cov (B, n, n) → sigma points (B, 2n + 1, n)."""
        n = mean.shape[-1]
        chol = safe_cholesky((n + self.lambda_(n)) * cov, config, "UKF covariance")
        cols = chol.transpose(-1, -2)  # row k = k-th column of L
        centre = mean.unsqueeze(-2)
        return torch.cat([centre, centre + cols, centre - cols], dim=-2)


def standard_normal(
    shape: tuple[int, ...],
    generator: torch.Generator,
    dtype: torch.dtype = torch.float32,
    device: torch.device | str | None = None,
) -> torch.Tensor:
    """N(0, I) draws of `shape` from an explicit generator (on the generator's device)."""
    return torch.randn(shape, generator=generator, dtype=dtype, device=device or generator.device)


def monte_carlo_points(
    mean: torch.Tensor,
    cov: torch.Tensor,
    eps: torch.Tensor,
    moment_matched: bool = True,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """Reparameterised Monte-Carlo sigma points χ = μ + L ε (paper eq. 7).

    mean (B, D), cov (B, D, D), eps (B, C, D) standard-normal draws → (B, C, D). With
    `moment_matched` the draws are first standardised (`moment_match_noise`) so the points'
    sample mean and 1/C covariance equal (μ, Σ) exactly.
    """
    if moment_matched:
        eps = moment_match_noise(eps)
    return sample_gaussian(mean, safe_cholesky(cov, config, "belief covariance"), eps)
