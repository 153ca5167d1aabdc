"""Replays through the per-process cache of compiled scenes (`replay.compiled_simulator`) and
the pool's memory of replays run (`replay.RolloutPool`)."""

import numpy as np

from pushtoknow.common.params import ObjectParams
from pushtoknow.identification import replay
from pushtoknow.identification.replay import PushTrack, ReplayScene, simulate_track
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.random_shapes import random_object_at
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

CONFIG = SimConfig(render=False)
SPEC = random_object_at(101, 3)


def _fresh(phi: np.ndarray, track: PushTrack) -> np.ndarray:
    spec = ObjectSpec(shape=SPEC.shape, params=ObjectParams.from_array(phi), height=SPEC.height)
    sim = PushSimulator(spec, CONFIG)
    sim.reset(tuple(track.pose0))
    rec = sim.execute(track.push, np.random.default_rng(0), start=track.start)
    return np.column_stack([rec.force_clean, rec.pose])


def test_cached_replays_equal_fresh_builds_and_the_cache_stays_bounded(monkeypatch):
    monkeypatch.setattr(replay, "COMPILED_SCENES", 3)
    monkeypatch.setattr(replay, "_compiled", type(replay._compiled)())
    x_min = float(SPEC.footprint.polygon.bounds[0])
    push = Push((x_min, 0.005), 0.1, "constant", 0.02)
    sim = PushSimulator(SPEC, CONFIG)
    sim.reset()
    rec = sim.execute(push, np.random.default_rng(0))
    track = PushTrack(push, rec.pusher[0], rec.pose[0], rec.tactile[:, :2], rec.pose)
    scene = ReplayScene(shape=SPEC.shape, height=SPEC.height, sim_config=CONFIG, stop_at_rest=None)
    base = SPEC.params.as_array()
    rng = np.random.default_rng(1)
    for i in range(8):
        phi = base * np.array([rng.uniform(0.8, 1.2), rng.uniform(0.8, 1.2), 1, 1, 1])
        phi[2:4] += rng.uniform(-2e-3, 2e-3, 2) * (i % 2)  # every other one moves the CoM
        np.testing.assert_array_equal(simulate_track(scene, phi, track), _fresh(phi, track))
        assert len(replay._compiled) <= 3


def _recorded_track(push: Push) -> PushTrack:
    sim = PushSimulator(SPEC, CONFIG)
    sim.reset()
    rec = sim.execute(push, np.random.default_rng(0))
    return PushTrack(push, rec.pusher[0], rec.pose[0], rec.tactile[:, :2], rec.pose)


def test_the_pool_runs_a_replay_once_and_what_it_remembers_is_what_a_fresh_one_gives(
    monkeypatch,
):
    """A (φ, push) asked for again, in the same batch or a later one, is not replayed: the
    answer is the fresh replay's, read-only. What was observed (force, pose) is not part of
    a replay; where the pad starts and φ's last bit are. The memory stays bounded."""
    monkeypatch.setattr(replay, "REMEMBERED_REPLAYS", 3)
    x_min = float(SPEC.footprint.polygon.bounds[0])
    track = _recorded_track(Push((x_min, 0.005), 0.1, "constant", 0.02))
    scene = ReplayScene(shape=SPEC.shape, height=SPEC.height, sim_config=CONFIG, stop_at_rest=None)
    phi = SPEC.params.as_array()
    with replay.RolloutPool(1) as pool:
        (first,), (again,) = pool.run(scene, np.stack([phi, phi]), [track])
        assert pool.push_rollouts == 1 and pool.rollouts == 2
        np.testing.assert_array_equal(first, _fresh(phi, track))
        assert again is first and not first.flags.writeable
        seen_otherwise = PushTrack(track.push, track.start, track.pose0, 0 * track.force,
                                   track.pose + 1e-3)  # fmt: skip
        pool.run(scene, phi, [seen_otherwise])
        assert pool.push_rollouts == 1
        moved = PushTrack(track.push, track.start + np.array([0.0, 1e-3]), track.pose0, track.force,
                          track.pose)  # fmt: skip
        nudged = phi.copy()
        nudged[0] = np.nextafter(phi[0], 1.0)
        (m,), (n,) = pool.run_each(scene, np.stack([phi, nudged]), [[moved], [track]])
        assert pool.push_rollouts == 3
        np.testing.assert_array_equal(m, _fresh(phi, moved))
        np.testing.assert_array_equal(n, _fresh(nudged, track))
        assert len(pool._done) == 3
        pool.run(scene, phi * [1.1, 1, 1, 1, 1], [track])  # a fourth: the oldest is forgotten
        assert len(pool._done) == 3
        pool.run(scene, phi, [track])
        assert pool.push_rollouts == 5


def test_a_recorded_pad_that_starts_a_push_fast_is_not_quasi_static():
    """m·a at the start of a real push: a pad track starting at 0.1 m/s within one 10 Hz sample
    accelerates the object at 1 m/s² (dynamic); at 0.02 m/s, 0.2 m/s² (quasi-static)."""
    from pushtoknow.identification.fit import QUASI_STATIC_ACCEL, is_quasi_static

    rate = 10.0
    push = Push((0.0, 0.0), 0.0, "constant", 0.02)

    def track(speed, pad=True):
        x = speed * np.arange(11) / rate
        pad_xy = np.column_stack([x, np.zeros_like(x)]) if pad else None
        return PushTrack(
            push, np.zeros(2), np.zeros(3), np.zeros((11, 2)), np.zeros((11, 3)), pad_xy
        )

    assert is_quasi_static(track(0.02, pad=False), rate)
    assert is_quasi_static(track(0.02), rate)
    assert not is_quasi_static(track(0.1), rate)
    assert 0.02 * rate < QUASI_STATIC_ACCEL < 0.1 * rate
    release = Push((0.0, 0.0), 0.0, "release", 0.4)
    assert not is_quasi_static(PushTrack(release, *list(vars(track(0.0)).values())[1:]), rate)


def test_a_com_by_a_traced_sliver_is_moved_where_the_supports_carry_it():
    """A square with a 2 mm sliver (as a traced outline can have): the CoM near the sliver's
    part of the convex hull is moved where supports lie, and the scene builds."""
    from shapely.geometry import Point, Polygon

    from pushtoknow.identification.replay import feasible
    from pushtoknow.testbed.scene import mass_layout
    from pushtoknow.testbed.shapes import footprint_from_shape

    raw = np.array([(-0.05, -0.05), (0.05, -0.05), (0.05, 0.05), (0.0, 0.05), (0.1, 0.1),
                    (-0.05, 0.05)])  # fmt: skip
    c = Polygon(raw).centroid
    verts = raw - [c.x, c.y]
    shape = {"type": "polygon", "vertices": verts.tolist()}
    fp = footprint_from_shape(shape)
    com = np.array([0.06, 0.062]) - [c.x, c.y]  # inside the hull, by the sliver
    phi = np.array([0.5, 0.5, *com, 1e-3])
    assert fp.com_region(0.003).contains(Point(*com))
    moved, dist, _ = feasible(phi, fp)
    assert dist > 0
    spec = ObjectSpec(shape=shape, params=ObjectParams.from_array(moved), height=0.02)
    layout = mass_layout(spec, CONFIG)
    np.testing.assert_allclose(layout.loads @ layout.points, moved[2:4], atol=1e-5)
