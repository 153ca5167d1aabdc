"""Unscented Kalman update of a Gaussian over any (sub-)state with any observation function."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass

import torch

from pushtoknow.filters.gaussian import (
    DEFAULT_CHOLESKY,
    CholeskyConfig,
    circular_weighted_mean,
    safe_cholesky,
    symmetrize,
    wrap_residual,
)
from pushtoknow.filters.sigma_points import MerweScaledSigmaPoints
from pushtoknow.filters.tensor_shapes import expect_shape

ObservationFn = Callable[[torch.Tensor], torch.Tensor]
"""Maps sigma points (B, S, N) to predicted observations (B, S, M)."""


@dataclass(frozen=True)
class UKFUpdateResult:
    """Posterior and by-products of one UKF update (shapes for state N, observation M).

    mean (B, N), cov (B, N, N); predicted_obs (B, M) and innovation_cov S (B, M, M) including R;
    gain K (B, N, M); innovation y = z - ẑ (B, M), angle components wrapped.
    """

    mean: torch.Tensor
    cov: torch.Tensor
    predicted_obs: torch.Tensor
    innovation_cov: torch.Tensor
    gain: torch.Tensor
    innovation: torch.Tensor


def _as_matrix(noise: torch.Tensor) -> torch.Tensor:
    if noise.ndim == 2:
        return torch.diag_embed(noise)
    return noise


def ukf_update(
    mean: torch.Tensor,
    cov: torch.Tensor,
    observation: torch.Tensor,
    observe: ObservationFn,
    noise: torch.Tensor,
    sigma_points: MerweScaledSigmaPoints = MerweScaledSigmaPoints(),
    state_angle_indices: Sequence[int] = (),
    obs_angle_indices: Sequence[int] = (),
    cholesky: CholeskyConfig = DEFAULT_CHOLESKY,
) -> UKFUpdateResult:
    """Standard UKF measurement update (Merwe scaled sigma points), batched.

    mean (B, N), cov (B, N, N) prior; observation z (B, M); observe: (B, S, N) → (B, S, M);
    noise R diagonal (B, M) or full (B, M, M). Angle components (state and observation) are
    averaged circularly and their residuals wrapped to (-π, π]. The angle components of the
    posterior mean are not wrapped (θ stays unwrapped along a trajectory).
    Posterior: x⁺ = x + K y, P⁺ = P - K S Kᵀ (filterpy's form), symmetrised.
    """
    b, n = mean.shape
    expect_shape(cov, "cov", [("B", b), ("N", n), ("N", n)])
    m = observation.shape[-1]
    expect_shape(observation, "observation", [("B", b), ("M", m)])
    if noise.ndim == 2:
        expect_shape(noise, "noise (diagonal R)", [("B", b), ("M", m)])
    else:
        expect_shape(noise, "noise R", [("B", b), ("M", m), ("M", m)])
    wm, wc = sigma_points.weights(n, mean.dtype, mean.device)
    points = sigma_points.points(mean, cov, cholesky)  # (B, 2n+1, n)
    z_points = observe(points)
    expect_shape(z_points, "observe(points)", [("B", b), ("S", points.shape[1]), ("M", m)])
    wm_b = wm.expand(b, -1)
    z_mean = circular_weighted_mean(z_points, wm_b, obs_angle_indices)
    dz = wrap_residual(z_points - z_mean.unsqueeze(-2), obs_angle_indices)
    dx = wrap_residual(points - mean.unsqueeze(-2), state_angle_indices)
    dz_w = (dz * wc.unsqueeze(-1)).transpose(-1, -2)  # (B, M, S)
    s = symmetrize(dz_w @ dz + _as_matrix(noise))
    pxz = (dx * wc.unsqueeze(-1)).transpose(-1, -2) @ dz
    chol_s = safe_cholesky(s, cholesky, "innovation covariance S")
    gain = torch.cholesky_solve(pxz.transpose(-1, -2), chol_s).transpose(-1, -2)  # Pxz S⁻¹
    innovation = wrap_residual(observation - z_mean, obs_angle_indices)
    post_mean = mean + (gain @ innovation.unsqueeze(-1)).squeeze(-1)
    post_cov = symmetrize(cov - gain @ s @ gain.transpose(-1, -2))
    return UKFUpdateResult(post_mean, post_cov, z_mean, s, gain, innovation)
