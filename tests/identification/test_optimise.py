"""The shared Levenberg–Marquardt descent (`identification.optimise`) on problems whose minimum
is known: a linear least squares with a Gaussian prior (the closed-form MAP), Rosenbrock's
valley, a convex Huber objective; Broyden's updates against exact Jacobians."""

from dataclasses import replace

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize

from pushtoknow.identification.optimise import (
    DescentSettings,
    Objective,
    forward_jacobian,
    levenberg_marquardt,
)

TIGHT = DescentSettings(
    max_iterations=200,
    max_step=10.0,
    step_tolerance=1e-13,
    cost_tolerance=1e-16,
    fd_steps=(1e-3, 1e-3, 1e-3),
)


class Counted:
    """A residual function u (B, D) → (B, M) that counts the candidates it was asked for."""

    def __init__(self, f):
        self.f, self.rows = f, 0

    def __call__(self, us: np.ndarray) -> np.ndarray:
        us = np.atleast_2d(us)
        self.rows += len(us)
        return np.stack([self.f(u) for u in us])


def linear_problem(seed: int, dim: int = 3, data: int = 12, penalties: int = 2):
    """r(u) = A u − y (the last `penalties` rows quadratic penalties), prior N(ū, P): the MAP is
    (AᵀA + P⁻¹)⁻¹ (Aᵀy + P⁻¹ū)."""
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(data + penalties, dim))
    y = rng.normal(size=data + penalties)
    root = rng.normal(size=(dim, dim))
    prior_cov = root @ root.T + 0.5 * np.eye(dim)
    prior_mean = rng.normal(size=dim)
    precision = np.linalg.inv(prior_cov)
    objective = Objective(
        Counted(lambda u: a @ u - y),
        data,
        np.zeros(data, dtype=bool),  # quadratic everywhere
        3.0,
        prior_mean,
        precision,
    )
    want = np.linalg.solve(a.T @ a + precision, a.T @ y + precision @ prior_mean)
    return objective, want


def start(objective: Objective, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return u, objective.residuals(u[None])[0]


def test_a_linear_least_squares_with_a_prior_reaches_the_closed_form_map():
    objective, want = linear_problem(0)
    got = levenberg_marquardt(objective, *start(objective, np.full(3, 5.0)), TIGHT)
    np.testing.assert_allclose(got.u, want, rtol=1e-9, atol=1e-10)
    assert got.cost == pytest.approx(objective.cost(objective.residuals(want[None])[0], want))
    assert got.jacobian is None and got.iterations >= 1


def test_rosenbrocks_valley_is_descended_to_its_minimum():
    """r = (10 (u₁ − u₀²), 1 − u₀), no prior: the minimum (1, 1) at the end of a curved
    valley, from the classic start (−1.2, 1)."""
    objective = Objective(
        Counted(lambda u: np.array([10 * (u[1] - u[0] ** 2), 1 - u[0]])),
        2,
        np.zeros(2, dtype=bool),
        3.0,
        np.zeros(2),
        np.zeros((2, 2)),
    )
    lm = DescentSettings(200, 10.0, 1e-12, 1e-20, (1e-7, 1e-7))
    got = levenberg_marquardt(objective, *start(objective, np.array([-1.2, 1.0])), lm)
    np.testing.assert_allclose(got.u, [1.0, 1.0], atol=1e-6)
    assert got.cost < 1e-12


def test_huber_weights_reach_the_minimum_of_the_robust_objective():
    """One gross outlier among robust residuals: the descent (iteratively reweighted) stops
    at the minimiser of the convex Huber + prior objective, found here by BFGS."""
    rng = np.random.default_rng(3)
    a = rng.normal(size=(20, 2))
    y = a @ np.array([0.5, -1.0]) + 0.1 * rng.normal(size=20)
    y[4] += 30.0
    objective = Objective(
        Counted(lambda u: a @ u - y), 20, np.ones(20, dtype=bool), 1.0, np.zeros(2), np.eye(2)
    )
    lm = DescentSettings(100, 10.0, 1e-12, 1e-14, (1e-4, 1e-4))
    got = levenberg_marquardt(objective, *start(objective, np.zeros(2)), lm)

    def f(u):
        return objective.cost(a @ u - y, u)

    want = minimize(f, np.zeros(2), method="BFGS", options={"gtol": 1e-10}).x
    np.testing.assert_allclose(got.u, want, atol=1e-5)
    assert got.cost <= f(want) + 1e-9


def test_broyden_on_a_linear_problem_equals_exact_jacobians_with_fewer_replays():
    """On a linear problem Broyden's rank-one rule keeps the (exact) Jacobian: the descent ends
    where exact Jacobians at every iteration end, with fewer replays."""
    objective, want = linear_problem(1)
    u0 = np.full(3, -4.0)
    lm = replace(TIGHT, step_tolerance=1e-8, cost_tolerance=1e-12)
    exact_told, broyden_told = [], []
    exact = levenberg_marquardt(objective, *start(objective, u0), lm, None, exact_told.append)
    broyden = levenberg_marquardt(
        objective, *start(objective, u0), replace(lm, broyden_steps=3), None, broyden_told.append
    )
    np.testing.assert_allclose(broyden.u, exact.u, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(broyden.u, want, rtol=1e-8, atol=1e-9)
    assert sum(broyden_told) < sum(exact_told)


def test_the_final_jacobian_is_exact_at_the_returned_point_and_steps_are_clipped():
    objective, _ = linear_problem(2)
    u0 = np.full(3, 50.0)  # far from the minimum: one iteration moves at most max_step
    clipped = DescentSettings(1, 0.25, 1e-12, 1e-12, TIGHT.fd_steps, broyden_steps=2)
    one = levenberg_marquardt(objective, *start(objective, u0), clipped)
    assert np.max(np.abs(one.u - u0)) <= 0.25 + 1e-12
    lm = replace(TIGHT, broyden_steps=2, final_jacobian=True)
    got = levenberg_marquardt(objective, *start(objective, u0), lm)
    fd = np.asarray(lm.fd_steps)
    np.testing.assert_array_equal(
        got.jacobian, forward_jacobian(objective.residuals, got.u, got.r, fd)
    )


def test_the_replay_callback_counts_every_candidate():
    objective, _ = linear_problem(4)
    told = []
    lm = replace(TIGHT, broyden_steps=1, final_jacobian=True)
    before = objective.residuals.rows
    levenberg_marquardt(objective, *start(objective, np.ones(3)), lm, replayed=told.append)
    assert sum(told) == objective.residuals.rows - before - 1  # less the start's own replay
    assert set(told) <= {1, 3}  # one trial, or one Jacobian of D = 3 candidates


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 10_000),
    dim=st.integers(1, 4),
    broyden_steps=st.integers(0, 3),
    trials=st.integers(1, 5),
)
def test_any_linear_map_problem_is_solved_and_never_made_worse(seed, dim, broyden_steps, trials):
    """On any linear least squares with a Gaussian prior, however the descent is set up, the
    objective never rises and the descent ends at the closed-form MAP: its objective to the
    objective's floating-point resolution (a point within √(ε·cost/H) of the MAP, ~1e-8 here,
    changes the objective by less than a rounding, so no descent can place it closer)."""
    objective, want = linear_problem(seed, dim=dim)
    u0 = np.random.default_rng(seed + 1).normal(size=dim) * 5
    u0, r0 = start(objective, u0)
    lm = DescentSettings(
        200, 10.0, 1e-13, 1e-16, (1e-3,) * dim, trials=trials, broyden_steps=broyden_steps
    )
    got = levenberg_marquardt(objective, u0, r0, lm)
    assert got.cost <= objective.cost(r0, u0)
    c_map = objective.cost(objective.residuals(want[None])[0], want)
    assert got.cost <= c_map * (1.0 + 1e-13)
    np.testing.assert_allclose(got.u, want, rtol=1e-6, atol=1e-6)


def test_linearised_information_on_a_quadratic_replay():
    """y_k = Σ_j b_kj u_j + Σ_j a_kj u_j² about u = 0 with cov = L Lᵀ (L diagonal): the
    central differences at ±L e_j give b exactly, and each residual's error is the mean over j
    of the midpoint's departure, (a_kj L_jj²)²."""
    from pushtoknow.identification.optimise import linearised_information

    rng = np.random.default_rng(3)
    a, b = rng.normal(size=(7, 4)), rng.normal(size=(7, 4))
    sd = np.array([0.5, 1.0, 2.0, 0.1])

    def residuals(us):
        return us @ b.T + (us**2) @ a.T

    jac, error = linearised_information(residuals, np.zeros(4), np.zeros(7), np.diag(sd**2))
    np.testing.assert_allclose(jac, b, atol=1e-12)
    np.testing.assert_allclose(error, np.mean((a * sd**2) ** 2, axis=1), rtol=1e-10)
    # a linear replay: exact Jacobian, no error, whatever the spread
    jac, error = linearised_information(lambda us: us @ b.T, np.ones(4), np.ones(4) @ b.T,
                                        np.diag(sd**2), spread=3.0)  # fmt: skip
    np.testing.assert_allclose(jac, b, atol=1e-12)
    np.testing.assert_allclose(error, 0.0, atol=1e-20)
