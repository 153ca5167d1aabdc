import numpy as np
import pytest

from pushtoknow.common.params import CATALOGUE_GRID, PARAM_NAMES
from pushtoknow.evaluation.metrics import (
    PriorMeanPredictor,
    coverage,
    gaussian_zscores,
    impossible_estimates,
    nrmse,
    product_nrmse,
)
from pushtoknow.testbed.objects import NOVEL_SHAPES
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape


def test_nrmse_by_hand():
    truth = np.zeros((2, 5))
    pred = np.zeros((2, 5))
    pred[:, 0] = [0.1, -0.1]  # mass RMSE 0.1 over a 1.0 kg range
    pred[0, 4] = 2e-4  # inertia RMSE sqrt(2e-8) over 1e-3
    r = nrmse(pred, truth)
    assert r["mass"] == pytest.approx(0.1)
    assert r["inertia"] == pytest.approx(np.sqrt(0.5) * 2e-4 / 1e-3)
    assert r["friction"] == 0.0
    assert r["overall"] == pytest.approx((r["mass"] + r["inertia"]) / 5)
    with pytest.raises(ValueError, match="shape"):
        nrmse(pred[:, :4], truth[:, :4])


def test_prior_mean_on_grid_is_about_0_4():
    rng = np.random.default_rng(0)
    grid = np.stack([rng.choice(CATALOGUE_GRID[k], 5000) for k in PARAM_NAMES], 1)
    prior = PriorMeanPredictor().fit(grid)
    m, _ = prior.predict(len(grid))
    r = nrmse(m, grid)
    for k in PARAM_NAMES:
        assert 0.3 < r[k] < 0.45  # docs/DESIGN.md §9: ≈0.37–0.41 on the grid


def test_coverage_of_calibrated_gaussian():
    rng = np.random.default_rng(1)
    truth = rng.normal(size=(20000, 5))
    zero, one = np.zeros_like(truth), np.ones_like(truth)
    cov = coverage(gaussian_zscores(zero, one, truth), 0.9)
    assert cov["overall"] == pytest.approx(0.9, abs=0.01)
    assert coverage(gaussian_zscores(zero, 0.1 * one, truth))["mass"] < 0.2


def test_impossible_estimates_are_counted():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])  # 9 cm square
    good = [0.5, 0.5, 0.01, -0.01, 1e-3]
    bad = [
        [-0.1, 0.5, 0.0, 0.0, 1e-3],  # negative mass
        [0.5, 0.5, 0.0, 0.0, 0.0],  # zero inertia
        [0.5, 0.5, 0.06, 0.0, 1e-3],  # CoM outside the footprint
        [0.2, 0.5, 0.0, 0.0, 2e-3],  # I_z above 0.2 kg · (0.0636 m)² = 8.1e-4
        [0.5, np.nan, 0.0, 0.0, 1e-3],
    ]
    mean = np.array([[good, *bad], [good] * 6])
    assert impossible_estimates(mean, [fp, fp]) == len(bad)


def test_a_com_in_a_notch_is_possible_beyond_the_hull_is_not():
    fp = footprint_from_shape(NOVEL_SHAPES["l_shape"])  # its notch is around (+2, +2) cm
    notch, beyond = [0.5, 0.5, 0.02, 0.02, 1e-3], [0.5, 0.5, 0.05, 0.05, 1e-3]
    assert not fp.contains(notch[2:4])
    assert impossible_estimates(np.array([[notch, beyond]]), [fp]) == 1


def test_product_nrmse_zero_when_product_right():
    truth = np.array([[0.5, 0.6, 0, 0, 1e-3]])
    pred = np.array([[0.6, 0.5, 0, 0, 1e-3]])  # wrong m and μ, right μ·m
    assert product_nrmse(pred, truth) == pytest.approx(0.0, abs=1e-12)


def test_estimates_outside_their_interval_are_counted_once_each():
    from pushtoknow.evaluation.metrics import estimates_outside_interval

    lower = np.tile([0.4, 0.4, -0.01, -0.01, 8e-4], (2, 3, 1))
    upper = np.tile([0.6, 0.6, 0.01, 0.02, 1.2e-3], (2, 3, 1))
    mean = 0.5 * (lower + upper)
    assert estimates_outside_interval(mean, lower, upper) == 0
    mean[0, 1, 0] = 0.7  # mass above its interval ...
    mean[0, 1, 3] = -0.05  # ... and c_y below its own: one estimate, counted once
    mean[1, 2, 4] = 7e-4  # I_z below
    assert estimates_outside_interval(mean, lower, upper) == 2


def test_a_mean_at_a_bound_is_inside_its_interval():
    from pushtoknow.evaluation.metrics import estimates_outside_interval

    lower = np.array([[0.4, 0.4, -0.01, -0.01, 8e-4]])
    upper = np.array([[0.6, 0.6, 0.01, 0.02, 1.2e-3]])
    assert estimates_outside_interval(lower, lower, upper) == 0
    assert estimates_outside_interval(upper, lower, upper) == 0
    rounded = upper * (1 + 1e-12)  # rounding past the bound: inside
    assert estimates_outside_interval(rounded, lower, upper) == 0
    beyond = upper.copy()
    beyond[0, 2] += 1e-6  # 1 µm past c_x's upper bound: outside
    assert estimates_outside_interval(beyond, lower, upper) == 1
    nan = lower.copy()
    nan[0, 1] = np.nan  # lies in no interval
    assert estimates_outside_interval(nan, lower, upper) == 1
    with pytest.raises(ValueError, match="shape"):
        estimates_outside_interval(lower, lower[:, :4], upper)
