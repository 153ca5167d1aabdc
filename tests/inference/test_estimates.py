"""Parameter estimates from Gaussian beliefs: never physically impossible, asymmetric intervals."""

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import PARAM_NAMES, normalise_params
from pushtoknow.inference.session import belief_to_estimate

POSITIVE = [PARAM_NAMES.index(k) for k in ("mass", "friction", "inertia")]


@settings(max_examples=200, deadline=None)
@given(
    mean=st.lists(st.floats(-20.0, 20.0), min_size=5, max_size=5),
    log_std=st.lists(st.floats(-8.0, 1.5), min_size=5, max_size=5),
    corr_seed=st.integers(0, 2**16),
)
def test_extreme_beliefs_never_give_an_impossible_estimate(mean, log_std, corr_seed):
    std = np.exp(log_std)
    a = np.random.default_rng(corr_seed).normal(size=(5, 5))
    corr = np.corrcoef(a @ a.T + np.eye(5))
    cov = corr * np.outer(std, std)
    e = belief_to_estimate(1, torch.tensor(mean), torch.tensor(cov))
    assert np.isfinite(e.mean).all() and (e.mean[POSITIVE] > 0).all()
    lo, hi = e.interval(0.9)
    assert (lo[POSITIVE] > 0).all() and (lo <= hi).all()


def test_interval_is_asymmetric_in_si_and_holds_its_level():
    mean = torch.zeros(5, dtype=torch.float64)
    cov = torch.eye(5, dtype=torch.float64) * 0.25
    e = belief_to_estimate(1, mean, cov)
    lo, hi = e.interval(0.9)
    m = PARAM_NAMES.index("mass")
    median = np.sqrt(0.2 * 1.2)  # the centre of the log range
    assert hi[m] - median > median - lo[m]  # log-normal: longer upper tail
    assert lo[m] < e.mean[m] < hi[m]
    # zscore ⇔ interval: the truth at an interval end has |z| = 1.645
    truth = e.mean.copy()
    truth[m] = hi[m]
    np.testing.assert_allclose(abs(e.zscore(truth)[m]), 1.6448536, rtol=1e-6)
    # truths drawn from the belief fall in the 90% interval 90% of the time
    rng = np.random.default_rng(0)
    from pushtoknow.common.params import denormalise_params

    draws = denormalise_params(rng.normal(0.0, 0.5, size=(20000, 5)))
    inside = (draws >= lo) & (draws <= hi)
    np.testing.assert_allclose(inside.mean(0), 0.9, atol=0.01)
    assert np.allclose(normalise_params(lo)[m], -1.6448536 * 0.5)


def test_reported_com_is_kept_a_margin_inside_even_in_a_notch():
    from shapely.geometry import Point, Polygon

    from pushtoknow.inference.session import keep_inside

    ell = np.array([[0, 0], [0.1, 0], [0.1, 0.04], [0.04, 0.04], [0.04, 0.1], [0, 0.1]]) - 0.03
    poly = Polygon(ell)
    margin = 0.009
    inside = np.array([0.0, -0.01])  # deep inside: unchanged
    np.testing.assert_array_equal(keep_inside(inside, ell, margin), inside)
    for p in ([0.03, 0.03], [0.012, 0.012], [0.2, -0.2], [-0.029, 0.0]):  # notch, edge, far
        q = keep_inside(np.array(p), ell, margin)
        assert poly.contains(Point(*q))
        assert poly.exterior.distance(Point(*q)) >= margin - 1e-6
    thin = np.array([[0, 0], [0.01, 0], [0.01, 0.001], [0, 0.001]])
    np.testing.assert_allclose(keep_inside(np.array([1.0, 1.0]), thin, margin), [0.005, 0.0005])
