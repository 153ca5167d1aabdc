"""Analytic (hand-written) models implementing the filter interfaces: linear dynamics and
observations, constant noise. For tests, baselines and problems with known physics."""

from __future__ import annotations

from collections.abc import Sequence

import torch
from torch import nn

from pushtoknow.filters.interfaces import (
    DynamicsModel,
    ObservationModel,
    ObservationNoiseModel,
    PoseObservation,
)

__all__ = [
    "ConstantObservationNoise",
    "LinearDynamics",
    "LinearObservation",
    "PoseObservation",
]


def _tensor(x: Sequence | torch.Tensor, dtype: torch.dtype) -> torch.Tensor:
    return torch.as_tensor(x, dtype=dtype).clone()


class LinearDynamics(DynamicsModel):
    """Δψ = F s + b with constant diagonal process noise q.

    transition F (P, D), offset b (P,), q_diag (P,) (variances). `learnable` makes F, b and
    log q parameters (for gradient tests); otherwise they are buffers.
    """

    def __init__(
        self,
        transition: Sequence | torch.Tensor,
        offset: Sequence | torch.Tensor,
        q_diag: Sequence | torch.Tensor,
        learnable: bool = False,
        dtype: torch.dtype = torch.float64,
    ):
        super().__init__()
        f, b, q = _tensor(transition, dtype), _tensor(offset, dtype), _tensor(q_diag, dtype)
        if learnable:
            self.transition = nn.Parameter(f)
            self.offset = nn.Parameter(b)
            self.log_q = nn.Parameter(q.log())
        else:
            self.register_buffer("transition", f)
            self.register_buffer("offset", b)
            self.register_buffer("log_q", q.log())

    def forward(self, states: torch.Tensor, context: object) -> tuple[torch.Tensor, torch.Tensor]:
        f = self.transition.to(states.dtype)
        delta = states @ f.transpose(0, 1) + self.offset.to(states.dtype)
        q = self.log_q.to(states.dtype).exp().expand_as(delta)
        return delta, q


class LinearObservation(ObservationModel):
    """z = H s + c. observation_matrix H (M, D), offset c (M,)."""

    def __init__(
        self,
        observation_matrix: Sequence | torch.Tensor,
        offset: Sequence | torch.Tensor | None = None,
        angle_indices: tuple[int, ...] = (),
        learnable: bool = False,
        dtype: torch.dtype = torch.float64,
    ):
        super().__init__()
        h = _tensor(observation_matrix, dtype)
        c = torch.zeros(h.shape[0], dtype=dtype) if offset is None else _tensor(offset, dtype)
        self.obs_dim = h.shape[0]
        self.angle_indices = tuple(angle_indices)
        if learnable:
            self.matrix = nn.Parameter(h)
            self.offset = nn.Parameter(c)
        else:
            self.register_buffer("matrix", h)
            self.register_buffer("offset", c)

    def forward(self, states: torch.Tensor, context: object) -> torch.Tensor:
        return states @ self.matrix.to(states.dtype).transpose(0, 1) + self.offset.to(states.dtype)


class ConstantObservationNoise(ObservationNoiseModel):
    """R = diag(r_diag), independent of z. r_diag (M,) variances."""

    def __init__(
        self,
        r_diag: Sequence | torch.Tensor,
        learnable: bool = False,
        dtype: torch.dtype = torch.float64,
    ):
        super().__init__()
        r = _tensor(r_diag, dtype)
        self.obs_dim = r.shape[0]
        if learnable:
            self.log_r = nn.Parameter(r.log())
        else:
            self.register_buffer("log_r", r.log())

    def forward(self, observation: torch.Tensor, context: object) -> torch.Tensor:
        return self.log_r.to(observation.dtype).exp().expand_as(observation)
