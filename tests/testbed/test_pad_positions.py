"""`pad_positions` reproduces the pad track the simulator records."""

import math

import numpy as np
import pytest

from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.push import PAD_CLEARANCE, Push, pad_positions
from pushtoknow.testbed.sim_config import PadConfig, PushConfig, SimConfig

FAST = SimConfig(push=PushConfig(horizon=1.5), render=False)
# catalogue:412 is a triangle with a flat face at x = FACE_X (object frame), spanning y ∈ [-0.084,
# 0.042]: a push at (FACE_X, 0) along -x is normal to it.
FACE_X = 0.0588333333333333
# The recorded pad is the commanded one after one physics step (dt = 4 ms) of semi-implicit
# integration: off by (F / m_pad) dt² from the contact force (F ≈ 6 N on the 50 kg pad: 2e-6 m)
# and, for a release push, by ½ a dt² (a ≤ 20 m/s² while the pad stops: 1.6e-4 m).
CONSTANT_TOL = 1e-5
RELEASE_TOL = 2e-4


def _record(push: Push):
    ex = SimulatedExecutor(load_object_spec("catalogue:412"), FAST, seed=0, randomise_pose=False)
    try:
        return ex.execute(push)
    finally:
        ex.close()


def test_constant_push_matches_record_with_nominal_start():
    push = Push((FACE_X, 0.0), math.pi, "constant", 0.03)
    rec = _record(push)
    pads = pad_positions(push, rec.time, FAST.push)
    assert pads.shape == rec.pusher.shape == (16, 2)
    want = PadConfig().radius + FAST.push.approach_gap
    np.testing.assert_allclose(pads[0], [FACE_X + want, 0.0], atol=1e-9)
    np.testing.assert_allclose(pads, rec.pusher, atol=CONSTANT_TOL)


def test_oblique_push_matches_record_given_its_start():
    push = Push((FACE_X, 0.01), math.pi - 0.6, "constant", 0.02)
    rec = _record(push)
    pads = pad_positions(push, rec.time, FAST.push, start=rec.pusher[0])
    np.testing.assert_allclose(pads, rec.pusher, atol=CONSTANT_TOL)
    # the nominal start is off here (the simulator backs off along an oblique line)
    nominal = pad_positions(push, rec.time, FAST.push)
    assert np.abs(nominal[0] - rec.pusher[0]).max() > 1e-3


def test_release_push_matches_record():
    cfg = FAST.push
    push = Push((FACE_X, 0.0), math.pi, "release", 0.3)
    rec = _record(push)
    pads = pad_positions(push, rec.time, cfg)
    np.testing.assert_allclose(
        pads[0], [FACE_X + PadConfig().radius + PAD_CLEARANCE, 0.0], atol=1e-12
    )
    np.testing.assert_allclose(pads, rec.pusher, atol=RELEASE_TOL)
    # the pad stops once decelerated: last samples identical
    np.testing.assert_allclose(pads[-1], pads[-2])


def test_unknown_profile_rejected():
    with pytest.raises(ValueError, match="profile"):
        pad_positions(Push((0.0, 0.0), 0.0, "wobble"), np.zeros(1), PushConfig())


def test_a_recorded_pad_track_replays_the_push_it_came_from():
    """Driving the pad along a constant push's own recorded track (linear between samples)
    reproduces that push: same sample count, same pad track, poses within 0.2 mm / 0.2°."""
    push = Push((FACE_X, 0.01), math.pi - 0.3, "constant", 0.03)
    rec = _record(push)
    ex = SimulatedExecutor(load_object_spec("catalogue:412"), FAST, seed=0, randomise_pose=False)
    try:
        ex.sim.reset(tuple(rec.pose[0]))
        again = ex.sim.execute(push, np.random.default_rng(0), render=False, pad_track=rec.pusher)
    finally:
        ex.close()
    assert again.pose.shape == rec.pose.shape
    np.testing.assert_allclose(again.pusher, rec.pusher, atol=CONSTANT_TOL)
    np.testing.assert_allclose(again.pose[:, :2], rec.pose[:, :2], atol=2e-4)
    np.testing.assert_allclose(again.pose[:, 2], rec.pose[:, 2], atol=math.radians(0.2))
    assert np.abs(rec.pose[-1, :2] - rec.pose[0, :2]).max() > 0.01  # it did push the object


def test_a_pad_track_of_the_wrong_shape_or_not_finite_is_refused():
    ex = SimulatedExecutor(load_object_spec("catalogue:412"), FAST, seed=0, randomise_pose=False)
    push = Push((FACE_X, 0.0), math.pi, "constant", 0.03)
    try:
        for bad, msg in [(np.zeros((1, 2)), "must be"), (np.zeros((5, 3)), "must be")]:
            with pytest.raises(ValueError, match=msg):
                ex.sim.execute(push, np.random.default_rng(0), render=False, pad_track=bad)
        track = np.zeros((5, 2))
        track[2, 0] = np.nan
        with pytest.raises(ValueError, match="non-finite"):
            ex.sim.execute(push, np.random.default_rng(0), render=False, pad_track=track)
    finally:
        ex.close()


def _replay(push, rec, **kw):
    ex = SimulatedExecutor(load_object_spec("catalogue:412"), FAST, seed=0, randomise_pose=False)
    try:
        ex.sim.reset(tuple(rec.pose[0]))
        return ex.sim.execute(push, np.random.default_rng(0), render=False, **kw)
    finally:
        ex.close()


def test_a_fine_pad_track_at_the_sample_times_replays_as_the_track_itself():
    """`pad_fine` rows at the samples' own times describe the same piecewise-linear pad as
    `pad_track`: the same push, to rounding (which pushing grows to ~1e-6 over a push)."""
    push = Push((FACE_X, 0.01), math.pi - 0.3, "constant", 0.03)
    rec = _record(push)
    fine = np.column_stack([rec.time, rec.pusher])
    coarse = _replay(push, rec, pad_track=rec.pusher)
    again = _replay(push, rec, pad_track=rec.pusher, pad_fine=fine)
    np.testing.assert_allclose(again.pusher, coarse.pusher, atol=1e-9)
    np.testing.assert_allclose(again.pose, coarse.pose, atol=1e-5)
    np.testing.assert_allclose(again.force_clean, coarse.force_clean, atol=1e-3)


def test_a_pad_that_stops_between_samples_follows_its_fine_track():
    """A pad stopping at 0.65 s: linear between 10 Hz samples it creeps on until 0.7 s and
    keeps pushing through sample 7's window; on its fine track it stops at 0.65 s, so the
    object is pushed for half that window, with about half the mean force."""
    push = Push((FACE_X, 0.0), math.pi, "constant", 0.03)
    rec = _record(push)
    start, u = rec.pusher[0], np.array([-1.0, 0.0])
    t_fine = np.arange(0.0, 1.5 + 1e-9, 0.004)
    travel = 0.05 * np.clip(t_fine - 0.1, 0.0, 0.55)  # 50 mm/s from 0.1 s to 0.65 s
    fine = np.column_stack([t_fine, start + travel[:, None] * u])
    coarse_track = start + (0.05 * np.clip(rec.time - 0.1, 0.0, 0.55))[:, None] * u
    coarse = _replay(push, rec, pad_track=coarse_track)
    stepped = _replay(push, rec, pad_track=coarse_track, pad_fine=fine)
    np.testing.assert_allclose(stepped.pusher, coarse.pusher, atol=1e-5)  # same at samples
    f_coarse, f_fine = (np.linalg.norm(r.force_clean[7]) for r in (coarse, stepped))
    steady = np.linalg.norm(coarse.force_clean[5])
    assert f_coarse == pytest.approx(steady, rel=0.25)
    assert f_fine < 0.75 * f_coarse


def test_a_bad_fine_pad_track_is_refused():
    ex = SimulatedExecutor(load_object_spec("catalogue:412"), FAST, seed=0, randomise_pose=False)
    push = Push((FACE_X, 0.0), math.pi, "constant", 0.03)
    track = np.zeros((5, 2))
    go = np.random.default_rng(0)
    try:
        with pytest.raises(ValueError, match="needs pad_track"):
            ex.sim.execute(push, go, render=False, pad_fine=np.zeros((3, 3)))
        with pytest.raises(ValueError, match="must be"):
            ex.sim.execute(push, go, render=False, pad_track=track, pad_fine=np.zeros((3, 2)))
        backwards = np.array([[0.0, 0, 0], [0.2, 0, 0], [0.1, 0, 0]])
        with pytest.raises(ValueError, match="increasing"):
            ex.sim.execute(push, go, render=False, pad_track=track, pad_fine=backwards)
    finally:
        ex.close()
