"""Joint differentiable filter (VT-JDF ablation): one UKF update of the full state."""

from __future__ import annotations

import torch

from pushtoknow.filters.base import BeliefFilter, FilterNoise, UpdateInfo
from pushtoknow.filters.ukf import ukf_update


class JointFilter(BeliefFilter):
    """VT-JDF: the same constrained Monte-Carlo prediction as `DualFilter`, then a standard UKF
    update (Merwe sigma points) of the whole state s = (ψ, φ̃) with z = h(project(s)) and R.

    Objects whose observation has a non-finite entry keep their predicted belief.
    """

    uses_update_noise = False

    def update(
        self,
        mean: torch.Tensor,
        cov: torch.Tensor,
        observation: torch.Tensor,
        context: object,
        noise: FilterNoise | None = None,
        generator: torch.Generator | None = None,
    ) -> tuple[torch.Tensor, torch.Tensor, UpdateInfo]:
        """Posterior (mean (B, D), cov (B, D, D), info) given the predicted belief and z (B, M).

        The update is deterministic; `noise` and `generator` are accepted for a uniform API.
        """
        cfg = self.config
        b = self._check_belief(mean, cov)
        self._check_context(context, b)
        z, valid, r_diag = self._observation_and_noise(observation, context, mean)
        ukf = ukf_update(
            mean,
            cov,
            z,
            lambda pts: self._predict_observations(pts, context),
            r_diag,
            cfg.sigma_points,
            cfg.pose_angle_indices,
            self.observation.angle_indices,
            cfg.cholesky,
        )
        keep = valid.view(b, 1)
        post_mean = torch.where(keep, ukf.mean, mean)
        post_cov = torch.where(keep.unsqueeze(-1), ukf.cov, cov)
        return post_mean, post_cov, UpdateInfo(None, None, None, skipped=~valid)
