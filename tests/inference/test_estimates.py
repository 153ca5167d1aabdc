"""Parameter estimates from Gaussian beliefs: never physically impossible, asymmetric intervals."""

import numpy as np
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import PARAM_NAMES, normalise_params
from pushtoknow.inference.estimator import belief_to_estimate

POSITIVE = [PARAM_NAMES.index(k) for k in ("mass", "friction", "inertia")]


@settings(max_examples=200, deadline=None)
@given(
    mean=st.lists(st.floats(-20.0, 20.0), min_size=5, max_size=5),
    log_std=st.lists(st.floats(-8.0, 1.0), min_size=5, max_size=5),  # wider: refused
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


def test_a_com_belief_outside_the_hull_is_reported_inside_its_interval_and_the_hull():
    """An L, its CoM belief centred in the notch and beyond the outline (the learned filter's
    two reported failures): the estimate's CoM mean lies in the hull less the margin and inside
    its own interval."""
    from shapely.geometry import Point, Polygon

    from pushtoknow.common.estimate import com_region

    ell = [[-0.03875, -0.03875], [0.06125, -0.03875], [0.06125, 0.00125], [0.00125, 0.00125],
           [0.00125, 0.06125], [-0.03875, 0.06125]]  # fmt: skip
    region = com_region(np.array(ell), 0.003)
    for com in ([0.008, 0.008], [0.09, -0.01], [-0.0039, 0.0]):
        mean = normalise_params(np.array([0.6, 0.5, *com, 8e-4]))
        cov = np.diag([0.1, 0.1, 0.4, 0.4, 0.1])
        e = belief_to_estimate(5, torch.tensor(mean), torch.tensor(cov), com_region=region)
        lo, hi = e.interval()
        assert np.all((lo <= e.mean) & (e.mean <= hi))
        assert Polygon(region).buffer(1e-9).contains(Point(*e.mean[2:4]))
        assert e.as_dict()["com_x"]["interval90"] == [lo[2], hi[2]]
