import numpy as np
import pytest

from pushtoknow.baselines.random_forest import (
    FEATURE_NAMES,
    ForestBaseline,
    ForestConfig,
    mask_shape_descriptors,
    push_features,
)


def straight_push(theta0=0.0):
    T = 21
    pose = np.zeros((T, 3))
    pose[:, 0] = np.linspace(0, 0.1, T)
    pose[:, 2] = theta0
    tactile = np.zeros((T, 3))
    tactile[1:, 0] = 3.0
    tactile[1:, 2] = 1.0
    action = np.array([-0.05, 0.0, 0.0, 0.02, 0])
    return pose, tactile, action


def test_push_features_by_hand():
    pose, tactile, action = straight_push()
    f = dict(zip(FEATURE_NAMES, push_features(pose, tactile, action, 0.01, (0.05, 0.05))))
    assert f["disp_along"] == pytest.approx(0.1)
    assert f["disp_across"] == pytest.approx(0.0)
    assert f["rotation"] == 0.0
    assert f["force_mean"] == pytest.approx(3.0)
    assert f["force_along"] == pytest.approx(3.0)
    assert f["contact_share"] == pytest.approx(20 / 21)
    assert f["contact_x"] == pytest.approx(-0.05)
    assert f["push_cos"] == pytest.approx(1.0)


def test_features_are_in_the_object_frame():
    # The same push on an object turned by 90°: contact and direction in the object frame move.
    pose, tactile, action = straight_push(theta0=np.pi / 2)
    f = dict(zip(FEATURE_NAMES, push_features(pose, tactile, action, 0.01, (0.05, 0.05))))
    assert f["contact_y"] == pytest.approx(0.05)
    assert f["push_sin"] == pytest.approx(-1.0)


def test_mask_descriptors():
    m = np.zeros((64, 64), bool)
    m[20:30, 10:50] = True  # 40 × 10 px
    area, (a, b) = mask_shape_descriptors(m, 0.01)
    assert area == pytest.approx(400 * 1e-4)
    assert a > 3 * b


def test_forest_learns_a_learnable_map_and_aggregates():
    rng = np.random.default_rng(0)
    X = rng.normal(size=(400, 6))
    Y = np.column_stack([X[:, 0], X[:, 1] ** 2, X[:, 2] - X[:, 3], 0.1 * X[:, 4], X[:, 5]])
    rf = ForestBaseline(ForestConfig(n_estimators=50)).fit(X[:300], Y[:300])
    m, s = rf.predict_pushes(X[300:])
    err = np.sqrt(((m - Y[300:]) ** 2).mean(0))
    prior = Y[:300].std(0)
    assert (err < 0.7 * prior).all()
    assert (s > 0).all()
    mean_k, std_k = rf.predict_object(X[300:305])
    assert np.allclose(mean_k[0], m[0]) and np.allclose(mean_k[-1], m[:5].mean(0))
    assert std_k.shape == (5, 5)
