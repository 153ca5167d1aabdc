"""Information scores of a predicted belief against the current one (pure functions).

Beliefs are batched Gaussians: mean (B, D), cov (B, D, D). `dims` restricts a score to a
sub-block of the state (a slice or index sequence, e.g. `slice(pose_dim, None)` for the
parameters). The matrix algebra runs in float64 on symmetrised covariances factorised with
`safe_cholesky` (relative jitter where needed); results come back in the input dtype.
"""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch.distributions import MultivariateNormal, kl_divergence

from pushtoknow.filters.gaussian import DEFAULT_CHOLESKY, CholeskyConfig, safe_cholesky
from pushtoknow.filters.tensor_shapes import expect_shape

Dims = slice | Sequence[int] | None
"""A sub-block of the state: a slice, a sequence of indices, or None (the whole state)."""

WORK_DTYPE = torch.float64  # the scores' linear algebra: 8×8 matrices, precision is free


def _index(dims: Dims, d: int, device: torch.device) -> torch.Tensor:
    """Indices (K,) of `dims` in a D-dimensional state."""
    if dims is None:
        return torch.arange(d, device=device)
    if isinstance(dims, slice):
        return torch.arange(d, device=device)[dims]
    return torch.as_tensor(list(dims), dtype=torch.long, device=device)


def select_block(
    mean: torch.Tensor | None, cov: torch.Tensor, dims: Dims
) -> tuple[torch.Tensor | None, torch.Tensor]:
    """The marginal of `dims`: mean (B, D) → (B, K) (or None), cov (B, D, D) → (B, K, K)."""
    idx = _index(dims, cov.shape[-1], cov.device)
    if idx.numel() == 0:
        raise ValueError(f"dims {dims!r} selects no component of a {cov.shape[-1]}-D state")
    block = cov.index_select(-1, idx).index_select(-2, idx)
    return (None if mean is None else mean.index_select(-1, idx)), block


def _gaussian(mean: torch.Tensor, cov: torch.Tensor, config: CholeskyConfig, name: str):
    chol = safe_cholesky(cov.to(WORK_DTYPE), config, name)
    return MultivariateNormal(mean.to(WORK_DTYPE), scale_tril=chol, validate_args=False)


def kl_information_gain(
    mean_n: torch.Tensor,
    cov_n: torch.Tensor,
    mean_0: torch.Tensor,
    cov_0: torch.Tensor,
    dims: Dims = None,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """IG_N = KL( N(μ_N, Σ_N) ‖ N(μ_0, Σ_0) ) (B,) in nats (paper eq. 17, docs/DESIGN.md §7).

    mean_n, mean_0 (B, D); cov_n, cov_0 (B, D, D): the belief after N prediction steps and
    the current one. dims: score only that marginal block (K of the D components). Closed
    form (`torch.distributions.kl_divergence` of two `MultivariateNormal`s):
    ½ [tr(Σ_0⁻¹ Σ_N) + (μ_0 - μ_N)ᵀ Σ_0⁻¹ (μ_0 - μ_N) - K + ln det Σ_0 - ln det Σ_N].
    Angles are compared unwrapped, as the filters carry them.
    """
    expect_shape(mean_n, "mean_n", [("B", None), ("D", None)])
    b, d = mean_n.shape
    expect_shape(mean_0, "mean_0", [("B", b), ("D", d)])
    expect_shape(cov_n, "cov_n", [("B", b), ("D", d), ("D", d)])
    expect_shape(cov_0, "cov_0", [("B", b), ("D", d), ("D", d)])
    mean_n, cov_n = select_block(mean_n, cov_n, dims)
    mean_0, cov_0 = select_block(mean_0, cov_0, dims)
    p = _gaussian(mean_n, cov_n, config, "predicted covariance Σ_N")
    q = _gaussian(mean_0, cov_0, config, "current covariance Σ_0")
    return kl_divergence(p, q).to(mean_n.dtype)


def log_det(cov: torch.Tensor, config: CholeskyConfig = DEFAULT_CHOLESKY) -> torch.Tensor:
    """ln det Σ (...,) of covariances (..., K, K), from a (jittered) Cholesky factor, float64."""
    chol = safe_cholesky(cov.to(WORK_DTYPE), config, "covariance")
    return 2.0 * torch.log(torch.diagonal(chol, dim1=-2, dim2=-1)).sum(-1)


def entropy_reduction(
    cov_0: torch.Tensor,
    cov_n: torch.Tensor,
    dims: Dims = None,
    config: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """H(N(·, Σ_0)) - H(N(·, Σ_N)) = ½ ln det Σ_0 - ½ ln det Σ_N (B,) in nats on block `dims`.

    cov_0, cov_N (B, D, D). Positive when Σ_N is tighter than Σ_0 (the means do not enter).
    """
    expect_shape(cov_0, "cov_0", [("B", None), ("D", None), ("D", None)])
    b, d = cov_0.shape[:2]
    expect_shape(cov_n, "cov_n", [("B", b), ("D", d), ("D", d)])
    _, block_0 = select_block(None, cov_0, dims)
    _, block_n = select_block(None, cov_n, dims)
    return (0.5 * (log_det(block_0, config) - log_det(block_n, config))).to(cov_0.dtype)
