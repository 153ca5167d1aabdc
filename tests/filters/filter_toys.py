"""Toy systems for the filter tests: linear-Gaussian models with parameters in the state and an
exact Kalman filter to compare against (helpers, not tests)."""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pushtoknow.filters import FilterConfig
from pushtoknow.models.analytic import ConstantObservationNoise, LinearDynamics, LinearObservation

F64 = torch.float64


@dataclass
class LinearToy:
    """Δψ = F s + f0 (+ noise q); z = H s + c (+ noise r); φ constant. State s = (ψ, φ)."""

    transition: torch.Tensor  # F (P, D)
    offset: torch.Tensor  # f0 (P,)
    q_diag: torch.Tensor  # (P,)
    obs_matrix: torch.Tensor  # H (M, D)
    obs_offset: torch.Tensor  # c (M,)
    r_diag: torch.Tensor  # (M,)
    pose_dim: int
    prior_mean: torch.Tensor  # (D,)
    prior_cov: torch.Tensor  # (D, D)

    @property
    def state_dim(self) -> int:
        return self.transition.shape[1]

    def models(self, learnable: bool = False):
        return (
            LinearDynamics(self.transition, self.offset, self.q_diag, learnable=learnable),
            LinearObservation(self.obs_matrix, self.obs_offset, learnable=learnable),
            ConstantObservationNoise(self.r_diag, learnable=learnable),
        )

    def config(self, **kwargs) -> FilterConfig:
        return FilterConfig(
            pose_dim=self.pose_dim,
            param_dim=self.state_dim - self.pose_dim,
            pose_angle_indices=(),
            **kwargs,
        )

    def full_transition(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """(A (D, D), a (D,), Q (D, D)) with s' = A s + a + w."""
        d, p = self.state_dim, self.pose_dim
        a = torch.eye(d, dtype=F64)
        a[:p] += self.transition
        off = torch.zeros(d, dtype=F64)
        off[:p] = self.offset
        q = torch.zeros(d, d, dtype=F64)
        q[:p, :p] = torch.diag(self.q_diag)
        return a, off, q

    def simulate(self, batch: int, steps: int, gen: torch.Generator):
        """Truth drawn from the prior; returns (states (T, B, D), observations (T, B, M))."""
        chol = torch.linalg.cholesky(self.prior_cov)
        s = self.prior_mean + torch.randn(batch, self.state_dim, generator=gen, dtype=F64) @ chol.T
        a, off, q = self.full_transition()
        states, obs = [], []
        for _ in range(steps):
            w = torch.randn(batch, self.state_dim, generator=gen, dtype=F64) @ q.sqrt().T
            s = s @ a.T + off + w
            v = torch.randn(batch, len(self.r_diag), generator=gen, dtype=F64) * self.r_diag.sqrt()
            states.append(s)
            obs.append(s @ self.obs_matrix.T + self.obs_offset + v)
        return torch.stack(states), torch.stack(obs)

    def kalman(self, observations: torch.Tensor):
        """Exact Kalman filter from the prior over observations (T, B, M) → (mean, cov)."""
        a, off, q = self.full_transition()
        h, c, r = self.obs_matrix, self.obs_offset, torch.diag(self.r_diag)
        b = observations.shape[1]
        m = self.prior_mean.expand(b, -1).clone()
        p = self.prior_cov.expand(b, -1, -1).clone()
        for z in observations:
            m = m @ a.T + off
            p = a @ p @ a.T + q
            s = h @ p @ h.T + r
            k = p @ h.T @ torch.linalg.inv(s)
            m = m + (k @ (z - m @ h.T - c).unsqueeze(-1)).squeeze(-1)
            p = p - k @ s @ k.transpose(-1, -2)
        return m, p


MASS_G = 9.81  # m · g of the toy block (kg · m/s²)
MU_CENTRE, MU_HALF_RANGE = 0.5, 0.175  # friction = centre + half_range · normalised


def pushed_block(
    lag_m: float = 0.002, force_std: float = 0.2, pos_std: float = 0.002, steps_q: float = 1e-3
) -> LinearToy:
    """1-D block pushed at constant speed (1 cm/step), unknown friction μ (normalised φ̃).

    Honest model: the block lags behind the pusher by lag_m per unit of φ̃ each step (higher
    friction, less slip forward); the pad measures F = m g μ(φ̃) + noise (force_std, N); the
    camera measures x + noise (pos_std, m); process noise steps_q (m) on x. Prior φ̃ ~ N(0,
    0.5²). Linear-Gaussian, so the exact posterior is the Kalman filter's.
    """
    return LinearToy(
        transition=torch.tensor([[0.0, -lag_m]], dtype=F64),
        offset=torch.tensor([0.01], dtype=F64),
        q_diag=torch.tensor([steps_q**2], dtype=F64),
        obs_matrix=torch.tensor([[1.0, 0.0], [0.0, MASS_G * MU_HALF_RANGE]], dtype=F64),
        obs_offset=torch.tensor([0.0, MASS_G * MU_CENTRE], dtype=F64),
        r_diag=torch.tensor([pos_std**2, force_std**2], dtype=F64),
        pose_dim=1,
        prior_mean=torch.zeros(2, dtype=F64),
        prior_cov=torch.diag(torch.tensor([1e-3**2, 0.5**2], dtype=F64)),
    )


def planar_toy() -> LinearToy:
    """3-D pose (x, y, θ) driven by 2 constant parameters, observed with 2 parameter channels."""
    transition = torch.zeros(3, 5, dtype=F64)
    transition[0, 3] = 0.01
    transition[1, 4] = -0.01
    transition[2, 3] = 0.02
    transition[2, 4] = 0.01
    obs = torch.zeros(5, 5, dtype=F64)
    obs[:3, :3] = torch.eye(3, dtype=F64)
    obs[3, 3], obs[3, 4], obs[4, 4] = 1.5, 0.3, -1.0
    return LinearToy(
        transition=transition,
        offset=torch.tensor([0.005, 0.0, 0.01], dtype=F64),
        q_diag=torch.tensor([1e-6, 1e-6, 1e-4], dtype=F64),
        obs_matrix=obs,
        obs_offset=torch.zeros(5, dtype=F64),
        r_diag=torch.tensor([4e-6, 4e-6, 4e-4, 0.04, 0.04], dtype=F64),
        pose_dim=3,
        prior_mean=torch.zeros(5, dtype=F64),
        prior_cov=torch.diag(torch.tensor([1e-6, 1e-6, 1e-4, 0.25, 0.25], dtype=F64)),
    )


class ToyPushDynamics(LinearDynamics.__mro__[1]):  # DynamicsModel
    """Smooth nonlinear planar push on s = (x, y, θ, φ̃) ∈ R⁸ using SI parameters: the object
    slides less with more friction and mass and turns with the CoM offset."""

    def forward(self, states, context):
        from pushtoknow.common.params import denormalise_params

        si = denormalise_params(states[..., 3:])
        m, mu, cx, cy = si[..., 0], si[..., 1], si[..., 2], si[..., 3]
        slide = 0.01 / (1.0 + mu * m)
        delta = torch.stack(
            [
                slide * torch.cos(states[..., 2]),
                slide * torch.sin(states[..., 2]),
                2.0 * cy - 0.5 * cx,
            ],
            dim=-1,
        )
        q = torch.stack([1e-7 + 1e-7 * m, 1e-7 + 1e-7 * m, 1e-5 + 0 * m], dim=-1)
        return delta, q


class ToyPushObservation(LinearObservation.__mro__[1]):  # ObservationModel
    """z = (x, y, θ, F_x, F_y): pose plus the friction force m μ g split by the CoM offset."""

    obs_dim = 5
    angle_indices = (2,)

    def forward(self, states, context):
        from pushtoknow.common.params import denormalise_params

        si = denormalise_params(states[..., 3:])
        force = si[..., 0] * si[..., 1] * 9.81
        return torch.cat([states[..., :3], torch.stack([force, 20.0 * force * si[..., 3]], -1)], -1)


def random_walk_toy() -> LinearToy:
    """Pose random walk (sd 1 cm/step), constant parameter, both observed (sd 1 cm, 0.5)."""
    return LinearToy(
        transition=torch.zeros(1, 2, dtype=F64),
        offset=torch.zeros(1, dtype=F64),
        q_diag=torch.tensor([1e-4], dtype=F64),
        obs_matrix=torch.eye(2, dtype=F64),
        obs_offset=torch.zeros(2, dtype=F64),
        r_diag=torch.tensor([1e-4, 0.25], dtype=F64),
        pose_dim=1,
        prior_mean=torch.zeros(2, dtype=F64),
        prior_cov=torch.diag(torch.tensor([1e-2, 1.0], dtype=F64)),
    )
