"""Importance-weighted parameter update (Liu & West 2001) with an effective-sample-size guard.

Pure functions on batched tensors: log-likelihoods (B, C) of C particles for B objects.
"""

from __future__ import annotations

import math

import torch

from pushtoknow.filters.gaussian import weighted_covariance, weighted_mean

_GRID = 48  # log-spaced grid points bracketing the tempering exponent
_GRID_DECADES = 12.0  # the grid spans remaining · [1e-12, 1]
_NEWTON_STEPS = 6  # safeguarded Newton refinements of the bracketed root (float64)
_MIN_SLOPE = 1e-12  # |d log ESS / dβ| below this: β is treated as locally constant


def sanitise_log_likelihood(loglik: torch.Tensor) -> torch.Tensor:
    """Shift each row of loglik (B, C) so its max is 0 and replace non-finite values by a very
    small finite log-likelihood (those particles get zero weight). Weights are unchanged."""
    big = torch.finfo(loglik.dtype).max / 4
    finite = torch.isfinite(loglik)
    safe = torch.where(finite, loglik, torch.full_like(loglik, -big))
    shifted = safe - safe.amax(-1, keepdim=True).detach()
    return shifted.clamp_min(-big)


def log_weights(loglik: torch.Tensor, exponent: torch.Tensor) -> torch.Tensor:
    """Normalised log-weights (B, C) of prior-uniform particles tempered by exponent (B,)."""
    return torch.log_softmax(exponent.unsqueeze(-1) * loglik, dim=-1)


def effective_sample_size(log_w: torch.Tensor) -> torch.Tensor:
    """ESS = 1 / Σ w² (B,) from normalised log-weights (B, C); between 1 and C."""
    return torch.exp(-torch.logsumexp(2.0 * log_w, dim=-1))


def _log_ess(loglik: torch.Tensor, beta: torch.Tensor) -> torch.Tensor:
    x = beta.unsqueeze(-1) * loglik
    return 2.0 * torch.logsumexp(x, -1) - torch.logsumexp(2.0 * x, -1)


def _log_ess_slope(loglik: torch.Tensor, beta: torch.Tensor) -> torch.Tensor:
    """d log ESS / dβ = 2 Σ w ℓ - 2 Σ u ℓ ≤ 0, w = softmax(βℓ), u = softmax(2βℓ)."""
    x = beta.unsqueeze(-1) * loglik
    w = torch.softmax(x, -1)
    u = torch.softmax(2.0 * x, -1)
    return 2.0 * ((w - u) * loglik).sum(-1)


def tempering_exponent(
    loglik: torch.Tensor, remaining: torch.Tensor, ess_target: float
) -> torch.Tensor:
    """Largest exponent β ∈ [0, remaining] (B,) with ESS(w ∝ exp(β ℓ)) ≥ ess_target.

    ESS(β) is non-increasing in β. β = remaining where the full remaining likelihood keeps
    ESS ≥ ess_target; otherwise the root of log ESS(β) = log ess_target, bracketed on a grid of
    log-spaced exponents and refined by safeguarded Newton steps on detached float64 values,
    then made differentiable by one Newton step with the attached log-likelihood
    (implicit-function gradient dβ/dℓ = -(∂ log ESS / ∂ℓ) / (∂ log ESS / ∂β)).
    """
    ll = loglik.detach().double()
    rem = remaining.detach().double()
    log_target = math.log(float(ess_target))
    full_ok = _log_ess(ll, rem) >= log_target
    if bool(full_ok.all()):
        return remaining
    # bracket on a log-spaced grid rem · 10^[-_GRID_DECADES, 0] (plus 0), then Newton from a
    # log-linear interpolation inside the bracket, safeguarded by bisection
    frac = torch.logspace(-_GRID_DECADES, 0.0, _GRID, dtype=ll.dtype, device=ll.device)
    frac = torch.cat([frac.new_zeros(1), frac])
    betas = rem.unsqueeze(-1) * frac  # (B, G+1)
    x = betas.unsqueeze(-1) * ll.unsqueeze(-2)  # (B, G+1, C)
    log_ess = 2.0 * torch.logsumexp(x, -1) - torch.logsumexp(2.0 * x, -1)
    k = ((log_ess >= log_target).sum(-1) - 1).clamp(0, _GRID - 1)  # last grid index above
    lo = torch.gather(betas, -1, k.unsqueeze(-1)).squeeze(-1)
    hi = torch.gather(betas, -1, (k + 1).unsqueeze(-1)).squeeze(-1)
    g_lo = torch.gather(log_ess, -1, k.unsqueeze(-1)).squeeze(-1) - log_target
    g_hi = torch.gather(log_ess, -1, (k + 1).unsqueeze(-1)).squeeze(-1) - log_target
    # Newton in u = log β (log ESS is closer to linear in log β), safeguarded by the bracket
    tiny = torch.finfo(ll.dtype).tiny
    lo = lo.clamp_min(tiny * 1e3)
    u_lo, u_hi = lo.log(), hi.log()
    t = (g_lo / (g_lo - g_hi).clamp_min(1e-300)).clamp(0.0, 1.0)
    u = u_lo + t * (u_hi - u_lo)
    for _ in range(_NEWTON_STEPS):
        beta = u.exp()
        g = _log_ess(ll, beta) - log_target
        slope = beta * _log_ess_slope(ll, beta)  # dg/du
        u_lo = torch.where(g >= 0, u, u_lo)
        u_hi = torch.where(g >= 0, u_hi, u)
        step = u - g / torch.where(slope < 0, slope, -torch.ones_like(slope))
        inside = (step >= u_lo) & (step <= u_hi) & (slope < 0)
        u = torch.where(inside, step, 0.5 * (u_lo + u_hi))
    beta = u.exp()
    slope = _log_ess_slope(ll, beta)
    usable = slope < -_MIN_SLOPE
    slope = torch.where(usable, slope, -torch.ones_like(slope)).to(loglik.dtype)
    beta_s = beta.to(loglik.dtype)
    g = _log_ess(loglik, beta_s) - log_target
    newton = torch.where(usable, beta_s - g / slope, beta_s)
    interior = torch.minimum(newton.clamp(min=0.0), remaining)
    return torch.where(full_ok, remaining, interior)


def liu_west_moments(
    particles: torch.Tensor, weights: torch.Tensor, h: float
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Liu–West kernel-shrinkage posterior of parameters, moment-matched to one Gaussian.

    particles (B, C, K), weights (B, C) summing to 1, h ∈ (0, 1) kernel bandwidth, a = √(1 - h²).
    μ = Σ w_j χ_j; V = Σ w_j (χ_j - μ)(χ_j - μ)ᵀ; kernel locations m_j = a χ_j + (1 - a) μ;
    Σ = Σ w_j (m_j - μ)(m_j - μ)ᵀ + h² V (docs/DESIGN.md §6 step 4). Since m_j - μ = a (χ_j - μ), Σ
    = V: the shrinkage preserves the first two moments, as Liu & West designed it.
    Returns mean (B, K), cov (B, K, K), kernel locations (B, C, K).
    """
    a = (1.0 - h * h) ** 0.5
    mean = weighted_mean(particles, weights)
    v = weighted_covariance(particles, weights, mean)
    locations = a * particles + (1.0 - a) * mean.unsqueeze(-2)
    cov = weighted_covariance(locations, weights, mean) + (h * h) * v
    return mean, cov, locations
