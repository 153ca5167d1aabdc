"""Shared machinery of the differentiable filters: config, noise, checks, Monte-Carlo prediction.

State s = (ψ, φ̃) ∈ R^D, D = pose_dim + param_dim: pose (x, y, θ) in m, m, rad (θ unwrapped)
followed by the normalised parameters. Beliefs are Gaussians: mean (B, D), cov (B, D, D).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
from pydantic import field_validator, model_validator
from torch import nn

from pushtoknow.common.frozen_config import Config
from pushtoknow.filters.constraints import StateConstraint
from pushtoknow.filters.gaussian import (
    CholeskyConfig,
    CovarianceError,
    antithetic_noise,
    moment_match_noise,
    safe_cholesky,
    sample_gaussian,
    weighted_covariance,
)
from pushtoknow.filters.interfaces import DynamicsModel, ObservationModel, ObservationNoiseModel
from pushtoknow.filters.sigma_points import MerweScaledSigmaPoints
from pushtoknow.filters.tensor_shapes import expect_floating, expect_shape


class FilterConfig(Config):
    """Configuration shared by the dual and joint filters.

    pose_dim, param_dim: sizes of ψ and φ̃; pose_angle_indices: angle components of ψ.
    num_sigma_points: C Monte-Carlo sigma points (100 at inference, docs/DESIGN.md §6).
    antithetic_noise: use the first C/2 draws of each step and their negatives (odd sample
      moments vanish: no skew error in the importance-weighted update). Needs C ≥ 2n.
    moment_matched_noise: then standardise the draws to exactly zero mean and identity 1/C
      covariance (no Monte-Carlo error in the propagated first two moments). Needs C > n
      (C ≥ 2n with antithetic pairs). n = D + pose_dim in the prediction (state and process
      noise are standardised jointly), param_dim in the dual update; where C is too small
      the step is skipped (`BeliefFilter.prepare_noise`).
    liu_west_h: kernel bandwidth h (a = √(1 - h²)), the paper's 0.01.
    ess_min_fraction, max_tempering_stages: effective-sample-size guard of the dual update
      (see `DualFilter`); max_tempering_stages = 1 switches the guard off.
    param_weighting: "marginal" (default, pose integrated out) or "joint_samples" (the paper's
      literal): the dual filter's parameter weights, see `DualFilter`.
    cross_covariance: "updated" (default) or "kept" (the paper's literal form): the dual filter's
      joint reassembly, see `DualFilter`.
    sigma_points: Merwe parameters of the UKF updates. cholesky: jitter schedule.
    """

    pose_dim: int = 3
    param_dim: int = 5
    pose_angle_indices: tuple[int, ...] = (2,)
    num_sigma_points: int = 100
    antithetic_noise: bool = True
    moment_matched_noise: bool = True
    liu_west_h: float = 0.01
    ess_min_fraction: float = 0.5
    max_tempering_stages: int = 3
    param_weighting: Literal["marginal", "joint_samples"] = "marginal"
    cross_covariance: Literal["updated", "kept"] = "updated"
    sigma_points: MerweScaledSigmaPoints = MerweScaledSigmaPoints()
    cholesky: CholeskyConfig = CholeskyConfig()

    @field_validator("liu_west_h")
    @classmethod
    def _h_in_unit_interval(cls, v: float) -> float:
        if not 0.0 < v < 1.0:
            raise ValueError(f"liu_west_h must be in (0, 1), got {v}")
        return v

    @field_validator("ess_min_fraction")
    @classmethod
    def _fraction(cls, v: float) -> float:
        if not 0.0 < v <= 1.0:
            raise ValueError(f"ess_min_fraction must be in (0, 1], got {v}")
        return v

    @field_validator("max_tempering_stages", "num_sigma_points", "pose_dim")
    @classmethod
    def _positive(cls, v: int) -> int:
        if v < 1:
            raise ValueError(f"must be ≥ 1, got {v}")
        return v

    @model_validator(mode="after")
    def _angles_in_pose(self) -> FilterConfig:
        bad = [i for i in self.pose_angle_indices if not 0 <= i < self.pose_dim]
        if bad:
            raise ValueError(
                f"pose_angle_indices {bad} outside the pose (pose_dim={self.pose_dim})"
            )
        return self

    @property
    def state_dim(self) -> int:
        return self.pose_dim + self.param_dim


@dataclass(frozen=True)
class FilterNoise:
    """Pre-drawn standard-normal noise for one filter step (makes a step deterministic).

    predict (B, C, D): prior sigma points; process (B, C, P): process noise;
    update (S, B, C, D) or None: the dual update's draws in each of its S tempering stages
    (the default marginal weighting uses only the parameter components [..., P:]; the joint
    filter needs none).
    """

    predict: torch.Tensor
    process: torch.Tensor
    update: torch.Tensor | None = None


@dataclass(frozen=True)
class UpdateInfo:
    """Diagnostics of one update.

    weights (B, C): final normalised parameter weights (dual; None for the joint filter);
    ess (B,): their effective sample size; stages (B,): tempering stages with a positive
    exponent; skipped (B,) bool: update skipped because the observation was not finite.
    """

    weights: torch.Tensor | None
    ess: torch.Tensor | None
    stages: torch.Tensor | None
    skipped: torch.Tensor


class BeliefFilter(nn.Module):
    """Base of the Gaussian-belief filters: holds the models and implements the shared
    constrained Monte-Carlo prediction (docs/DESIGN.md §6 steps 1–2). Subclasses implement
    `update`."""

    uses_update_noise: bool = True  # whether `update` draws random numbers

    def __init__(
        self,
        dynamics: DynamicsModel,
        observation: ObservationModel,
        observation_noise: ObservationNoiseModel,
        config: FilterConfig = FilterConfig(),
        constraint: StateConstraint | None = None,
    ):
        super().__init__()
        self.dynamics = dynamics
        self.observation = observation
        self.observation_noise = observation_noise
        self.config = config
        self.constraint = constraint
        if observation_noise.obs_dim != observation.obs_dim:
            raise ValueError(
                f"observation model has obs_dim={observation.obs_dim} but the noise model "
                f"has obs_dim={observation_noise.obs_dim}"
            )

    # -- checks ---------------------------------------------------------------------------
    def _check_belief(self, mean: torch.Tensor, cov: torch.Tensor) -> int:
        d = self.config.state_dim
        expect_shape(mean, "mean", [("B", None), ("D", d)])
        b = mean.shape[0]
        expect_shape(cov, "cov", [("B", b), ("D", d), ("D", d)])
        expect_floating(mean, "mean")
        expect_floating(cov, "cov", like=mean)
        return b

    def _check_context(self, context: object, batch: int) -> None:
        validate = getattr(context, "validate", None)
        if callable(validate):
            validate(batch)

    def model_input(self, states: torch.Tensor, context: object) -> torch.Tensor:
        """States as the models may see them: invalid ones projected (docs/DESIGN.md §6 step 1)."""
        if self.constraint is None:
            return states
        return self.constraint.project(states, context)

    # -- noise ----------------------------------------------------------------------------
    def prepare_noise(self, eps: torch.Tensor) -> torch.Tensor:
        """Variance reduction of standard-normal draws (..., C, n) per the config.

        Antithetic pairs are used only if C ≥ 2n and whitening only if the draws then span
        all n dimensions (C/2 ≥ n with pairs, C > n without); otherwise the draws are only
        centred, so small C never yields a rank-deficient whitening.
        """
        c, n = eps.shape[-2], eps.shape[-1]
        antithetic = self.config.antithetic_noise and c // 2 >= n
        if antithetic:
            eps = antithetic_noise(eps)
        if self.config.moment_matched_noise:
            if antithetic or c > n:
                eps = moment_match_noise(eps)
            else:
                eps = eps - eps.mean(dim=-2, keepdim=True)
        return eps

    def draw_noise(
        self,
        batch: int,
        generator: torch.Generator,
        dtype: torch.dtype = torch.float32,
        device: torch.device | str | None = None,
        num_sigma_points: int | None = None,
    ) -> FilterNoise:
        """Standard-normal draws for one step from an explicit generator."""
        c = num_sigma_points or self.config.num_sigma_points
        d, p, s = self.config.state_dim, self.config.pose_dim, self.config.max_tempering_stages
        device = device if device is not None else generator.device

        def randn(*shape: int) -> torch.Tensor:
            return torch.randn(shape, generator=generator, dtype=dtype, device=device)

        update = randn(s, batch, c, d) if self.uses_update_noise else None
        return FilterNoise(randn(batch, c, d), randn(batch, c, p), update)

    def _resolve_noise(
        self,
        noise: FilterNoise | None,
        generator: torch.Generator | None,
        batch: int,
        like: torch.Tensor,
    ) -> FilterNoise:
        if noise is None:
            if generator is None:
                raise ValueError(
                    "pass pre-drawn noise= (FilterNoise) or an explicit generator= "
                    "(torch.Generator): every random draw is explicit"
                )
            noise = self.draw_noise(batch, generator, like.dtype, like.device)
        d, p = self.config.state_dim, self.config.pose_dim
        expect_shape(noise.predict, "noise.predict", [("B", batch), ("C", None), ("D", d)])
        c = noise.predict.shape[1]
        if c <= d:
            raise ValueError(
                f"{c} sigma points cannot represent a {d}-D covariance: need C > D = {d}"
            )
        expect_shape(noise.process, "noise.process", [("B", batch), ("C", c), ("P", p)])
        if noise.update is not None:
            expect_shape(
                noise.update, "noise.update", [("S", None), ("B", batch), ("C", None), ("D", d)]
            )
        return noise

    # -- prediction -----------------------------------------------------------------------
    def predict(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        context: object,
        noise: FilterNoise | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Predicted belief (mean (B, D), cov (B, D, D)) after one step (docs/DESIGN.md §6 steps
        1–2).

        χ = μ + L ε; the dynamics sees project(χ); χ̄_ψ = χ_ψ + Δψ + √q ε'; χ̄_φ = χ_φ (original
        values, retained even when invalid); moments with weights 1/C.
        """
        b = self._check_belief(mean, cov)
        self._check_context(context, b)
        noise = self._resolve_noise(noise, generator, b, mean)
        p = self.config.pose_dim
        eps, eps_q = noise.predict.to(mean.dtype), noise.process.to(mean.dtype)
        joint = self.prepare_noise(torch.cat([eps, eps_q], dim=-1))
        eps, eps_q = joint[..., : eps.shape[-1]], joint[..., eps.shape[-1] :]
        chol = safe_cholesky(cov, self.config.cholesky, "belief covariance")
        points = sample_gaussian(mean, chol, eps)
        delta, q_diag = self.dynamics(self.model_input(points, context), context)
        c = points.shape[1]
        expect_shape(delta, "dynamics delta_pose", [("B", b), ("C", c), ("P", p)])
        expect_shape(q_diag, "dynamics q_diag", [("B", b), ("C", c), ("P", p)])
        positive = q_diag > 0
        std = torch.where(positive, torch.sqrt(torch.where(positive, q_diag, 1.0)), 0.0)
        pose = points[..., :p] + delta + std * eps_q
        predicted = torch.cat([pose, points[..., p:]], dim=-1)
        pred_mean = predicted.mean(dim=1)
        pred_cov = weighted_covariance(predicted, None, pred_mean)
        finite = torch.isfinite(pred_mean).all(-1) & torch.isfinite(pred_cov).flatten(1).all(-1)
        if not bool(finite.all()):
            bad = torch.nonzero(~finite).flatten().tolist()
            raise CovarianceError(
                f"predicted belief is not finite at batch index {bad[:10]}: the dynamics model "
                "returned non-finite values"
            )
        return pred_mean, pred_cov

    def update(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        observation: torch.Tensor,
        context: object,
        noise: FilterNoise | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, UpdateInfo]:
        raise NotImplementedError

    def forward(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        observation: torch.Tensor,
        context: object,
        noise: FilterNoise | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, UpdateInfo]:
        """One filter step: predict, then update with observation z (B, M)."""
        b = self._check_belief(mean, cov)
        noise = self._resolve_noise(noise, generator, b, mean)
        pred_mean, pred_cov = self.predict(mean, cov, context, noise)
        return self.update(pred_mean, pred_cov, observation, context, noise)

    # -- helpers for updates --------------------------------------------------------------
    def _observation_and_noise(
        self, observation: torch.Tensor, context: object, like: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(z with non-finite rows zeroed (B, M), valid (B,) bool, r_diag (B, M))."""
        b, m = like.shape[0], self.observation.obs_dim
        expect_shape(observation, "observation z", [("B", b), ("M", m)])
        expect_floating(observation, "observation z", like=like)
        valid = torch.isfinite(observation).all(-1)
        z = torch.where(valid.unsqueeze(-1), observation, torch.zeros_like(observation))
        r_diag = self.observation_noise(z, context)
        expect_shape(r_diag, "observation noise r_diag", [("B", b), ("M", m)])
        return z, valid, r_diag

    def _predict_observations(self, states: torch.Tensor, context: object) -> torch.Tensor:
        b, c = states.shape[:2]
        out = self.observation(self.model_input(states, context), context)
        expect_shape(
            out, "observation model output", [("B", b), ("C", c), ("M", self.observation.obs_dim)]
        )
        return out
