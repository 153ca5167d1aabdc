"""One Levenberg–Marquardt descent for the maximum a posteriori fits of replayed pushes
(docs/DESIGN.md §12): `fit.identify`'s refinement and the physics filter's iterated update
(`recursive.iterated_update`) both descend with `levenberg_marquardt`.

The objective (`Objective`) over coordinates u (D,) is

    Σ_i ρ(r_i(u)) + ½ Σ_j e_j(u)² + ½ (u − ū)ᵀ P⁻¹ (u − ū),

r the first `n_data` residuals (noise units; ρ Huber on the `robust` ones, quadratic on the
rest), e the residuals after them (feasibility penalties, quadratic) and the last term a
Gaussian prior N(ū, P). Each iteration solves the iteratively reweighted (Huber) Gauss–Newton
normal equations damped by λ·diag(H), tries up to `trials` values of λ (×4 after a rejected
step, ÷3 after an accepted one), clips the step to `max_step` per coordinate and stops when no
step lowers the objective, or a step moves no coordinate more than `step_tolerance` or lowers
the objective by less than `cost_tolerance`. Jacobians are forward differences of one batch
of D replays; between exact ones, `broyden_steps` accepted steps may update the Jacobian by
Broyden's rank-one rule (a descent that then finds no lower objective retries with an exact
one).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from pushtoknow.identification.residuals import huber_cost, huber_weights

LAMBDA_START = 1e-2  # the damping λ a descent starts from
LAMBDA_MIN = 1e-6  # λ never drops below this
LAMBDA_DOWN = 3.0  # λ ÷ this after an accepted step
LAMBDA_UP = 4.0  # λ × this after a rejected one

Residuals = Callable[[np.ndarray], np.ndarray]  # u (B, D) → residuals (B, M)
Replayed = Callable[[int], None]  # told how many candidates were just replayed


@dataclass(frozen=True, eq=False)
class Objective:
    """The MAP objective of one fit (module doc): `residuals` u (B, D) → (B, M), the first
    `n_data` of each row data residuals in noise units, `robust` (n_data,) marking those under
    the Huber loss of threshold `huber` (noise std), the remaining M − n_data quadratic
    penalties; the Gaussian prior's mean `prior_mean` (D,) and precision `prior_precision`
    (D, D)."""

    residuals: Residuals
    n_data: int
    robust: np.ndarray
    huber: float
    prior_mean: np.ndarray
    prior_precision: np.ndarray

    def cost(self, r: np.ndarray, u: np.ndarray) -> float:
        """The objective at u (D,) with residuals r (M,)."""
        n = self.n_data
        d = u - self.prior_mean
        return (
            huber_cost(r[:n], self.huber, self.robust)
            + 0.5 * float(r[n:] @ r[n:])
            + 0.5 * d @ self.prior_precision @ d
        )

    def weights(self, r: np.ndarray) -> np.ndarray:
        """(M,) iteratively reweighted least-squares weights of residuals r (M,): Huber's on
        the data, 1 on the penalties."""
        n = self.n_data
        return np.concatenate([huber_weights(r[:n], self.huber, self.robust), np.ones(len(r) - n)])

    def normal_equations(
        self, jac: np.ndarray, r: np.ndarray, u: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """Gauss–Newton Hessian (D, D) and gradient (D,) at u (D,) from the Jacobian (M, D) of
        the residuals r (M,): JᵀWJ + P⁻¹ and JᵀWr + P⁻¹(u − ū), W the Huber weights at r."""
        w = self.weights(r)
        h = jac.T @ (w[:, None] * jac) + self.prior_precision
        g = jac.T @ (w * r) + self.prior_precision @ (u - self.prior_mean)
        return h, g


@dataclass(frozen=True)
class DescentSettings:
    """How `levenberg_marquardt` descends. fd_steps (D,): forward-difference step per
    coordinate; trials: λ values tried per iteration; broyden_steps: accepted steps between
    exact Jacobians updated by Broyden's rule (0: an exact Jacobian at every iteration);
    final_jacobian: also return the exact Jacobian at the returned point."""

    max_iterations: int
    max_step: float
    step_tolerance: float
    cost_tolerance: float
    fd_steps: tuple[float, ...]
    trials: int = 4
    broyden_steps: int = 0
    final_jacobian: bool = False


@dataclass(frozen=True, eq=False)
class Descent:
    """Where a descent stopped: u (D,), its residuals r (M,) and objective `cost`; jacobian
    (M, D): the exact forward-difference Jacobian at u (None unless `final_jacobian`); step
    (D,): the last accepted step (zeros if the last iteration accepted none); iterations."""

    u: np.ndarray
    r: np.ndarray
    cost: float
    jacobian: np.ndarray | None
    step: np.ndarray
    iterations: int


def clip_step(step: np.ndarray, max_step: float) -> np.ndarray:
    """The step (D,) scaled down so that no coordinate moves more than `max_step`."""
    return step * min(1.0, max_step / max(np.max(np.abs(step)), 1e-300))


def forward_jacobian(
    residuals: Residuals, u: np.ndarray, r: np.ndarray, fd_steps: np.ndarray
) -> np.ndarray:
    """(M, D) forward differences at u (D,) (residuals r (M,)), one batch of D replays."""
    rj = residuals(u[None] + np.diag(fd_steps))
    return ((rj - r[None]) / fd_steps[:, None]).T


def central_jacobian(residuals: Residuals, u: np.ndarray, fd_steps: np.ndarray) -> np.ndarray:
    """(M, D) central differences at u (D,), one batch of 2D replays."""
    d = len(fd_steps)
    rj = residuals(np.concatenate([u[None] + np.diag(fd_steps), u[None] - np.diag(fd_steps)]))
    return ((rj[:d] - rj[d:]) / (2 * fd_steps[:, None])).T


def linearised_information(
    residuals: Residuals,
    u: np.ndarray,
    r: np.ndarray,
    cov: np.ndarray,
    spread: float = 1.0,
) -> tuple[np.ndarray, np.ndarray]:
    """The statistical linearisation of a push's data residuals about the optimum u (D,)
    (residuals r (n,) there, noise units) across a belief's spread cov (D, D): sigma points
    u ± `spread`·L e_j (L = chol(cov)) replayed. Returns the Jacobian (n, D) of their central
    differences and each residual's linearisation error (n,), the mean over j of the squared
    departure of the midpoint (y⁺ + y⁻)/2 from r (noise units²): what the replay's jitter and
    curvature within the belief's own spread add to each residual's variance.

    One round of (iterated) posterior linearisation, with two simplifications: the points lie
    at ±1 standard deviation (the cubature rule's at ±√D would weigh curvature more), and
    cross terms between directions are not sampled. A forward difference at one point reads a
    replay's step-to-step jitter (a contact that begins one step later) as information. The
    first round spreads the points across the belief before the push, where the jitter
    averages out and curvature counts as noise, later rounds across the last posterior; a
    round started at a posterior already too sure would keep its points inside the jitter's
    scale, its steps read as slopes again. On a linear replay every round is exact (error 0)."""
    dim = len(u)
    chol = np.linalg.cholesky(cov + 1e-15 * np.eye(dim) * max(np.trace(cov), 1e-300))
    steps = spread * chol.T  # row j: spread · L e_j
    y = residuals(np.concatenate([u[None] + steps, u[None] - steps]))[:, : len(r)]
    y_plus, y_minus = y[:dim], y[dim:]
    jl = (y_plus - y_minus) / (2.0 * spread)  # (D, n): (J L)ᵀ
    jac = np.linalg.solve(chol.T, jl).T
    error = np.mean((0.5 * (y_plus + y_minus) - r[None]) ** 2, axis=0)
    return jac, error


def levenberg_marquardt(
    objective: Objective,
    u: np.ndarray,
    r: np.ndarray,
    settings: DescentSettings,
    cost: float | None = None,
    replayed: Replayed | None = None,
) -> Descent:
    """Descend `objective` from u (D,) with residuals r (M,) and objective `cost` (None: the
    objective's at u; np.inf accepts any first step). `replayed(k)` is told after every
    batch of k candidates replayed. Deterministic: same inputs, same descent."""
    fd = np.asarray(settings.fd_steps, dtype=np.float64)
    dim = len(fd)
    c = objective.cost(r, u) if cost is None else cost
    lam, step = LAMBDA_START, np.zeros(dim)
    jac: np.ndarray | None = None  # None: an exact one is due at u
    exact, since_exact = True, 0
    iterations = 0

    def exact_jacobian(u: np.ndarray, r: np.ndarray) -> np.ndarray:
        out = forward_jacobian(objective.residuals, u, r, fd)
        if replayed is not None:
            replayed(dim)
        return out

    for _ in range(settings.max_iterations):
        iterations += 1
        if jac is None:
            jac, exact, since_exact = exact_jacobian(u, r), True, 0
        h, g = objective.normal_equations(jac, r, u)
        moved, previous = False, c
        for _ in range(settings.trials):
            step = clip_step(
                np.linalg.solve(h + lam * np.diag(np.diagonal(h)), -g), settings.max_step
            )
            trial = u + step
            rt = objective.residuals(trial[None])[0]
            if replayed is not None:
                replayed(1)
            ct = objective.cost(rt, trial)
            if ct < c:
                r_prev = r
                u, r, c, lam = trial, rt, ct, max(lam / LAMBDA_DOWN, LAMBDA_MIN)
                moved = True
                break
            lam *= LAMBDA_UP
        if not moved:
            step = np.zeros(dim)
            if exact:
                break
            jac = None  # retry with the exact one
            continue
        converged = (
            np.max(np.abs(step)) < settings.step_tolerance or previous - c < settings.cost_tolerance
        )
        if converged or since_exact >= settings.broyden_steps:
            jac = None
        else:
            jac = jac + np.outer(r - r_prev - jac @ step, step) / float(step @ step)
            exact, since_exact = False, since_exact + 1
        if converged:
            break
    if settings.final_jacobian and (jac is None or not exact):
        jac = exact_jacobian(u, r)
    return Descent(u, r, c, jac if settings.final_jacobian else None, step, iterations)
