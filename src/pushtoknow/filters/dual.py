"""Dual differentiable filter (paper §III-C, docs/DESIGN.md §6): Liu–West parameter update and
conditional UKF pose update on a joint Gaussian belief over s = (ψ, φ̃)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pushtoknow.filters.base import BeliefFilter, FilterConfig, FilterNoise, UpdateInfo
from pushtoknow.filters.constraints import StateConstraint
from pushtoknow.filters.gaussian import (
    DEFAULT_CHOLESKY,
    CholeskyConfig,
    circular_weighted_mean,
    gaussian_log_likelihood_unnormalised,
    safe_cholesky,
    sample_gaussian,
    symmetrize,
    weighted_covariance,
    weighted_cross_covariance,
    weighted_mean,
    wrap_residual,
)
from pushtoknow.filters.interfaces import (
    DynamicsModel,
    ObservationModel,
    ObservationNoiseModel,
    PoseObservation,
)
from pushtoknow.filters.liu_west import (
    effective_sample_size,
    liu_west_moments,
    log_weights,
    sanitise_log_likelihood,
    tempering_exponent,
)
from pushtoknow.filters.ukf import UKFUpdateResult, ukf_update


def regression_slope(
    inputs: torch.Tensor,
    outputs: torch.Tensor,
    obs_angle_indices: tuple[int, ...] = (),
    cholesky: CholeskyConfig = DEFAULT_CHOLESKY,
) -> torch.Tensor:
    """Statistical linear regression slope (B, M, N) of outputs (B, C, M) on inputs (B, C, N)
    over C equally weighted samples: Cov(out, in) Cov(in)⁻¹ (angle outputs wrapped)."""
    dev_in = inputs - inputs.mean(dim=1, keepdim=True)
    out_mean = circular_weighted_mean(outputs, None, obs_angle_indices)
    dev_out = wrap_residual(outputs - out_mean.unsqueeze(-2), obs_angle_indices)
    cov_in = symmetrize(weighted_cross_covariance(dev_in, dev_in))
    cross = weighted_cross_covariance(dev_in, dev_out)  # (B, N, M)
    return torch.cholesky_solve(cross, safe_cholesky(cov_in, cholesky, "sample covariance")).mT


class DualFilter(BeliefFilter):
    """VT-DDF: one step = constrained Monte-Carlo prediction, then the dual update.

    Update (docs/DESIGN.md §6 steps 3–6), predicted belief N(μ̄, Σ̄), observation z, noise R = R(z).
    G = Σ̄_ψφ Σ̄_φ⁻¹ and Σ_ψ|φ = Σ̄_ψψ - G Σ̄_φψ describe the predicted N(ψ | φ).

    * Parameters (Liu–West): C points φ_j with predicted observations Z_j, log-weights
      -½ (Z_j - z)ᵀ R_w⁻¹ (Z_j - z) (angle residuals wrapped) normalised in log space; the
      Liu–West moments of the weighted φ_j give μ_φ, Σ_φ. `config.param_weighting` chooses Z_j:
      - "marginal" (default, Rao–Blackwellised): φ_j ~ N(μ̄_φ, Σ̄_φ), Z_j = h(ψ̂_j, φ_j) at the
        conditional mean pose ψ̂_j = μ̄_ψ + G (φ_j - μ̄_φ), and R_w = R + P_zz where P_zz is the
        unscented covariance of h(ψ, μ̄_φ) over N(ψ | φ): the pose is integrated out instead of
        sampled. Exact for linear-Gaussian models.
      - "joint_samples" (the paper's literal form): χ'_j ~ N(μ̄, Σ̄), Z_j = h(χ'_j), R_w = R. The
        sampled pose puts weight noise unrelated to φ into every update: the weighted variance of φ
        shrinks by about (1 - 1/ESS) per step and its mean random-walks, so over long runs
        (10²–10⁴ steps) Σ_φ collapses (see tests/filters/test_dual.py).
      Models see project(point) (docs/DESIGN.md §6 step 1).
    * Effective-sample-size guard (progressive correction): if the weights of the full
      likelihood would have ESS < ess_min_fraction · C, only the tempered likelihood L^β is
      applied, with the largest β keeping ESS = ess_min_fraction · C; the weighted moments
      then define an intermediate Gaussian, which is resampled and weighted by the remaining
      L^(1-β), and so on. Exponents add up to 1, so the whole likelihood is used; the last of
      `max_tempering_stages` stages applies whatever exponent remains (its ESS may then be
      lower). β is differentiable (implicit-function gradient, `liu_west.tempering_exponent`).
      max_tempering_stages = 1 is the plain Liu–West update.
    * Pose: N(ψ | φ = μ_φ) (eq. 14–15), UKF update (Merwe points) with h(ψ) = h(project(ψ,
      μ_φ)) and noise R.
    * Joint posterior bel(ψ|φ) bel(φ), mean (μ_ψ|φ⁺, μ_φ), covariance per
      `config.cross_covariance`:
      - "kept" (docs/DESIGN.md §6 step 6 / paper, literally): Σ = [[Σ_ψ|φ⁺ + C Σ_φ⁻¹ Cᵀ, C], [Cᵀ,
        Σ_φ]] with C = Σ̄_ψφ. PSD, but as Σ_φ shrinks the pose variance C Σ_φ⁻¹ Cᵀ grows and the
        ψ–φ correlation tends to ±1; with a precise pose observation that feeds back into
        a collapse of Σ_φ and a diverging pose variance (see tests/filters/test_dual.py).
      - "updated" (default): bel(ψ|φ) keeps its linear dependence on φ through the update,
        E[ψ | φ, z] = μ_ψ|φ⁺ + G⁺ (φ - μ_φ) with G⁺ = G - K D, K the UKF gain and D the total
        slope d h(ψ̂(φ), φ) / dφ (statistical linear regression over the stage-0 points); then
        Σ = [[Σ_ψ|φ⁺ + G⁺ Σ_φ G⁺ᵀ, G⁺ Σ_φ], [Σ_φ G⁺ᵀ, Σ_φ]]. Also PSD by construction (its
        Schur complement is Σ_ψ|φ⁺); exact for linear-Gaussian models up to the Monte-Carlo
        error of the parameter weights.

    An object whose observation has a non-finite entry keeps its predicted belief
    (`UpdateInfo.skipped`); no NaN reaches the state or the gradients.
    """

    def __init__(
        self,
        dynamics: DynamicsModel,
        observation: ObservationModel,
        observation_noise: ObservationNoiseModel,
        config: FilterConfig = FilterConfig(),
        constraint: StateConstraint | None = None,
    ):
        super().__init__(dynamics, observation, observation_noise, config, constraint)

    def _unscented_points(
        self, pose_mean: torch.Tensor, pose_cov: torch.Tensor, params: torch.Tensor
    ) -> torch.Tensor:
        """Merwe points (B, 2P + 1, D) of N(ψ; pose_mean, pose_cov) with φ fixed to params."""
        pts = self.config.sigma_points.points(pose_mean, pose_cov, self.config.cholesky)
        return torch.cat([pts, params.unsqueeze(1).expand(-1, pts.shape[1], -1)], dim=-1)

    def _unscented_obs_cov(self, z_pts: torch.Tensor) -> torch.Tensor:
        """Unscented covariance P_zz (B, M, M) of the observations z_pts (B, 2P + 1, M) of
        `_unscented_points`."""
        wm, wc = self.config.sigma_points.weights(self.config.pose_dim, z_pts.dtype, z_pts.device)
        angles = self.observation.angle_indices
        z_mean = circular_weighted_mean(z_pts, wm.expand(z_pts.shape[0], -1), angles)
        dz = wrap_residual(z_pts - z_mean.unsqueeze(-2), angles)
        return symmetrize((dz * wc.unsqueeze(-1)).mT @ dz)

    def update(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        observation: torch.Tensor,
        context: object,
        noise: FilterNoise | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, UpdateInfo]:
        """Posterior (mean (B, D), cov (B, D, D), info) given the predicted belief and z (B, M):
        the stages of the class docstring, each a function of this module."""
        cfg = self.config
        b = self._check_belief(mean, cov)
        self._check_context(context, b)
        noise = self._resolve_noise(noise, generator, b, mean)
        if noise.update is None or noise.update.shape[0] < 1:
            raise ValueError("the dual update needs noise.update of shape (S ≥ 1, B, C, D)")
        p = cfg.pose_dim
        z, valid, r_diag = self._observation_and_noise(observation, context, mean)
        angles = self.observation.angle_indices

        cond = conditional_pose(cov, p, cfg)
        params = self._parameter_update(mean, cov, cond, z, valid, r_diag, context, noise)

        def observe(pose_points: torch.Tensor) -> torch.Tensor:
            fixed = params.mean.unsqueeze(1).expand(-1, pose_points.shape[1], -1)
            return self._predict_observations(torch.cat([pose_points, fixed], -1), context)

        ukf = ukf_update(
            cond.mean_given(mean, params.mean),
            cond.cov,
            z,
            observe,
            r_diag,
            cfg.sigma_points,
            cfg.pose_angle_indices,
            angles,
            cfg.cholesky,
        )
        total = None
        if cfg.cross_covariance == "updated":
            total = total_observation_slope(
                params.first_points, params.first_obs, cond.slope, p, cfg, angles
            )
        post_mean, post_cov = reassemble_joint(ukf, params, cov[:, :p, p:], cond.slope, total, cfg)
        keep = valid.view(b, 1)
        post_mean = torch.where(keep, post_mean, mean)
        post_cov = torch.where(keep.unsqueeze(-1), post_cov, cov)
        info = UpdateInfo(
            weights=params.weights, ess=params.ess, stages=params.stages, skipped=~valid
        )
        return post_mean, post_cov, info

    def _parameter_update(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        cond: ConditionalPose,
        z: torch.Tensor,
        valid: torch.Tensor,
        r_diag: torch.Tensor,
        context: object,
        noise: FilterNoise,
    ) -> ParameterPosterior:
        """Stage 1: the Liu–West parameter update with the ESS guard (class docstring) on the
        predicted belief N(mean (B, D), cov (B, D, D)), z (B, M), R = diag(r_diag) (B, M)."""
        cfg = self.config
        p = cfg.pose_dim
        b = mean.shape[0]
        marginal = cfg.param_weighting == "marginal"
        angles = self.observation.angle_indices
        pose_mean, param_mean_bar = mean[:, :p], mean[:, p:]
        if marginal:  # h over N(ψ | φ = μ̄_φ), evaluated together with the stage-0 points
            ut_states = self._unscented_points(pose_mean, cond.cov, param_mean_bar)
        weight_noise = r_diag
        stage_mean, stage_cov = (param_mean_bar, cov[:, p:, p:]) if marginal else (mean, cov)
        remaining = torch.ones(b, dtype=mean.dtype, device=mean.device)
        stages = torch.zeros(b, dtype=torch.long, device=mean.device)
        assert noise.update is not None  # checked by `update`
        num_stages = min(noise.update.shape[0], cfg.max_tempering_stages)
        for stage in range(num_stages):
            eps = noise.update[stage].to(mean.dtype)
            eps = self.prepare_noise(eps[..., p:] if marginal else eps)
            chol = safe_cholesky(stage_cov, cfg.cholesky, "tempering-stage covariance")
            drawn = sample_gaussian(stage_mean, chol, eps)  # (B, C, K) or (B, C, D)
            if marginal:
                pose_hat = pose_mean.unsqueeze(1) + (drawn - param_mean_bar.unsqueeze(1)) @ (
                    cond.slope.mT
                )
                points = torch.cat([pose_hat, drawn], dim=-1)
            else:
                points = drawn
            if stage == 0 and marginal:  # one model call (one encoding in "mean" mode)
                both = self._predict_observations(torch.cat([ut_states, points], 1), context)
                n_ut = ut_states.shape[1]
                predicted_obs = both[:, n_ut:]
                obs_cov = self._unscented_obs_cov(both[:, :n_ut])
                weight_noise = symmetrize(torch.diag_embed(r_diag) + obs_cov)
            else:
                predicted_obs = self._predict_observations(points, context)
            if stage == 0:  # samples of the predicted belief, for the linearisation of h
                first_points, first_obs = points, predicted_obs
            residual = wrap_residual(predicted_obs - z.unsqueeze(-2), angles)
            loglik = gaussian_log_likelihood_unnormalised(residual, weight_noise, cfg.cholesky)
            loglik = torch.where(valid.unsqueeze(-1), loglik, torch.zeros_like(loglik))
            loglik = sanitise_log_likelihood(loglik)
            last = stage == num_stages - 1
            if last:
                beta = remaining
            else:
                target = cfg.ess_min_fraction * points.shape[1]
                beta = tempering_exponent(loglik, remaining, target)
            log_w = log_weights(loglik, beta)
            weights = log_w.exp()
            stages = stages + (beta.detach() > 0).long()
            remaining = remaining - beta
            if last or bool((remaining.detach() <= 0).all()):
                break
            stage_mean = weighted_mean(drawn, weights)
            stage_cov = weighted_covariance(drawn, weights, stage_mean)
        param_mean, param_cov, _ = liu_west_moments(points[..., p:], weights, cfg.liu_west_h)
        return ParameterPosterior(
            param_mean,
            param_cov,
            weights,
            effective_sample_size(log_w),
            stages,
            first_points,
            first_obs,
        )


@dataclass(frozen=True)
class ConditionalPose:
    """The predicted N(ψ | φ) of a joint Gaussian over s = (ψ, φ): E[ψ | φ] = μ̄_ψ + G (φ − μ̄_φ)
    with slope G = Σ̄_ψφ Σ̄_φ⁻¹ (B, P, K), covariance Σ_ψ|φ = Σ̄_ψψ − G Σ̄_φψ (B, P, P)."""

    slope: torch.Tensor
    cov: torch.Tensor

    def mean_given(self, mean: torch.Tensor, params: torch.Tensor) -> torch.Tensor:
        """E[ψ | φ = params] (B, P) for the joint mean (B, D) and params (B, K)."""
        p = self.cov.shape[-1]
        shift = (params - mean[:, p:]).unsqueeze(1) @ self.slope.mT
        return mean[:, :p] + shift.squeeze(1)


def conditional_pose(cov: torch.Tensor, pose_dim: int, cfg: FilterConfig) -> ConditionalPose:
    """Stage 0: N(ψ | φ) of the predicted belief with covariance cov (B, D, D)."""
    p = pose_dim
    chol_phi_bar = safe_cholesky(cov[:, p:, p:], cfg.cholesky, "predicted Σ_φ")
    slope = torch.cholesky_solve(cov[:, p:, :p], chol_phi_bar).mT  # G (B, P, K)
    return ConditionalPose(slope, symmetrize(cov[:, :p, :p] - slope @ cov[:, p:, :p]))


@dataclass(frozen=True)
class ParameterPosterior:
    """Stage 1's result: the parameters' posterior mean (B, K) and cov (B, K, K), the final
    weights (B, C), ESS (B,) and stages used (B,), and the stage-0 points (B, C, D) with their
    predicted observations (B, C, M) (samples of the predicted belief, to linearise h)."""

    mean: torch.Tensor
    cov: torch.Tensor
    weights: torch.Tensor
    ess: torch.Tensor
    stages: torch.Tensor
    first_points: torch.Tensor
    first_obs: torch.Tensor


def total_observation_slope(
    points: torch.Tensor,
    obs: torch.Tensor,
    slope: torch.Tensor,
    pose_dim: int,
    cfg: FilterConfig,
    obs_angle_indices: tuple[int, ...] = (),
) -> torch.Tensor:
    """D = d h(ψ̂(φ), φ) / dφ (B, M, K): the total slope of the observation along the
    conditional mean pose ψ̂(φ), by statistical linear regression over the stage-0 points
    (B, C, D) and their observations (B, C, M). Marginal weighting draws the points along
    ψ̂(φ), so their slope is the total one; joint samples give h ≈ H_ψ ψ + H_φ φ, and
    D = H_ψ G + H_φ."""
    p = pose_dim
    if cfg.param_weighting == "marginal":
        return regression_slope(points[..., p:], obs, obs_angle_indices, cfg.cholesky)
    h = regression_slope(points, obs, obs_angle_indices, cfg.cholesky)
    return h[..., :p] @ slope + h[..., p:]


def reassemble_joint(
    ukf: UKFUpdateResult,
    params: ParameterPosterior,
    prior_cross: torch.Tensor,
    slope: torch.Tensor,
    total_slope: torch.Tensor | None,
    cfg: FilterConfig,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Stage 3: the joint posterior bel(ψ | φ) bel(φ) (mean (B, D), cov (B, D, D)) from the
    UKF's conditional pose posterior, the parameters' posterior and, per
    `cfg.cross_covariance` (class docstring), the predicted cross-covariance C = Σ̄_ψφ (B, P, K)
    ("kept") or the slopes G (B, P, K) and D (B, M, K) ("updated")."""
    if cfg.cross_covariance == "kept":
        chol_phi = safe_cholesky(params.cov, cfg.cholesky, "parameter posterior Σ_φ")
        reg = torch.cholesky_solve(prior_cross.mT, chol_phi)  # Σ_φ⁻¹ Cᵀ
        cross = prior_cross
        pose_cov = symmetrize(ukf.cov + cross @ reg)
    else:
        if total_slope is None:
            raise ValueError("the 'updated' reassembly needs the total observation slope")
        slope_post = slope - ukf.gain @ total_slope
        cross = slope_post @ params.cov
        pose_cov = symmetrize(ukf.cov + cross @ slope_post.mT)
    post_mean = torch.cat([ukf.mean, params.mean], dim=-1)
    post_cov = torch.cat(
        [torch.cat([pose_cov, cross], -1), torch.cat([cross.mT, params.cov], -1)],
        dim=-2,
    )
    return post_mean, post_cov


def vision_only_filter(
    dynamics: DynamicsModel,
    pose_noise: ObservationNoiseModel,
    config: FilterConfig = FilterConfig(),
    constraint: StateConstraint | None = None,
) -> DualFilter:
    """V-DDF: the dual filter with z = z^V = (x, y, θ) only (no tactile model)."""
    observation = PoseObservation(config.pose_dim, config.pose_angle_indices)
    return DualFilter(dynamics, observation, pose_noise, config, constraint)
