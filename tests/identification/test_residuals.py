"""Residual weighting of `identification.residuals`: a resting object's repeated pose counts
once; AR(1) pose errors are whitened exactly."""

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.identification.residuals import rest_weights, whiten_ar1


def test_a_resting_tail_keeps_one_sample():
    moving = np.column_stack([np.linspace(0, 0.05, 6), np.zeros(6), np.zeros(6)])
    rest = np.tile([0.05, 0.0, 0.0], (10, 1)) + 1e-4  # within tolerance of the last pose
    w = rest_weights(np.concatenate([moving, rest]), 2e-3, 0.04)
    # the moving samples (the last one within 2 mm of the rest counts as resting) and the
    # first resting sample keep weight 1; the rest of the stretch none
    first_rest = 5
    assert np.all(w[: first_rest + 1] == 1.0) and np.all(w[first_rest + 1 :] == 0.0)


def test_a_track_that_never_rests_keeps_every_sample_and_a_still_one_keeps_one():
    turning = np.column_stack([np.zeros(8), np.zeros(8), np.linspace(0, 1, 8)])
    assert np.all(rest_weights(turning, 1e-3, 0.01) == 1.0)
    still = np.zeros((8, 3))
    assert rest_weights(still, 1e-3, 0.01).tolist() == [1.0] + [0.0] * 7


@settings(max_examples=30, deadline=None)
@given(st.floats(0.0, 0.95), st.integers(2, 30), st.integers(0, 1000))
def test_whitening_turns_ar1_covariance_into_the_identity(rho, n, seed):
    """W Σ Wᵀ = I for Σ_ij = ρ^|i−j| and W the whitening map (applied to Σ's columns)."""
    lag = np.abs(np.arange(n)[:, None] - np.arange(n)[None])
    sigma = rho**lag
    chol = np.linalg.cholesky(sigma)
    # whitening each column of the Cholesky factor gives an orthogonal matrix
    w_chol = whiten_ar1(chol.T[:, :, None], rho, [n])[:, :, 0].T
    np.testing.assert_allclose(w_chol @ w_chol.T, np.eye(n), atol=1e-9)
    # two tracks back to back are whitened independently
    e = np.random.default_rng(seed).normal(size=(2 * n, 1))
    both = whiten_ar1(e, rho, [n, n])
    np.testing.assert_allclose(both[:n], whiten_ar1(e[:n], rho, [n]))
    np.testing.assert_allclose(both[n:], whiten_ar1(e[n:], rho, [n]))
