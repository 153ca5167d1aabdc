"""The parameter map: log space for m, μ and I_z, linear for the CoM; SI moments of beliefs."""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import (
    CATALOGUE_GRID,
    LOG_PARAMS,
    PARAM_NAMES,
    PARAM_RANGES,
    denormalise_params,
    linear_param_affine,
    normalise_param,
    normalise_params,
    product_moments,
    si_moments,
)

LOG_IDX = [PARAM_NAMES.index(k) for k in sorted(LOG_PARAMS)]


def test_catalogue_range_maps_to_minus_one_one():
    lo = np.array([PARAM_RANGES[k][0] for k in PARAM_NAMES])
    hi = np.array([PARAM_RANGES[k][1] for k in PARAM_NAMES])
    np.testing.assert_allclose(normalise_params(lo), -1.0, atol=1e-12)
    np.testing.assert_allclose(normalise_params(hi), 1.0, atol=1e-12)
    # log space: the geometric mean of a range is its centre
    z = normalise_param("mass", float(np.sqrt(0.2 * 1.2)))
    assert z == pytest.approx(0.0, abs=1e-12)
    assert normalise_param("com_x", 0.0) == pytest.approx(0.0, abs=1e-12)


@settings(max_examples=100, deadline=None)
@given(st.lists(st.floats(-30.0, 30.0), min_size=5, max_size=5))
def test_every_state_maps_to_a_physical_parameter_and_back(z):
    z = np.array(z)
    phi = denormalise_params(z)
    assert (phi[LOG_IDX] > 0).all()  # positive by construction, however extreme the state
    np.testing.assert_allclose(normalise_params(phi), z, atol=1e-9 * (1 + np.abs(z).max()))
    phi_t = denormalise_params(torch.tensor(z))
    np.testing.assert_allclose(phi_t.numpy(), phi, rtol=1e-12)


def test_torch_map_has_finite_gradients_at_zero_com():
    phi = torch.tensor([0.5, 0.5, 0.0, 0.0, 1e-3], dtype=torch.float64, requires_grad=True)
    normalise_params(phi).sum().backward()
    assert torch.isfinite(phi.grad).all()
    z = torch.zeros(5, dtype=torch.float64, requires_grad=True)
    denormalise_params(z).sum().backward()
    assert torch.isfinite(z.grad).all()


def test_si_moments_and_product_match_monte_carlo():
    rng = np.random.default_rng(0)
    mean = np.array([0.2, -0.3, 0.1, -0.2, 0.4])
    a = rng.normal(size=(5, 5)) * 0.2
    cov = a @ a.T + 0.01 * np.eye(5)
    draws = denormalise_params(rng.multivariate_normal(mean, cov, size=400_000))
    m, s = si_moments(mean, cov)
    np.testing.assert_allclose(m, draws.mean(0), rtol=5e-3, atol=1e-5)
    np.testing.assert_allclose(s, draws.std(0), rtol=1e-2, atol=1e-5)
    pm, ps = product_moments(mean, cov)
    prod = draws[:, 0] * draws[:, 1]
    assert pm == pytest.approx(prod.mean(), rel=5e-3)
    assert ps == pytest.approx(prod.std(), rel=1e-2)


def test_linear_affine_is_for_linear_parameters_only():
    off, scale = linear_param_affine("com_y")
    lo, hi = PARAM_RANGES["com_y"]
    assert off + scale * -1 == pytest.approx(lo) and off + scale == pytest.approx(hi)
    with pytest.raises(ValueError, match="log space"):
        linear_param_affine("mass")
    assert set(CATALOGUE_GRID) == set(PARAM_NAMES)
