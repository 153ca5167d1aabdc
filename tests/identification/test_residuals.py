"""Residual weighting of `identification.residuals`: a resting object's repeated pose counts
once; AR(1) pose errors are whitened exactly."""

from pathlib import Path

import numpy as np
import pytest
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


def test_a_contact_offset_moves_every_pad_track_along_the_push():
    """`ReplayResiduals.shifted` moves the start, the pad track and the fine pad track (a real
    pusher's) by the offset along the push, keeping the fine track's times."""
    import types

    from pushtoknow.identification.replay import PushTrack
    from pushtoknow.identification.residuals import ReplayResiduals
    from pushtoknow.testbed.push import Push

    push = Push((0.05, 0.0), np.pi / 2, "constant", 0.02)  # along +y
    pad = np.array([[0.0, 0.0], [0.0, 0.002]])
    fine = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.001], [0.1, 0.0, 0.002]])
    track = PushTrack(push, np.zeros(2), np.zeros(3), np.zeros((2, 2)), np.zeros((2, 3)), pad, fine)
    (moved,) = ReplayResiduals.shifted(types.SimpleNamespace(tracks=[track]), np.array([0.003]))
    np.testing.assert_allclose(moved.start, [0.0, 0.003], atol=1e-15)
    np.testing.assert_allclose(moved.pad, pad + np.array([0.0, 0.003]), atol=1e-15)
    np.testing.assert_allclose(moved.pad_fine[:, 1:], fine[:, 1:] + [0.0, 0.003], atol=1e-15)
    np.testing.assert_array_equal(moved.pad_fine[:, 0], fine[:, 0])
    np.testing.assert_array_equal(track.pad_fine, fine)  # the original is left as it was


def test_a_probe_of_one_push_s_contact_offset_replays_that_push_only():
    """The forward-difference probe of push k's contact offset changes nothing the other
    pushes' replays depend on: only push k is replayed again, and the residuals equal those
    of a pool that replays everything afresh."""
    from pushtoknow.common.params import normalise_params
    from pushtoknow.identification.fit import tracks_from_records
    from pushtoknow.identification.prior import fit_transform
    from pushtoknow.identification.replay import ReplayScene, RolloutPool
    from pushtoknow.identification.residuals import ReplayResiduals
    from pushtoknow.identification.synthetic import simulate_pushes
    from pushtoknow.testbed.random_shapes import random_object_at
    from pushtoknow.testbed.sim_config import SimConfig

    spec = random_object_at(101, 5)
    config = SimConfig(render=False)
    tracks = tracks_from_records(simulate_pushes(spec, ["release", "release", "release"]), config)
    scene = ReplayScene(spec.shape, spec.height, config)
    sigmas = np.array([0.1, 0.1, 2e-3, 2e-3, 0.04])
    u = np.append(fit_transform() @ normalise_params(spec.params.as_array()), [0.2, -0.1, 0.3])
    probe = u.copy()
    probe[6] += 0.3
    with RolloutPool(1) as pool, RolloutPool(1) as fresh:
        res = ReplayResiduals(scene, tracks, pool, sigmas)
        r_u = res.residuals(u)
        assert pool.push_rollouts == 3
        r_probe = res.residuals(probe)
        assert pool.push_rollouts == 4
        alone = ReplayResiduals(scene, tracks, fresh, sigmas)
        np.testing.assert_array_equal(r_probe, alone.residuals(probe))
    changed = np.abs(r_probe - r_u)[0, : res.n_samples].reshape(-1, 5)
    lengths = np.cumsum([0, *res.push_lengths])
    assert changed[lengths[1] : lengths[2]].max() > 0  # the probed push moved
    assert changed[: lengths[1]].max() == 0 and changed[lengths[2] :].max() == 0


def test_a_real_pusher_holding_the_object_at_rest_carries_no_force_residual():
    """Replayed along a recorded pad, the force samples up to and including the object's
    breakaway and after it has come to its final rest weigh 0 (static friction: a preload, the
    breakaway, a probe left pressed on it), whether it slides or turns; an object that never
    moves leaves no force sample; replayed by its profile, none is dropped."""
    from pushtoknow.identification.replay import PushTrack
    from pushtoknow.identification.residuals import resting_force_weights
    from pushtoknow.testbed.push import Push

    push = Push((0.05, 0.0), np.pi, "constant", 0.02)
    force = np.array([[0.7, 0.0], [0.7, 0.1], [3.0, 0.2], [2.0, 0.0], [2.1, 0.0], [1.5, 0.0]])
    force = np.vstack([force, [[1.4, 0.0], [1.4, 0.0]]])  # preloaded, and pressed at the end
    pose = np.zeros((8, 3))
    pose[1, 0] = 2e-4  # within the tolerance: still at rest
    pose[2:, 0] = [0.003, 0.008, 0.013, 0.016, 0.0162, 0.0161]  # at rest from sample 5
    pad = np.zeros((8, 2))
    real = PushTrack(push, np.zeros(2), np.zeros(3), force, pose, pad)
    w = resting_force_weights(real)
    np.testing.assert_array_equal(w[:, 0], [0, 0, 0, 1, 1, 1, 0, 0])
    np.testing.assert_array_equal(w[:, 1], w[:, 0])
    turning = np.zeros((8, 3))
    turning[3:, 2] = [0.01, 0.02, 0.03, 0.04, 0.05]  # a pure rotation, moving to the end
    w = resting_force_weights(PushTrack(push, np.zeros(2), np.zeros(3), force, turning, pad))
    np.testing.assert_array_equal(w[:, 0], [0, 0, 0, 0, 1, 1, 1, 1])
    simulated = PushTrack(push, np.zeros(2), np.zeros(3), force, pose, None)
    np.testing.assert_array_equal(resting_force_weights(simulated), 1.0)
    still = PushTrack(push, np.zeros(2), np.zeros(3), force, np.zeros((8, 3)), pad)
    np.testing.assert_array_equal(resting_force_weights(still), 0.0)


def test_the_real_hex_pressed_before_it_moves_carries_no_force_residual():
    """The MIT Push hex's first push on ABS: the probe presses on it with about 4 N while
    nothing moves (docs/DESIGN.md §11). Those samples, and only samples with the object at
    rest, weigh 0; the sliding ones in between all count."""
    from pushtoknow.evaluation.real_benchmark import find_real_objects
    from pushtoknow.identification import fit
    from pushtoknow.identification.residuals import BREAKAWAY_MOTION, resting_force_weights

    folder = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets"
    folder = folder / "mit-push-abs" / "hex"
    if not folder.is_dir():
        pytest.skip(f"{folder} not found (real-data test)")
    (obj,), _ = find_real_objects(folder)
    i = next(k for k, f in enumerate(obj.files) if "s=0.500_t=-1.396" in str(f))
    (track,) = fit.tracks_from_records([obj.records[i]], obj.sim_config)
    w = resting_force_weights(track)[:, 0]
    pose = np.asarray(track.pose)
    still = np.max(np.abs(pose - pose[0]), axis=1) <= BREAKAWAY_MOTION
    pressed = still & (np.linalg.norm(track.force, axis=1) > 3.0)
    assert pressed[1:].sum() >= 1  # a sample after the first, pressed and still
    assert np.all(w[pressed] == 0.0)
    settled = np.max(np.abs(pose - pose[-1]), axis=1) <= BREAKAWAY_MOTION
    sliding = np.flatnonzero(~still & ~settled)[1:]  # after the breakaway, before the stop
    assert len(sliding) >= 2
    assert np.all(w[sliding] == 1.0)
