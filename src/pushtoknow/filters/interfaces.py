"""Model interfaces the filters call (torchfilter style), batched over objects and sigma points.

Shapes: B objects, C sigma points, D = pose_dim + param_dim state, P = pose_dim, M observation.
`context` is an opaque per-batch object the filter passes through unchanged (for the learned
models, `pushtoknow.models.context.PushContext`). Models only ever receive states that satisfy
the filter's constraints (invalid sigma points are projected first, see `filters.constraints`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import Any

import torch
from torch import nn


class DynamicsModel(nn.Module, ABC):
    """Process model: pose change and heteroscedastic diagonal process noise per sigma point."""

    @abstractmethod
    def forward(self, states: torch.Tensor, context: Any) -> tuple[torch.Tensor, torch.Tensor]:
        """states (B, C, D) → (delta_pose (B, C, P), q_diag (B, C, P) ≥ 0).

        Units: pose change in m, m, rad over one filter step; q_diag is the variance of the
        additive pose noise (m², m², rad²).
        """


class ObservationModel(nn.Module, ABC):
    """Observation model h(s): predicted observation per state.

    Subclasses set `obs_dim` (M) and `angle_indices` (observation components that are angles,
    whose residuals are wrapped to (-π, π]).
    """

    obs_dim: int
    angle_indices: tuple[int, ...] = ()

    @abstractmethod
    def forward(self, states: torch.Tensor, context: Any) -> torch.Tensor:
        """states (B, C, D) → predicted observations (B, C, M)."""


class ObservationNoiseModel(nn.Module, ABC):
    """Heteroscedastic diagonal observation noise R(z)."""

    obs_dim: int

    @abstractmethod
    def forward(self, observation: torch.Tensor, context: Any) -> torch.Tensor:
        """observation z (B, M) (finite) → r_diag (B, M) > 0, variances in the units of z²."""


class PoseObservation(ObservationModel):
    """h(s) = ψ: the first `pose_dim` state components (vision-only V-DDF, z = z^V)."""

    def __init__(self, pose_dim: int = 3, angle_indices: tuple[int, ...] = (2,)):
        super().__init__()
        self.obs_dim = pose_dim
        self.angle_indices = tuple(angle_indices)

    def forward(self, states: torch.Tensor, context: Any) -> torch.Tensor:
        return states[..., : self.obs_dim]
