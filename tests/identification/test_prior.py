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
    PriorRanges,
    footprint_prior,
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
