"""`identification.prior`: the prior's ranges (`PriorRanges`) and moments."""

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pydantic import ValidationError

from pushtoknow.common.params import PARAM_NAMES, denormalise_params, space_scale
from pushtoknow.identification.prior import (
    CATALOGUE_PRIOR,
    EVERYDAY_PRIOR,
    GYRATION_SPREAD,
    RANDOM_SHAPE_PRIOR,
    PriorRanges,
    footprint_prior,
    generator_prior,
    inertia_moments,
    prior_moments,
)

I_M, I_MU, I_IZ = (PARAM_NAMES.index(k) for k in ("mass", "friction", "inertia"))


@settings(max_examples=30, deadline=None)
@given(lo=st.floats(0.01, 2.0), ratio=st.floats(1.01, 10.0))
def test_the_prior_moments_are_those_of_log_x_for_x_uniform_over_the_range(lo, ratio):
    """Against a Monte-Carlo reference: E[log m] and var(log m) for m ~ U(lo, hi)."""
    hi = min(lo * ratio, 29.0)
    mean, cov = prior_moments(PriorRanges(mass=(lo, hi)))
    draws = np.log(np.random.default_rng(0).uniform(lo, hi, 400_000))
    scale = space_scale()[I_M]
    assert np.log(denormalise_params(mean)[I_M]) == pytest.approx(draws.mean(), abs=5e-3)
    assert cov[I_M, I_M] * scale**2 == pytest.approx(draws.var(), rel=2e-2)


def test_the_everyday_prior_is_wider_and_covers_real_surfaces():
    _, cat = prior_moments(CATALOGUE_PRIOR)
    mean, every = prior_moments(EVERYDAY_PRIOR)
    for i in (I_M, I_MU, I_IZ):
        assert every[i, i] > 2 * cat[i, i]
    mu, sd = (
        np.log(denormalise_params(mean)[I_MU]),
        np.sqrt(every[I_MU, I_MU]) * space_scale()[I_MU],
    )
    assert abs(np.log(0.29) - mu) / sd < 1.0  # plywood's μ is inside the everyday prior
    assert abs(np.log(0.29) - np.log(0.51)) / (np.sqrt(cat[I_MU, I_MU]) * space_scale()[I_MU]) > 2.5


def test_the_footprint_prior_takes_m_and_mu_from_the_ranges():
    square = np.array([[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]])
    for ranges in (CATALOGUE_PRIOR, EVERYDAY_PRIOR):
        mean, cov = footprint_prior(square, 0.03, ranges)
        ref_mean, ref_cov = prior_moments(ranges)
        np.testing.assert_allclose(mean[[I_M, I_MU]], ref_mean[[I_M, I_MU]])
        np.testing.assert_allclose(cov[I_M, I_M], ref_cov[I_M, I_M])


@settings(max_examples=25, deadline=None)
@given(
    m_lo=st.floats(0.05, 1.0),
    m_ratio=st.floats(1.5, 20.0),
    k=st.floats(0.01, 0.1),
    i_lo=st.floats(1e-5, 2e-3),
    i_ratio=st.floats(1.5, 1e4),
)
def test_the_inertia_moments_are_the_plate_relation_restricted_to_the_range(
    m_lo, m_ratio, k, i_lo, i_ratio
):
    """Against a brute-force quadrature on a grid: m uniform over its range, and given m,
    log I_z's density ∝ exp(−(log I_z − log m − 2 log k)² / (2 (2·spread)²)) over the range."""
    m_range, i_range = (m_lo, m_lo * m_ratio), (i_lo, i_lo * i_ratio)
    m = np.linspace(*m_range, 1500)
    b = np.linspace(np.log(i_range[0]), np.log(i_range[1]), 1500)
    z = (b[None] - np.log(m)[:, None] - 2 * np.log(k)) / (2 * GYRATION_SPREAD)
    log_p = -0.5 * z**2
    p = np.exp(log_p - log_p.max(axis=1, keepdims=True))
    p /= p.sum(axis=1, keepdims=True) * len(m)  # each m its share 1 / len(m)
    ref_mean = float(np.sum(p * b[None]))
    ref_var = float(np.sum(p * b[None] ** 2)) - ref_mean**2
    ref_cov = float(np.sum(p * np.log(m)[:, None] * b[None])) - float(np.mean(np.log(m))) * ref_mean
    mean, var, cov = inertia_moments(m_range, i_range, k)
    assert mean == pytest.approx(ref_mean, abs=0.01)
    assert var == pytest.approx(ref_var, rel=0.03, abs=1e-3)
    assert cov == pytest.approx(ref_cov, rel=0.03, abs=1e-3)


def test_a_wide_inertia_range_leaves_the_plate_relation_and_a_narrow_one_holds_i_z_inside():
    """A wide range (everyday objects'): E[log I_z] = E[log m] + 2 log k, slope 1 on log m (to
    the share of the relation beyond 0.08 kg·m²). The catalogue's
    (0.5–1.5 g·m²): a footprint whose plate would put I_z at 2.3 g·m² for the median mass keeps
    I_z's median inside the range, and log m moves it much less."""
    square = np.array([[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]])
    scale = space_scale()
    wide = PriorRanges(mass=(0.05, 5.0), inertia=(5e-6, 0.08))
    mean, cov = footprint_prior(square, 0.04, wide)
    phi = denormalise_params(mean)
    assert phi[I_IZ] == pytest.approx(phi[I_M] * 0.04**2, rel=1e-3)
    var_m = cov[I_M, I_M] * scale[I_M] ** 2
    assert cov[I_IZ, I_M] * scale[I_IZ] * scale[I_M] == pytest.approx(var_m, rel=1e-2)
    mean, cov = footprint_prior(square, 0.06, CATALOGUE_PRIOR)
    phi = denormalise_params(mean)
    assert CATALOGUE_PRIOR.inertia[0] < phi[I_IZ] < CATALOGUE_PRIOR.inertia[1]
    slope = cov[I_IZ, I_M] * scale[I_IZ] / (cov[I_M, I_M] * scale[I_M])
    assert 0 < slope < 0.5


def test_random_shapes_take_the_catalogue_prior_with_i_z_from_their_footprint():
    """Their prior before the footprint is seen is the catalogue's; after, I_z is the plate
    relation unbounded (many of their I_z lie outside the catalogue's range)."""
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.testbed.random_shapes import random_objects

    assert generator_prior(load_object_spec("catalogue:5").name) == CATALOGUE_PRIOR
    assert generator_prior(None) == CATALOGUE_PRIOR
    specs = random_objects(60, seed=4)
    assert all(generator_prior(s.name) == RANDOM_SHAPE_PRIOR for s in specs)
    for a, b in zip(prior_moments(RANDOM_SHAPE_PRIOR), prior_moments(CATALOGUE_PRIOR)):
        np.testing.assert_array_equal(a, b)
    square = np.array([[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]])
    mean, cov = footprint_prior(square, 0.06, RANDOM_SHAPE_PRIOR)
    phi = denormalise_params(mean)
    assert phi[I_IZ] == pytest.approx(phi[I_M] * 0.06**2, rel=1e-9)  # 2.1 g·m²: beyond 1.5
    scale = space_scale()
    var_m = cov[I_M, I_M] * scale[I_M] ** 2
    assert cov[I_IZ, I_M] * scale[I_IZ] * scale[I_M] == pytest.approx(var_m, rel=1e-9)
    inertia = np.array([s.params.inertia for s in specs])
    c_lo, c_hi = CATALOGUE_PRIOR.inertia
    assert np.mean((inertia < c_lo) | (inertia > c_hi)) > 0.1
    assert "plate" in RANDOM_SHAPE_PRIOR.label() and "plate" not in CATALOGUE_PRIOR.label()


@pytest.mark.parametrize(
    "kwargs, words",
    [
        ({"mass": (2.0, 1.0)}, "prior mass range 2–1"),
        ({"friction": (0.1, 3.0)}, "prior friction range 0.1–3"),
        ({"inertia": (0.0, 1e-3)}, "prior inertia range 0–0.001"),
    ],
)
def test_an_impossible_range_is_refused_naming_it(kwargs, words):
    with pytest.raises(ValidationError) as e:
        PriorRanges(**kwargs)
    assert words in str(e.value)
