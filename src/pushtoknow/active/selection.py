"""N-step look-ahead scores of M candidate pushes, all evaluated as one batch (docs/DESIGN.md §7).

From the current belief N(μ_0, Σ_0) (one object), each candidate's belief is rolled forward
N steps with the filter's prediction step under that candidate's context. Two scores:

* "kl" (docs/DESIGN.md §7 / paper eq. 17, policy "active-kl"): prediction only, no updates;
  IG_N = KL( N(μ_N, Σ_N) ‖ N(μ_0, Σ_0) ) over the whole state. The prediction leaves the
  parameter marginal unchanged (χ̄_φ = χ_φ), so this rewards pushes whose predicted pose moves
  and spreads most.
* "entropy" (ours, policy "active-entropy"): after each prediction, the covariance of the
  expected Kalman-type update with the observation model (value-independent, so no
  observation is simulated): Merwe sigma points χ of the predicted N(μ̄, Σ̄), Z = h(χ) (angle
  components averaged circularly and wrapped), R = R(ẑ) at their mean ẑ,
  P_zz = Cov(Z) + R, P_xz = Cov(χ, Z), Σ⁺ = Σ̄ - P_xz P_zz⁻¹ P_xzᵀ; the mean stays μ̄. Score
  = ½ ln det Σ_0,φφ - ½ ln det Σ_N,φφ on the parameter block: the expected reduction of the
  parameters' entropy, i.e. the information the pose and force observations along the push
  would carry about them.

All candidates share the same noise draws (common random numbers): their scores differ only by
their contexts, and scoring them one by one with the same generator gives the same numbers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Literal

import torch

from pushtoknow.active.scores import WORK_DTYPE, entropy_reduction, kl_information_gain
from pushtoknow.common.errors import ShapeError
from pushtoknow.filters.base import BeliefFilter, FilterNoise
from pushtoknow.filters.gaussian import (
    CovarianceError,
    circular_weighted_mean,
    safe_cholesky,
    symmetrize,
    wrap_residual,
)
from pushtoknow.filters.tensor_shapes import expect_shape

ScoreName = Literal["kl", "entropy"]
SCORES: tuple[str, ...] = ("kl", "entropy")

ContextAt = Callable[[int], object]
"""k ↦ the filter context of look-ahead step k (0 ≤ k < N), batched over the M candidates."""


def draw_common_noise(
    filt: BeliefFilter,
    n_steps: int,
    generator: torch.Generator,
    dtype: torch.dtype,
    device: torch.device | str | None = None,
    num_sigma_points: int | None = None,
) -> list[FilterNoise]:
    """Prediction noise of one object for each of N steps: predict (1, C, D), process (1, C, P)
    standard-normal draws (no update noise). Drawn in step order from `generator`."""
    c = num_sigma_points or filt.config.num_sigma_points
    d, p = filt.config.state_dim, filt.config.pose_dim
    device = device if device is not None else generator.device
    out = []
    for _ in range(n_steps):
        eps = torch.randn((1, c, d), generator=generator, dtype=dtype, device=device)
        eps_q = torch.randn((1, c, p), generator=generator, dtype=dtype, device=device)
        out.append(FilterNoise(eps, eps_q, None))
    return out


def expected_update_covariance(
    filt: BeliefFilter, mean: torch.Tensor, cov: torch.Tensor, context: object
) -> torch.Tensor:
    """Σ⁺ (B, D, D) = Σ̄ - P_xz P_zz⁻¹ P_xzᵀ of a Kalman-type update of N(mean (B, D), cov
    (B, D, D)) with the filter's observation model and noise (see the module docstring).

    Merwe points per `filt.config.sigma_points` (2D + 1 per object); the models see the
    constraint-projected points (`filt.model_input`). The deviations of the points from the
    mean are their exact ± Cholesky columns (never wrapped); observation angles are wrapped.
    The algebra runs in float64 through a (jittered) Cholesky factor of P_zz; returns cov's
    dtype, symmetrised.
    """
    cfg = filt.config
    b, d = mean.shape
    points = cfg.sigma_points.points(mean, cov, cfg.cholesky)  # (B, S, D)
    wm, wc = cfg.sigma_points.weights(d, mean.dtype, mean.device)
    z = filt.observation(filt.model_input(points, context), context)
    m = filt.observation.obs_dim
    expect_shape(z, "observation model output", [("B", b), ("S", points.shape[1]), ("M", m)])
    angles = filt.observation.angle_indices
    z_mean = circular_weighted_mean(z, wm.expand(b, -1), angles)
    r_diag = filt.observation_noise(z_mean, context)
    expect_shape(r_diag, "observation noise r_diag", [("B", b), ("M", m)])
    dz = wrap_residual(z - z_mean.unsqueeze(-2), angles).to(WORK_DTYPE)
    dx = (points - mean.unsqueeze(-2)).to(WORK_DTYPE)
    w = wc.to(WORK_DTYPE).unsqueeze(-1)
    p_zz = symmetrize((dz * w).mT @ dz + torch.diag_embed(r_diag.to(WORK_DTYPE)))
    p_xz = (dx * w).mT @ dz  # (B, D, M)
    chol = safe_cholesky(p_zz, cfg.cholesky, "expected innovation covariance P_zz")
    white = torch.linalg.solve_triangular(chol, p_xz.mT, upper=False)  # L⁻¹ P_xzᵀ (B, M, D)
    return symmetrize(cov.to(WORK_DTYPE) - white.mT @ white).to(cov.dtype)


def _expand_noise(noise: FilterNoise, batch: int) -> FilterNoise:
    return FilterNoise(
        noise.predict.expand(batch, -1, -1), noise.process.expand(batch, -1, -1), None
    )


def score_candidates(
    filt: BeliefFilter,
    mean: torch.Tensor,
    cov: torch.Tensor,
    context_at: ContextAt,
    num_candidates: int,
    n_steps: int,
    score: ScoreName = "kl",
    generator: torch.Generator | None = None,
    num_sigma_points: int | None = None,
    noise: Sequence[FilterNoise] | None = None,
) -> torch.Tensor:
    """Scores (M,) of M candidate pushes from the belief mean (1, D), cov (1, D, D).

    The belief is expanded to batch M and predicted N = `n_steps` times with
    `context_at(k)` (the M candidates' contexts of step k, batched), with the expected
    covariance update after each prediction for "entropy" (module docstring). Higher is
    better for both scores. Randomness: `noise` (N pre-drawn `FilterNoise` of batch 1, shared
    by all candidates) or else `generator` (`draw_common_noise`, C = `num_sigma_points` or
    the filter's). Runs without autograd. Raises `CovarianceError` if a score is not
    finite (a model returned non-finite values).
    """
    if score not in SCORES:
        raise ValueError(f"unknown score {score!r}; use one of {SCORES}")
    if num_candidates < 1 or n_steps < 1:
        raise ValueError(
            f"need num_candidates ≥ 1 and n_steps ≥ 1, got {num_candidates}, {n_steps}"
        )
    d = filt.config.state_dim
    expect_shape(mean, "mean", [("1", 1), ("D", d)])
    expect_shape(cov, "cov", [("1", 1), ("D", d), ("D", d)])
    if noise is None:
        if generator is None:
            raise ValueError(
                "pass noise= or an explicit generator= (every random draw is explicit)"
            )
        noise = draw_common_noise(
            filt, n_steps, generator, mean.dtype, mean.device, num_sigma_points
        )
    if len(noise) < n_steps:
        raise ShapeError(f"noise holds {len(noise)} steps, need n_steps = {n_steps}")
    m = num_candidates
    mean_0, cov_0 = mean.expand(m, d), cov.expand(m, d, d)
    with torch.no_grad():
        mu, sigma = mean_0, cov_0
        for k in range(n_steps):
            context = context_at(k)
            mu, sigma = filt.predict(mu, sigma, context, noise=_expand_noise(noise[k], m))
            if score == "entropy":
                sigma = expected_update_covariance(filt, mu, sigma, context)
        if score == "kl":
            out = kl_information_gain(mu, sigma, mean_0, cov_0, None, filt.config.cholesky)
        else:
            params = slice(filt.config.pose_dim, None)
            out = entropy_reduction(cov_0, sigma, params, filt.config.cholesky)
    bad = ~torch.isfinite(out)
    if bool(bad.any()):
        raise CovarianceError(
            f"{score} score is not finite for candidates {torch.nonzero(bad).flatten().tolist()}"
        )
    return out
