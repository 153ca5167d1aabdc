"""MIT Push reader: synthetic files with exact answers, and the three real sample files."""

from __future__ import annotations

import json
import math
import re
from pathlib import Path

import h5py
import numpy as np
import pytest

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.errors import DatasetError, ObjectSpecError
from pushtoknow.common.params import GRAVITY
from pushtoknow.datasets.mit_push import (
    CONTACT_FORCE_THRESHOLD,
    MIT_SHAPES,
    PUSHER_RADIUS,
    MitPushMeta,
    MitPushWarning,
    dataset_to_centroid_pose,
    estimate_friction,
    find_mit_push_files,
    iter_mit_push,
    load_mit_streams,
    mit_object,
    mit_polygon,
    parse_mit_filename,
    read_mit_push,
)

SAMPLE_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets" / "mit-push-sample"
CENTRE_PUSH = "motion_surface=plywood_shape=rect1_a=0_v=100_i=1.000_s=0.500_t=0.000.json"
T0 = 1_476_729_000.0  # Unix s, like the real files
RECT1_MASS = 0.8374  # kg


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------
def _name(
    shape="rect1", surface="plywood", a="0", v="50", i="1.000", s="0.500", t="0.000", ext="json"
) -> str:
    return f"motion_surface={surface}_shape={shape}_a={a}_v={v}_i={i}_s={s}_t={t}.{ext}"


def _write(path: Path, streams: dict[str, np.ndarray]) -> Path:
    """Write streams with the dataset's schema (.json: lists of rows, .h5: N×4 datasets)."""
    if path.suffix == ".json":
        path.write_text(json.dumps({k: np.asarray(v).tolist() for k, v in streams.items()}))
    else:
        with h5py.File(path, "w") as h5:
            for k, v in streams.items():
                h5.create_dataset(k, data=np.asarray(v))
    return path


def _times(start: float, stop: float, rate: float, rng=None) -> np.ndarray:
    """Relative sample times in [start, stop] at `rate`, optionally jittered (still increasing)."""
    n = math.floor((stop - start) * rate + 1e-9) + 1
    k = np.arange(n, dtype=np.float64)
    if rng is not None:
        k[1:-1] += rng.uniform(-0.3, 0.3, n - 2)
    return start + k / rate


def _linear_streams(rng, theta0=0.4, omega=0.3, v=(0.05, -0.02), force=(1.0, 0.5)):
    """Object and pusher moving linearly in time; raw yaw wrapped like the real files.

    Streams start at different times, run at different irregular rates; the reading on the
    probe is minus the force on the object.
    """
    t_tip = _times(0.013, 2.31, 250, rng)
    t_obj = _times(0.0, 2.27, 180, rng)
    t_ft = _times(0.021, 2.4, 500, rng)
    vx, vy = v
    tip = np.stack([T0 + t_tip, 0.30 + vx * t_tip, 0.01 + vy * t_tip, 0 * t_tip], 1)
    obj = np.stack(
        [T0 + t_obj, 0.35 + vx * t_obj, 0.012 + vy * t_obj, wrap_angle(theta0 + omega * t_obj)], 1
    )
    ft = np.stack([T0 + t_ft, -force[0] + 0 * t_ft, -force[1] + 0 * t_ft, 0 * t_ft], 1)
    exact = {
        "obj": lambda t: np.stack([0.35 + vx * t, 0.012 + vy * t, theta0 + omega * t], 1),
        "tip": lambda t: np.stack([0.30 + vx * t, 0.01 + vy * t], 1),
    }
    return {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft}, exact


def _tare_streams(offset=(-1.5, -0.5), force=(0.3 * RECT1_MASS * GRAVITY, 0.0)):
    """Pusher at rest 0–0.5 s, pushing +x at 0.05 m/s 0.5–1.5 s, at rest 1.5–2 s.

    The probe reads offset − force while pushing and offset at rest; ft samples sit halfway
    between the 10 Hz window edges so each window holds exactly 50 of them. The ft stream
    starts 0.1 s before the others, so window 0, [-0.1, 0) s, holds raw samples too.
    """
    t = _times(0.0, 2.0, 250)
    x = 0.30 + 0.05 * np.clip(t - 0.5, 0.0, 1.0)
    tip = np.stack([T0 + t, x, 0 * t, 0 * t], 1)
    obj = np.stack([T0 + t, x + 0.045 + PUSHER_RADIUS, 0 * t, 0.2 + 0 * t], 1)
    tf = -0.1 + (np.arange(1150) + 0.5) / 500  # -0.099 .. 2.199
    pushing = (tf >= 0.5) & (tf < 1.5)
    fx = offset[0] - np.where(pushing, force[0], 0.0)
    fy = offset[1] - np.where(pushing, force[1], 0.0)
    ft = np.stack([T0 + tf, fx, fy, 0 * tf], 1)
    return {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft}


@pytest.fixture
def mit_sample_dir() -> Path:
    if not SAMPLE_DIR.is_dir():
        pytest.skip(f"../shared/datasets/mit-push-sample not found: {SAMPLE_DIR} (real-data tests)")
    return SAMPLE_DIR.resolve()


@pytest.fixture(params=["json", "h5"])
def mit_ext(request) -> str:
    return request.param


# ------------------------------------------------------------------------------------------
# file names
# ------------------------------------------------------------------------------------------
def test_parse_filename():
    meta = parse_mit_filename("/x/" + _name(a="0", v="100", i="1.000", s="0.250", t="0.698"))
    assert meta == MitPushMeta("plywood", "rect1", 0.0, 0.1, 1.0, 0.25, 0.698)
    assert parse_mit_filename(_name(shape="tri3", surface="abs", ext="h5", v="20")).speed == 0.02


@pytest.mark.parametrize(
    "name",
    [
        "push_rect1.json",
        "motion_surface=plywood_shape=rect1_a=0_v=fast_i=1.000_s=0.500_t=0.000.json",
        "motion_surface=plywood_shape=rect1_a=0_v=100_i=1.000_s=0.500.json",
        "motion_surface=plywood_shape=rect1_a=0_v=100_i=1.000_s=0.500_t=0.000.csv",
        "motion_surface=plywood_shape=rect1_v=100_a=0_i=1.000_s=0.500_t=0.000.json",
    ],
)
def test_bad_filename_names_the_file(name):
    with pytest.raises(DatasetError) as e:
        parse_mit_filename(Path("/data") / name)
    assert name in str(e.value)
    assert "does not match" in e.value.problem


def test_bad_filename_on_read(tmp_path):
    streams, _ = _linear_streams(np.random.default_rng(0))
    p = _write(tmp_path / "push_rect1.json", streams)
    with pytest.raises(DatasetError, match=re.escape(p.name)):
        read_mit_push(p)


# ------------------------------------------------------------------------------------------
# synthetic data: exact answers
# ------------------------------------------------------------------------------------------
def test_interpolation_exact_on_linear_motion(tmp_path, mit_ext):
    streams, exact = _linear_streams(np.random.default_rng(1))
    push = read_mit_push(_write(tmp_path / _name(ext=mit_ext), streams), tare=False)
    t_start = max(a[0, 0] for a in streams.values())
    t_end = min(a[-1, 0] for a in streams.values())
    assert push.t0 == t_start
    assert len(push) == math.floor((t_end - t_start) * 10)
    np.testing.assert_array_equal(push.times, np.arange(len(push)) / 10.0)
    tau = push.times + (t_start - T0)  # time since the synthetic origin
    np.testing.assert_allclose(push.object_pose, exact["obj"](tau), atol=1e-6, rtol=0)
    np.testing.assert_allclose(push.tip_pose, exact["tip"](tau), atol=1e-6, rtol=0)
    np.testing.assert_allclose(push.force, np.tile([1.0, 0.5], (len(push), 1)), atol=1e-12)
    # ft starts last (t_start): window 0 lies before it, no raw sample → the first reading
    assert push.force_samples[0] == 0 and np.all(push.force_samples[1:] > 0)
    assert push.contact.all()
    assert push.tip_pose.shape == (len(push), 2) and push.object_pose.shape == (len(push), 3)


@pytest.mark.parametrize("theta0, omega", [(3.0, 0.5), (-3.0, -0.5), (0.2, 4.0)])
def test_yaw_unwrapped_across_pi(tmp_path, theta0, omega):
    streams, _ = _linear_streams(np.random.default_rng(2), theta0=theta0, omega=omega)
    assert np.abs(streams["object_pose"][:, 3]).max() <= np.pi  # the file holds wrapped yaw
    push = read_mit_push(_write(tmp_path / _name(), streams))
    tau = push.times + (push.t0 - T0)
    np.testing.assert_allclose(push.object_pose[:, 2], theta0 + omega * tau, atol=1e-6)
    assert np.abs(push.object_pose[:, 2]).max() > np.pi + 0.4  # kept unwrapped
    assert np.all(np.sign(np.diff(push.object_pose[:, 2])) == np.sign(omega))


@pytest.mark.parametrize(
    "span, rate, expected",
    [
        (2.0, 10.0, 20),
        (2.05, 10.0, 20),
        (1.999, 10.0, 19),
        (2.3, 10.0, 23),  # (T0 + 2.3) - T0 = 2.29999995 s in float64: still 23 samples
        (1.1, 10.0, 11),
        (2.0, 25.0, 50),
        (1.0, 3.0, 3),
    ],
)
def test_resampled_length_rule(tmp_path, span, rate, expected):
    rng = np.random.default_rng(3)
    tip = np.stack([T0 + np.linspace(-0.1, span, 300), *rng.normal(size=(3, 300)) * 1e-3], 1)
    obj = np.stack([T0 + np.linspace(0.0, span + 0.2, 300), *rng.normal(size=(3, 300)) * 1e-3], 1)
    ft = np.stack([T0 + np.linspace(-0.05, span + 0.1, 300), *rng.normal(size=(3, 300))], 1)
    p = _write(tmp_path / _name(), {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft})
    push = read_mit_push(p, rate=rate)
    assert push.duration == pytest.approx(span, abs=1e-6)
    assert len(push) == expected == math.floor(push.duration * rate + 1e-4)
    np.testing.assert_allclose(push.times, np.arange(expected) / rate, rtol=0, atol=0)
    assert len(push.force) == len(push.contact) == len(push.tip_pose) == expected


def test_force_is_window_average_not_point_sample(tmp_path):
    """F = 2 + cos(2π·rate·t): window mean 2; a point sample at t_k would give 3, centre 1.

    The ft stream starts 0.1 s before t_start, so window 0 averages 100 raw samples too.
    """
    rate = 10.0
    t = _times(0.1, 2.2, 250)
    tip = np.stack([T0 + t, 0.3 + 0.01 * t, 0 * t, 0 * t], 1)
    obj = np.stack([T0 + t, 0.35 + 0.01 * t, 0 * t, 0 * t], 1)
    tf = (np.arange(2200) + 0.5) / 1000  # half a sample off the window edges (t_start = 0.1)
    phase = 2 * np.pi * rate * (tf - 0.1)
    ft = np.stack([T0 + tf, -(2 + np.cos(phase)), -(-1 + 0.5 * np.sin(phase)), 0 * tf], 1)
    p = _write(tmp_path / _name(), {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft})
    push = read_mit_push(p, rate=rate, tare=False)
    assert len(push) == 20
    assert np.all(push.force_samples == 100)
    np.testing.assert_allclose(push.force, np.tile([2.0, -1.0], (20, 1)), atol=1e-4)


def test_empty_force_window_falls_back_to_interpolation(tmp_path):
    rate = 10.0
    t = _times(0.0, 2.0, 250)
    tip = np.stack([T0 + t, 0.3 + 0 * t, 0 * t, 0 * t], 1)
    obj = np.stack([T0 + t, 0.35 + 0 * t, 0 * t, 0 * t], 1)
    tf = -0.1 + (np.arange(2200) + 0.5) / 1000  # starts before the others: t_start = 0
    keep = ~((tf >= 0.3) & (tf < 0.4))  # window 4, [0.3, 0.4) s, ending at t_4, gets no sample
    tf = tf[keep]
    fx = 1.0 + 2.0 * tf  # linear ramp: window means and interpolation are both exact
    ft = np.stack([T0 + tf, -fx, 0 * tf, 0 * tf], 1)
    push = read_mit_push(
        _write(tmp_path / _name(), {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft}),
        tare=False,
    )
    # window 0 is [-0.1, 0) s, before t_start: its 100 raw samples are used
    assert push.force_samples[4] == 0 and np.all(np.delete(push.force_samples, 4) == 100)
    centres = (np.arange(len(push)) - 0.5) / rate  # of the windows ending at t_k
    np.testing.assert_allclose(push.force[:, 0], 1.0 + 2.0 * centres, atol=1e-6)
    assert push.force[0, 0] == pytest.approx(0.9, abs=1e-6)  # F(-0.05 s)


def test_window_zero_without_earlier_force_is_the_first_reading(tmp_path):
    """The ft stream starts at t_start (as in the real files): window 0 has no raw sample and
    np.interp at its centre, -0.05 s, clamps to the first reading (not the ramp's 0.9)."""
    t = _times(-0.05, 2.05, 250)
    tip = np.stack([T0 + t, 0.3 + 0 * t, 0 * t, 0 * t], 1)
    obj = np.stack([T0 + t, 0.35 + 0 * t, 0 * t, 0 * t], 1)
    # first stamp at t_start = 0, then halfway between 1 kHz ticks (off the window edges)
    tf = np.concatenate([[0.0], (np.arange(2100) + 0.5) / 1000])
    fx = 1.0 + 2.0 * tf
    ft = np.stack([T0 + tf, -fx, 0 * tf, 0 * tf], 1)
    push = read_mit_push(
        _write(tmp_path / _name(), {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft}),
        tare=False,
    )
    assert push.t0 == T0 and len(push) == 20
    assert push.force_samples[0] == 0
    assert push.force[0, 0] == 1.0  # the reading at t_start, exactly
    # window 1, [0, 0.1): the reading at 0 and 100 samples with mean 1 + 2·0.05
    assert push.force_samples[1] == 101
    assert push.force[1, 0] == pytest.approx((1.0 + 100 * 1.1) / 101, abs=1e-9)
    assert np.all(push.force_samples[2:] == 100)
    centres = (np.arange(2, 20) - 0.5) / 10.0
    np.testing.assert_allclose(push.force[2:, 0], 1.0 + 2.0 * centres, atol=1e-9)
    np.testing.assert_allclose(push.force[:, 1], 0.0, atol=0)


def test_force_step_appears_in_the_window_ending_after_it(tmp_path):
    """Probe force steps to 2 N at 0.73 s and back to 0 at 1.52 s (1 kHz, off the edges).

    Sample k averages [t_k - 0.1, t_k): the step first shows at sample 8 (window [0.7, 0.8),
    70% of it after the step) and is full from sample 9; it ends at sample 16 (20% of [1.5,
    1.6)). The old convention ([t_k, t_k + 0.1)) would show it one sample earlier.
    """
    t = _times(0.0, 2.0, 250)
    tip = np.stack([T0 + t, 0.3 + 0.05 * t, 0 * t, 0 * t], 1)
    obj = np.stack([T0 + t, 0.35 + 0.05 * t, 0 * t, 0 * t], 1)
    tf = -0.1 + (np.arange(2200) + 0.5) / 1000
    fx = np.where((tf > 0.73) & (tf < 1.52), 2.0, 0.0)
    ft = np.stack([T0 + tf, -fx, 0 * tf, 0 * tf], 1)
    push = read_mit_push(
        _write(tmp_path / _name(), {"tip_pose": tip, "object_pose": obj, "ft_wrench": ft}),
        tare=False,
    )
    expected = np.zeros(20)
    expected[8] = 0.7 * 2.0
    expected[9:16] = 2.0
    expected[16] = 0.2 * 2.0
    np.testing.assert_allclose(push.force[:, 0], expected, atol=1e-12)
    np.testing.assert_array_equal(push.force[:, 1], 0.0)
    np.testing.assert_array_equal(np.flatnonzero(push.contact), np.arange(8, 16))  # 0.4 < 0.5 N
    # poses stay point samples at t_k
    np.testing.assert_allclose(push.tip_pose[:, 0], 0.3 + 0.05 * push.times, atol=1e-9)


def test_reader_matches_the_simulator_tactile_timing(tmp_path):
    """A simulated push written as a MIT file reads back with the simulator's tactile samples.

    The physics-rate force of step s (acting over ((s-1)·dt, s·dt]) is stamped at the step's
    middle, so no raw sample sits on a window edge (the reader's windows are [ , ), the
    simulator's ( , ]); 0.1 s of zero force before the push stands for the pad at rest.
    """
    from pushtoknow.common.params import ObjectParams
    from pushtoknow.testbed.objects import ObjectSpec
    from pushtoknow.testbed.push import Push
    from pushtoknow.testbed.sim import PushSimulator
    from pushtoknow.testbed.sim_config import PushConfig, SimConfig

    obj = mit_object("rect1")
    spec = ObjectSpec(shape="rect1", params=ObjectParams(obj.mass, 0.3, 0.0, 0.0, obj.inertia))
    sim = PushSimulator(spec, SimConfig(push=PushConfig(horizon=1.5), render=False))
    try:
        sim.reset((0.35, 0.02, 0.3))
        cp = np.array([0.35, 0.02]) + 0.045 * np.array([-np.cos(0.3), -np.sin(0.3)])
        push = Push((float(cp[0]), float(cp[1]) + 0.01), 0.3, "constant", 0.1)
        rec = sim.execute(push, np.random.default_rng(0), render=False, trace=True)
        dt = sim.model.opt.timestep
    finally:
        sim.close()
    tr = rec.trace
    n = len(tr["time"])
    per = round(0.1 / dt)
    s = np.arange(-per + 1, n + 1)  # steps; s <= 0: pad at rest before the push
    tf = (s - 0.5) * dt
    f = np.vstack([np.zeros((per, 2)), tr["force"]])
    ft = np.column_stack([T0 + tf, -f, 0 * tf])  # the probe reads minus the force on the object
    t_obj = np.concatenate([[0.0], tr["time"]])
    pose = np.vstack([rec.pose[:1], tr["pose"]])
    streams = {
        "tip_pose": np.column_stack([T0 + rec.time, rec.pusher, 0 * rec.time]),
        "object_pose": np.column_stack([T0 + t_obj, pose]),
        "ft_wrench": ft,
    }
    mit = read_mit_push(_write(tmp_path / _name(v="100"), streams), tare=False)
    k = len(mit)
    assert k == len(rec.time) - 2  # the ft stream ends dt/2 before the others
    assert np.all(mit.force_samples == per)
    assert np.linalg.norm(rec.force_clean, axis=1).max() > 1.0  # it did push
    np.testing.assert_allclose(mit.force, rec.force_clean[:k], rtol=0, atol=1e-9)
    np.testing.assert_array_equal(rec.force_clean[0], 0.0)
    # poses at t_k, as the images: exact up to the Unix-time rounding (2.4e-7 s at T0)
    np.testing.assert_allclose(mit.object_pose, rec.pose[:k], rtol=0, atol=1e-6)
    np.testing.assert_allclose(mit.tip_pose, rec.pusher[:k], rtol=0, atol=1e-6)


def test_tare_sign_contact_and_friction(tmp_path, mit_ext):
    offset = np.array([-1.5, -0.5])
    mu = 0.3
    f = np.array([mu * RECT1_MASS * GRAVITY, 0.0])
    p = _write(tmp_path / _name(ext=mit_ext), _tare_streams(tuple(offset), tuple(f)))
    push = read_mit_push(p)
    assert len(push) == 20
    np.testing.assert_allclose(push.force_offset, offset, atol=1e-12)
    # pushing during [0.5, 1.5) s: the windows [t_k - 0.1, t_k) of samples 6..15
    pushing = np.zeros(20, dtype=bool)
    pushing[6:16] = True
    # force on the object = −(reading − offset): +x, along the pusher's motion
    np.testing.assert_allclose(push.force[pushing], np.tile(f, (10, 1)), atol=1e-9)
    np.testing.assert_allclose(push.force[~pushing], 0.0, atol=1e-9)
    np.testing.assert_array_equal(push.contact, pushing)
    assert estimate_friction(push) == pytest.approx(mu, rel=1e-9)

    raw = read_mit_push(p, tare=False)  # offset kept: force at rest is −offset, "in contact"
    np.testing.assert_allclose(raw.force[~pushing], np.tile(-offset, (10, 1)), atol=1e-9)
    assert raw.contact.all() and np.all(raw.force_offset == 0)


def test_no_contact_friction_raises(tmp_path):
    s = _tare_streams(offset=(0.0, 0.0), force=(0.1, 0.0))  # below the contact threshold
    assert 0.1 < CONTACT_FORCE_THRESHOLD
    push = read_mit_push(_write(tmp_path / _name(), s))
    assert not push.contact.any()
    with pytest.raises(DatasetError, match="no samples in contact"):
        estimate_friction(push)


def test_out_of_order_and_duplicate_timestamps(tmp_path):
    """A late-stamped row is dropped (file order kept); of equal stamps the last row is kept."""
    streams, _ = _linear_streams(np.random.default_rng(4))
    obj = streams["object_pose"].copy()
    t = obj[:, 0]
    t[10] = t[12] + 0.001  # late stamp, as in the real object_pose streams
    t[20] = t[19]  # duplicate stamp
    obj[20, 1] += 1e-3  # make the duplicates distinguishable
    streams["object_pose"] = obj
    raw = load_mit_streams(_write(tmp_path / _name(), streams))
    kept = raw.object_pose
    assert raw.dropped == {"tip_pose": 0, "object_pose": 2, "ft_wrench": 0}
    assert np.all(np.diff(kept[:, 0]) > 0)
    expected = np.delete(obj, [10, 19], axis=0)
    np.testing.assert_array_equal(kept, expected)


def test_json_and_h5_give_the_same_push(tmp_path):
    streams, _ = _linear_streams(np.random.default_rng(5))
    a = read_mit_push(_write(tmp_path / _name(ext="json"), streams))
    b = read_mit_push(_write(tmp_path / _name(ext="h5"), streams))
    for k in ("times", "object_pose", "tip_pose", "force", "contact", "force_offset"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))
    assert a.meta == b.meta


def test_triangle_pose_is_moved_to_the_centroid(tmp_path):
    theta = 0.7
    t = _times(0.0, 1.0, 250)
    pose = np.stack([T0 + t, 0.4 + 0 * t, -0.1 + 0 * t, theta + 0 * t], 1)
    ft = np.stack([T0 + t, 0 * t, 0 * t, 0 * t], 1)
    s = {"tip_pose": pose, "object_pose": pose, "ft_wrench": ft}
    push = read_mit_push(_write(tmp_path / _name(shape="tri2"), s))
    off = np.array([0.045 - 0.1510 / 3, 0.045 - 0.1259 / 3])  # centroid in the dataset frame
    rot = np.array([[np.cos(theta), -np.sin(theta)], [np.sin(theta), np.cos(theta)]])
    expected = np.tile([0.4, -0.1] + rot @ off, (len(push), 1))
    np.testing.assert_allclose(push.object_pose[:, :2], expected, atol=1e-12)
    np.testing.assert_allclose(push.object_pose[:, 2], theta, atol=1e-12)
    np.testing.assert_array_equal(push.raw.object_pose, pose)  # raw keeps the dataset frame
    back = dataset_to_centroid_pose(np.array([0.4, -0.1, theta]), "rect1")
    np.testing.assert_allclose(back, [0.4, -0.1, theta])  # symmetric shapes: no offset


def test_yaw_flip_warns(tmp_path):
    streams, _ = _linear_streams(np.random.default_rng(6), omega=0.0)
    streams["object_pose"][100:, 3] += np.pi / 2
    with pytest.warns(MitPushWarning, match="yaw jumps by 90"):
        read_mit_push(_write(tmp_path / _name(), streams))


def test_invalid_rate_and_non_overlapping_streams(tmp_path):
    streams, _ = _linear_streams(np.random.default_rng(7))
    p = _write(tmp_path / _name(), streams)
    for rate in (0.0, -10.0, float("nan")):
        with pytest.raises(ValueError, match="rate"):
            read_mit_push(p, rate=rate)
    streams["ft_wrench"][:, 0] += 10.0  # after the other two streams end
    p = _write(tmp_path / _name(v="60"), streams)
    with pytest.raises(DatasetError, match="do not overlap"):
        read_mit_push(p)


# ------------------------------------------------------------------------------------------
# corrupt files
# ------------------------------------------------------------------------------------------
def _corrupt(kind: str, path: Path) -> Path:
    streams, _ = _linear_streams(np.random.default_rng(8))
    if kind == "truncated":
        text = json.dumps({k: v.tolist() for k, v in streams.items()})
        path.write_text(text[: len(text) // 2])
    elif kind == "garbage":
        path.write_bytes(np.random.default_rng(9).bytes(4096))
    elif kind == "columns":
        streams["ft_wrench"] = streams["ft_wrench"][:, :3]
        _write(path, streams)
    elif kind == "nan":
        streams["object_pose"][5, 2] = np.nan
        _write(path, streams)
    elif kind == "missing":
        del streams["tip_pose"]
        _write(path, streams)
    elif kind == "short":
        streams["tip_pose"] = streams["tip_pose"][:1]
        _write(path, streams)
    elif kind == "ragged":
        d = {k: v.tolist() for k, v in streams.items()}
        d["object_pose"][3] = d["object_pose"][3][:2]
        path.write_text(json.dumps(d))
    return path


@pytest.mark.parametrize(
    "kind, ext, problem",
    [
        ("truncated", "json", "corrupt JSON"),
        ("garbage", "json", "corrupt JSON"),
        ("garbage", "h5", "HDF5"),
        ("columns", "json", r"ft_wrench: expected shape \(N, 4\)"),
        ("columns", "h5", r"ft_wrench: expected shape \(N, 4\)"),
        ("nan", "json", "object_pose: 1 non-finite"),
        ("nan", "h5", "object_pose: 1 non-finite"),
        ("missing", "json", "missing stream 'tip_pose'"),
        ("missing", "h5", "missing stream 'tip_pose'"),
        ("short", "h5", "tip_pose: 1 row"),
        ("ragged", "json", "object_pose: not a numeric"),
    ],
)
def test_corrupt_file_names_file_and_problem(tmp_path, kind, ext, problem):
    p = _corrupt(kind, tmp_path / _name(ext=ext))
    with pytest.raises(DatasetError, match=problem) as e:
        read_mit_push(p)
    assert Path(e.value.path) == p
    assert p.name in str(e.value)


def test_unknown_shape_names_file_and_shape(tmp_path, mit_ext):
    streams, _ = _linear_streams(np.random.default_rng(10))
    p = _write(tmp_path / _name(shape="star5", ext=mit_ext), streams)
    with pytest.raises(DatasetError, match="unknown shape 'star5'") as e:
        read_mit_push(p)
    assert p.name in str(e.value)


def test_missing_file(tmp_path):
    with pytest.raises(DatasetError, match="no such file"):
        read_mit_push(tmp_path / _name())


# ------------------------------------------------------------------------------------------
# object catalogue
# ------------------------------------------------------------------------------------------
def _area_centroid_inertia(v):
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cr = x * y1 - x1 * y
    area = cr.sum() / 2
    c = np.array([((x + x1) * cr).sum(), ((y + y1) * cr).sum()]) / (6 * area)
    j0 = ((x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1) * cr).sum() / 12
    return area, c, j0 / area - c @ c  # polar second moment per unit area about the centroid


def test_catalogue_is_consistent_with_masses_and_inertias():
    assert set(MIT_SHAPES) == {
        "rect1", "rect2", "rect3", "tri1", "tri2", "tri3",
        "ellip1", "ellip2", "ellip3", "hex", "butter",
    }  # fmt: skip
    density = RECT1_MASS / 0.090**2  # kg/m² of the 13 mm steel plate
    for shape in MIT_SHAPES:
        o = mit_object(shape)
        area, c, k = _area_centroid_inertia(o.polygon)
        assert area > 0, f"{shape}: polygon not counter-clockwise"
        np.testing.assert_allclose(c, 0.0, atol=1e-12, err_msg=shape)
        assert area * density == pytest.approx(o.mass, rel=0.025), shape
        assert o.mass * k == pytest.approx(o.inertia, rel=0.015), shape  # CoM at the centroid
        p = o.params(0.3)
        assert (p.mass, p.friction, p.com_x, p.com_y, p.inertia) == (o.mass, 0.3, 0, 0, o.inertia)
    assert mit_object("rect1").mass == RECT1_MASS and mit_object("rect1").inertia == 1.131e-3
    assert PUSHER_RADIUS == 4.745e-3


def test_catalogue_geometry():
    assert np.ptp(mit_polygon("rect2"), axis=0) == pytest.approx([0.0899, 0.1126])
    assert np.ptp(mit_polygon("rect3"), axis=0) == pytest.approx([0.1350, 0.0899])
    assert mit_polygon("ellip3").shape == (64, 2)
    assert mit_polygon("ellip3", ellipse_vertices=16).shape == (16, 2)
    assert np.ptp(mit_polygon("ellip3"), axis=0) == pytest.approx([0.105, 0.157], abs=1e-4)
    assert np.linalg.norm(mit_polygon("hex"), axis=1) == pytest.approx(np.full(6, 0.0605))
    butter = mit_polygon("butter")
    assert np.ptp(butter[:, 0]) == pytest.approx(0.0955, abs=5e-4)
    # triangles: legs (x, y), centroid offset from the dataset frame (45 mm inset corner)
    for shape, (lx, ly) in {"tri1": (0.1259, 0.1259), "tri2": (0.1510, 0.1259),
                            "tri3": (0.1765, 0.1256)}.items():  # fmt: skip
        v = mit_polygon(shape, frame="dataset")
        np.testing.assert_allclose(v[0], [0.045, 0.045])
        assert np.ptp(v, axis=0) == pytest.approx([lx, ly])
        off = mit_object(shape).frame_offset
        np.testing.assert_allclose(off, [0.045 - lx / 3, 0.045 - ly / 3], atol=1e-12)
        np.testing.assert_allclose(mit_polygon(shape), v - off, atol=1e-12)
    for shape in ("rect1", "ellip2", "hex", "butter"):
        assert np.all(mit_object(shape).frame_offset == 0)
    with pytest.raises(ObjectSpecError, match="unknown MIT shape"):
        mit_object("star5")
    with pytest.raises(ObjectSpecError):
        mit_polygon("star5")


# ------------------------------------------------------------------------------------------
# selection
# ------------------------------------------------------------------------------------------
def test_find_and_iter_filters(tmp_path):
    streams, _ = _linear_streams(np.random.default_rng(11))
    names = [
        _name(v="20"),
        _name(v="20", ext="h5"),  # same push in both formats: listed once, as .h5
        _name(v="50"),
        _name(v="20", a="1000"),
        _name(shape="tri1", v="20", surface="abs"),
    ]
    (tmp_path / "sub").mkdir()
    for n in names:
        _write(tmp_path / "sub" / n, streams)
    (tmp_path / "readme.txt").write_text("not a push")
    found = find_mit_push_files(tmp_path, acceleration=0, speed=0.02)
    assert [p.name for p, _ in found] == [names[4], names[1]]
    assert [p.name for p, _ in find_mit_push_files(tmp_path, shape="rect1", speed=0.05)] == [
        names[2]
    ]
    assert len(find_mit_push_files(tmp_path)) == 4
    assert len(find_mit_push_files(tmp_path, surface="delrin")) == 0
    pushes = list(iter_mit_push(tmp_path, surface="plywood", acceleration=0, speed=0.02))
    assert len(pushes) == 1 and pushes[0].meta.shape == "rect1"
    with pytest.raises(DatasetError, match="not a directory"):
        find_mit_push_files(tmp_path / "nope")


# ------------------------------------------------------------------------------------------
# the three real files
# ------------------------------------------------------------------------------------------
def test_real_files_parse_and_resample(mit_sample_dir):
    files = sorted(mit_sample_dir.glob("*.json"))
    assert len(files) == 3
    spans = {}
    for f in files:
        push = read_mit_push(f)
        for name in ("tip_pose", "object_pose", "ft_wrench"):
            assert np.all(np.diff(getattr(push.raw, name)[:, 0]) > 0), (f.name, name)
        assert len(push) == math.floor(push.duration * 10.0) > 5
        np.testing.assert_array_equal(push.times, np.arange(len(push)) / 10.0)
        assert np.all(np.isfinite(push.object_pose)) and np.all(np.isfinite(push.force))
        # Sample k averages the raw samples in [t_{k-1}, t_k) (~25 per 0.1 s window).
        ft = push.raw.ft_wrench
        tf = ft[:, 0] - push.t0
        f_obj = -(ft[:, 1:3] - push.force_offset)
        assert np.all(push.force_samples[1:] > 0)
        for k in range(1, len(push)):
            w = (tf >= push.times[k] - 0.1) & (tf < push.times[k])
            assert push.force_samples[k] == w.sum()
            np.testing.assert_allclose(push.force[k], f_obj[w].mean(axis=0), atol=1e-12)
        # The force stream starts last in all three files: window 0 lies before it, and
        # sample 0 is its first reading (np.interp clamps).
        assert tf[0] == 0.0 and push.force_samples[0] == 0
        np.testing.assert_array_equal(push.force[0], f_obj[0])
        assert push.contact.any() and not push.contact.all()  # rest before/after the push
        assert not push.contact[0]  # (the first reading is taken at rest)
        spans[f.name] = tuple(np.flatnonzero(push.contact)[[0, -1]])
        assert push.meta.speed == pytest.approx(0.1) and push.meta.acceleration == 0
        # off-centre / angled pushes rotate the block a lot
        if f.name != CENTRE_PUSH:
            assert abs(push.object_pose[-1, 2] - push.object_pose[0, 2]) > math.radians(20)
        first, last = spans[f.name]
        assert push.contact[first : last + 1].all()  # one contact phase
    # Measured (first, last) contact samples: each contact window ends at its t_k, so contact
    # is first felt in [t_{first-1}, t_first).
    assert spans == {
        "motion_surface=plywood_shape=rect1_a=0_v=100_i=0.000_s=0.000_t=0.000.json": (1, 5),
        "motion_surface=plywood_shape=rect1_a=0_v=100_i=0.000_s=0.500_t=0.698.json": (2, 7),
        CENTRE_PUSH: (2, 6),
    }


def test_real_centre_push_translates_with_plausible_friction(mit_sample_dir):
    push = read_mit_push(mit_sample_dir / CENTRE_PUSH)
    dtheta = push.object_pose[-1, 2] - push.object_pose[0, 2]
    assert abs(math.degrees(dtheta)) < 2.0
    assert push.obj.mass == RECT1_MASS
    assert 0.15 < estimate_friction(push) < 0.35
    # world frame, force on the object: along the pusher's motion (measured 0.5° apart)
    d = push.tip_pose[-1] - push.tip_pose[0]
    f = push.force[push.contact].mean(axis=0)
    cos = f @ d / (np.linalg.norm(f) * np.linalg.norm(d))
    assert cos > math.cos(math.radians(5))
    # the sensor offset of this file, measured at rest before and after the push
    np.testing.assert_allclose(push.force_offset, [-1.53, -0.53], atol=0.05)


def test_real_h5_equals_json(mit_sample_dir, tmp_path):
    src = mit_sample_dir / CENTRE_PUSH
    data = json.loads(src.read_text())
    dst = _write(tmp_path / src.with_suffix(".h5").name, {k: np.array(v) for k, v in data.items()})
    a, b = read_mit_push(src), read_mit_push(dst)
    for k in ("times", "object_pose", "tip_pose", "force", "contact"):
        np.testing.assert_array_equal(getattr(a, k), getattr(b, k))


def test_real_subset_selection(mit_sample_dir):
    assert len(list(iter_mit_push(mit_sample_dir, shape="rect1", acceleration=0, speed=0.1))) == 3
    assert find_mit_push_files(mit_sample_dir, speed=0.02) == []
    assert find_mit_push_files(mit_sample_dir, surface="abs") == []


def test_contact_phase_keeps_the_bounces_inside_it():
    from pushtoknow.datasets.mit_push import contact_phase_force

    force = np.array([[0.0, 0], [3.0, 4], [0.2, 0], [6.0, 8], [0.0, 0]])  # a bounce at sample 2
    contact = np.array([False, True, False, True, False])
    np.testing.assert_allclose(contact_phase_force(force, contact), [5.0, 0.2, 10.0])
    assert contact_phase_force(force, np.zeros(5, bool)).size == 0
