"""Toy problems for the active-selection tests: dynamics whose coupling of the pose to the
parameters is chosen per candidate by the context (helpers, not tests)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pushtoknow.common.angles import wrap_angle
from pushtoknow.filters import DualFilter, FilterConfig
from pushtoknow.filters.interfaces import DynamicsModel, ObservationModel
from pushtoknow.models.analytic import ConstantObservationNoise, LinearObservation

F64 = torch.float64
GAIN = 0.01  # m of pose change per step per unit of φ̃ at coupling 1
STEP_Q = 1e-6  # m², process noise variance per step
POS_R = 1e-6  # m², variance of the pose observation
PRIOR_POSE_VAR, PRIOR_PARAM_VAR = 1e-6, 0.25


@dataclass(frozen=True)
class CouplingContext:
    """coupling (B,): how strongly each candidate's push couples the pose to the parameters
    (0: the pusher misses, the pose does not depend on φ)."""

    coupling: torch.Tensor

    def validate(self, batch: int) -> None:
        assert self.coupling.shape == (batch,), (self.coupling.shape, batch)


class CouplingDynamics(DynamicsModel):
    """1-D pose, 1 parameter: Δx = coupling · GAIN · φ̃, noise variance STEP_Q. Linear."""

    def forward(self, states, context):
        c = context.coupling.to(states.dtype)[:, None, None]
        delta = c * GAIN * states[..., 1:2]
        return delta, torch.full_like(delta, STEP_Q)


def linear_filter(num_sigma_points: int = 20) -> DualFilter:
    """State (x, φ̃); z = x (pose only, variance POS_R)."""
    cfg = FilterConfig(
        pose_dim=1, param_dim=1, pose_angle_indices=(), num_sigma_points=num_sigma_points
    )
    return DualFilter(
        CouplingDynamics(),
        LinearObservation([[1.0, 0.0]]),
        ConstantObservationNoise([POS_R]),
        cfg,
    )


def linear_prior() -> tuple[torch.Tensor, torch.Tensor]:
    """mean (1, 2), cov (1, 2, 2)."""
    mean = torch.tensor([[0.0, 0.3]], dtype=F64)
    cov = torch.diag(torch.tensor([PRIOR_POSE_VAR, PRIOR_PARAM_VAR], dtype=F64)).unsqueeze(0)
    return mean, cov


def exact_linear(coupling: float, n_steps: int, entropy: bool):
    """Exact Kalman prediction (and, if `entropy`, covariance update) of the linear toy:
    (mean (2,), cov (2, 2)) after n_steps."""
    mean, cov = linear_prior()
    mean, cov = mean[0], cov[0]
    a = torch.tensor([[1.0, coupling * GAIN], [0.0, 1.0]], dtype=F64)
    q = torch.diag(torch.tensor([STEP_Q, 0.0], dtype=F64))
    h = torch.tensor([[1.0, 0.0]], dtype=F64)
    for _ in range(n_steps):
        mean, cov = a @ mean, a @ cov @ a.T + q
        if entropy:
            s = h @ cov @ h.T + POS_R
            k = cov @ h.T @ torch.linalg.inv(s)
            cov = cov - k @ s @ k.T
    return mean, cov


class PlanarCouplingDynamics(DynamicsModel):
    """Nonlinear 8-D toy: (x, y, θ, φ̃ ∈ R⁵); the context's coupling scales a push that moves
    and turns the object depending on φ̃ nonlinearly. Independent of θ (so rotating the
    object changes nothing but the wrap of the observed angle)."""

    def forward(self, states, context):
        c = context.coupling.to(states.dtype)[:, None]
        phi = states[..., 3:]
        delta = torch.stack(
            [
                GAIN * c * torch.sigmoid(phi[..., 0] - phi[..., 1]),
                0.5 * GAIN * c * torch.tanh(phi[..., 4]),
                0.05 * c * torch.tanh(phi[..., 2] + 0.5 * phi[..., 3]),
            ],
            dim=-1,
        )
        ones = torch.ones_like(phi[..., 0])
        q = torch.stack([STEP_Q * (1 + phi[..., 4].square()), STEP_Q * ones, 1e-4 * ones], -1)
        return delta, q


class PlanarObservation(ObservationModel):
    """z = (x, y, wrap(θ), F): the pose with θ wrapped to (-π, π], and a force m μ-like
    product of parameters scaled by the coupling."""

    obs_dim = 4
    angle_indices = (2,)

    def forward(self, states, context):
        c = context.coupling.to(states.dtype)[:, None]
        phi = states[..., 3:]
        force = c * torch.exp(0.3 * phi[..., 0]) * (1.0 + 0.2 * phi[..., 1])
        return torch.cat(
            [states[..., :2], wrap_angle(states[..., 2:3]), force.unsqueeze(-1)], dim=-1
        )


def planar_filter(num_sigma_points: int = 24) -> DualFilter:
    cfg = FilterConfig(num_sigma_points=num_sigma_points)
    return DualFilter(
        PlanarCouplingDynamics(),
        PlanarObservation(),
        ConstantObservationNoise([1e-6, 1e-6, 1e-4, 0.01]),
        cfg,
    )


def planar_prior(theta: float = 0.0) -> tuple[torch.Tensor, torch.Tensor]:
    """mean (1, 8), cov (1, 8, 8) with a little correlation among the parameters."""
    mean = torch.tensor([[0.01, -0.02, theta, 0.1, -0.2, 0.3, 0.0, 0.1]], dtype=F64)
    var = torch.tensor([1e-6, 1e-6, 1e-3, 0.3, 0.3, 0.3, 0.3, 0.3], dtype=F64)
    cov = torch.diag(var)
    cov[3, 4] = cov[4, 3] = 0.05
    return mean, cov.unsqueeze(0)
