"""The recording format (docs/RECORDING.md): round trip, every check's one-line error (the file
left unchanged), resampling, and identification from a recording as from the shard."""

import hashlib
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.errors import DatasetError
from pushtoknow.datasets.recording import (
    FORMAT,
    RawPush,
    RecordingMeta,
    read_recording,
    recording_meta,
    records_from_pushes,
    write_recording,
)
from pushtoknow.datasets.shards import read_shard
from pushtoknow.testbed.sim import PushRecord

sys.path.insert(0, str(Path(__file__).parents[1] / "identification"))
from identify_data import SHORT, SPEC, write_tiny_dataset

RATE = 10.0
T = 31
CLI = [sys.executable, "-m", "pushtoknow.cli"]


def _synthetic(t=None, pusher=None, pose=None, force=None, group="push-000") -> RawPush:
    """A push along +x at 20 mm/s: the pad 50 mm behind the object's centroid, 2 N of force
    along +x with 0.05 N of noise, a small yaw drift."""
    rng = np.random.default_rng(0)
    t = np.arange(T) / RATE if t is None else t
    x = 0.02 * t
    if pose is None:
        pose = np.column_stack([x, np.zeros_like(t), 0.01 * t])
    if pusher is None:
        pusher = np.column_stack([x - 0.05, np.zeros_like(t)])
    if force is None:
        force = np.column_stack([np.full_like(t, 2.0), np.zeros_like(t)])
        force = force + rng.normal(0, 0.05, force.shape)
    return RawPush(group, t, pusher, pose, force)


def _write_raw(path: Path, raws, **attrs) -> Path:
    """A recording file written by hand (as another robot's software would)."""
    with h5py.File(path, "w") as f:
        f.attrs.update(format=FORMAT, version=1, object="box", height=0.05, **attrs)
        for r in raws:
            g = f.create_group(r.group)
            for name in ("time", "pusher", "object_pose", "force"):
                g.create_dataset(name, data=getattr(r, name))
    return path


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    """The identification tests' tiny rendered dataset: one rect1 object, a constant and a
    release push of 2 s."""
    return write_tiny_dataset(tmp_path_factory.mktemp("ds"), ("constant", "release"))


def _episode(tiny):
    (ep,) = read_shard(tiny / "shard-00000.h5")
    return ep


def test_round_trip_keeps_every_recorded_array_bitwise(tiny, tmp_path):
    ep = _episode(tiny)
    path = write_recording(tmp_path / "rec.h5", ep.records, recording_meta(ep.spec, SHORT))
    assert not list(tmp_path.glob("*.tmp"))  # written atomically, nothing left behind
    meta, records = read_recording(path)
    assert meta.name == "tiny" and meta.rate == 10.0 and meta.notes == ()
    assert meta.height == SPEC.height and meta.force_noise_std == 0.05
    np.testing.assert_array_equal(meta.truth, SPEC.params.as_array())
    np.testing.assert_array_equal(meta.outline, SPEC.footprint.vertices)
    for got, want in zip(records, ep.records, strict=True):
        assert got.push == want.push
        for name in ("time", "pose", "tactile", "pusher", "rgb", "depth"):
            np.testing.assert_array_equal(getattr(got, name), getattr(want, name), err_msg=name)
        assert got.force_clean is None  # a recording has no noiseless force
    _, no_images = read_recording(path, images=False)
    assert no_images[0].rgb is None and no_images[0].depth is None


def test_missing_truth_and_commanded_push_are_nan_and_derived_from_the_pad(tiny, tmp_path):
    """Without the commanded push, the push is derived from the pad track as an MIT Push
    import derives it: a simulated constant push comes back with its direction and speed."""
    ep = _episode(tiny)
    meta = recording_meta(ep.spec, SHORT)
    truth = meta.truth.copy()
    truth[[1, 4]] = np.nan
    from dataclasses import replace

    path = write_recording(tmp_path / "rec.h5", ep.records[:1], replace(meta, truth=truth))
    with h5py.File(path, "r+") as f:
        for k in ("push_contact", "push_direction", "push_speed", "push_profile"):
            del f["push-000"].attrs[k]
    got_meta, (rec,) = read_recording(path)
    np.testing.assert_array_equal(np.isnan(got_meta.truth), [False, True, False, False, True])
    want = ep.records[0].push
    assert rec.push.profile == "constant"
    assert rec.push.direction == pytest.approx(want.direction, abs=1e-3)
    assert rec.push.speed == pytest.approx(want.speed, rel=0.01)
    # the contact point lies on the footprint's boundary, near the commanded one
    assert np.hypot(*np.subtract(rec.push.contact, want.contact)) < 0.01


def _check_fails(path: Path, *words: str, **kwargs) -> None:
    """read_recording raises one line naming each word, and leaves the file unchanged."""
    before = hashlib.sha256(path.read_bytes()).hexdigest()
    with pytest.raises(DatasetError) as e:
        read_recording(path, **kwargs)
    msg = str(e.value)
    assert "\n" not in msg and str(path) in msg
    for w in words:
        assert w in msg, msg
    assert hashlib.sha256(path.read_bytes()).hexdigest() == before


def test_a_valid_hand_written_file_reads(tmp_path):
    meta, (rec,) = read_recording(_write_raw(tmp_path / "ok.h5", [_synthetic()]))
    assert meta.name == "box" and meta.height == 0.05 and meta.outline is None
    assert np.isnan(meta.truth).all() and meta.force_noise_std is None
    assert rec.push.direction == pytest.approx(0.0, abs=1e-9)
    assert rec.push.speed == pytest.approx(0.02)
    assert rec.tactile[:, 2].all()  # 2 N > 0.5 N: in contact throughout


def test_not_a_recording_or_another_version(tmp_path):
    path = _write_raw(tmp_path / "r.h5", [_synthetic()])
    with h5py.File(path, "r+") as f:
        f.attrs["format"] = "something-else"
    _check_fails(path, "format attribute 'something-else'")
    with h5py.File(path, "r+") as f:
        f.attrs.update(format=FORMAT, version=2)
    _check_fails(path, "version 2", "reads version 1")


def test_missing_dataset(tmp_path):
    path = _write_raw(tmp_path / "r.h5", [_synthetic()])
    with h5py.File(path, "r+") as f:
        del f["push-000/force"]
    _check_fails(path, "push-000/force: missing")


def test_wrong_shape(tmp_path):
    raw = _synthetic()
    raw.pusher = np.column_stack([raw.pusher, np.zeros(T)])
    _check_fails(
        _write_raw(tmp_path / "r.h5", [raw]), "push-000/pusher: shape (31, 3), expected (31, 2)"
    )


def test_non_finite_value(tmp_path):
    raw = _synthetic()
    raw.object_pose[7, 1] = np.nan
    _check_fails(_write_raw(tmp_path / "r.h5", [raw]), "push-000/object_pose", "sample 7")


def test_time_not_strictly_increasing(tmp_path):
    t = np.arange(T) / RATE
    t[12] = t[11]
    _check_fails(
        _write_raw(tmp_path / "r.h5", [_synthetic(t=t)]),
        "push-000/time: not strictly increasing at sample 12",
    )


def test_gap_in_time(tmp_path):
    t = np.arange(T) / RATE
    t[20:] += 2.0
    _check_fails(_write_raw(tmp_path / "r.h5", [_synthetic(t=t)]), "push-000/time: a gap of 2.1")


def test_frozen_force_channel(tmp_path):
    raws = [_synthetic(), _synthetic(force=np.tile([1.5, 0.0], (T, 1)), group="push-001")]
    _check_fails(_write_raw(tmp_path / "r.h5", raws), "push-001/force: frozen", "[1.5, 0.0]")


def test_frozen_pose_channel(tmp_path):
    pose = np.tile([0.1, 0.2, 0.3], (T, 1))
    _check_fails(_write_raw(tmp_path / "r.h5", [_synthetic(pose=pose)]), "object_pose: frozen")


def test_force_pointing_away_from_the_object(tmp_path):
    raw = _synthetic()
    raw.force = -raw.force  # the force on the pad, as most F/T sensors report it
    _check_fails(
        _write_raw(tmp_path / "r.h5", [raw]),
        "push-000/force: points against the push on 31 of 31",
        "sign flipped",
    )


def test_positions_in_millimetres(tmp_path):
    raw = _synthetic()
    raw.object_pose[:, :2] *= 1000.0
    raw.object_pose[:, 0] += 350.0
    _check_fails(
        _write_raw(tmp_path / "r.h5", [raw]), "push-000/object_pose: position 410 m", "millimetres?"
    )


def test_height_in_millimetres(tmp_path):
    path = _write_raw(tmp_path / "r.h5", [_synthetic()])
    with h5py.File(path, "r+") as f:
        f.attrs["height"] = 50.0
    _check_fails(path, "height=50.0")


def test_an_off_centroid_outline_moves_the_object_frame_with_a_note(tmp_path):
    """A robot's object frame at a corner: poses, outline and the true CoM move to the
    footprint's centroid (docs/DESIGN.md §2), and the note says so."""
    square = np.array([[0.0, 0.0], [0.1, 0.0], [0.1, 0.1], [0.0, 0.1]])
    path = _write_raw(tmp_path / "r.h5", [_synthetic()], outline=square, truth_com_x=0.05)
    meta, (rec,) = read_recording(path)
    np.testing.assert_allclose(meta.outline.mean(axis=0), 0.0, atol=1e-15)
    assert meta.truth[2] == pytest.approx(0.0)
    raw = _synthetic()
    th = raw.object_pose[:, 2]
    want_x = raw.object_pose[:, 0] + 0.05 * np.cos(th) - 0.05 * np.sin(th)
    np.testing.assert_allclose(rec.pose[:, 0], want_x, atol=1e-12)
    assert any("centroid" in n for n in meta.notes)


def test_a_jittery_clock_is_resampled_with_a_note(tmp_path):
    rng = np.random.default_rng(1)
    t = np.arange(T) / RATE + rng.uniform(-0.02, 0.02, T)
    meta, (rec,) = read_recording(_write_raw(tmp_path / "r.h5", [_synthetic(t=t)]))
    assert any("push-000: a jittery clock resampled" in n for n in meta.notes)
    np.testing.assert_allclose(np.diff(rec.time), 1 / meta.rate, rtol=1e-9)


def test_a_faster_clock_is_resampled_to_the_rate_asked(tmp_path):
    """100 Hz read at 10 Hz: positions interpolated, the force averaged over each window."""
    t = np.arange(301) / 100.0
    raw = _synthetic(t=t, force=np.column_stack([2.0 + 0.1 * np.sin(40 * t), 0.01 * t]))
    meta, (rec,) = read_recording(_write_raw(tmp_path / "r.h5", [raw]), rate=10.0)
    assert meta.rate == 10.0 and len(rec.time) == 31
    np.testing.assert_allclose(rec.pusher[:, 0], 0.02 * rec.time - 0.05, atol=1e-12)
    assert any("force window-averaged" in n for n in meta.notes)


@settings(max_examples=30, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    jitter=st.floats(0.01, 0.4),
    velocity=st.tuples(st.floats(-0.2, 0.2), st.floats(-0.2, 0.2)),
)
def test_resampling_a_jittered_clock_preserves_a_linear_motion(seed, jitter, velocity):
    """Linear motion sampled at jittered times comes back on a uniform clock, still exactly
    the same line (linear interpolation is exact on it)."""
    rng = np.random.default_rng(seed)
    t = (np.arange(T) + rng.uniform(-jitter, jitter, T)) / RATE
    v = np.asarray(velocity)
    if np.hypot(*v) < 1e-3:
        v = np.array([0.02, 0.0])
    p0 = np.array([0.1, -0.2])
    pusher = p0 + np.outer(t, v)
    pose = np.column_stack([pusher + 0.05 * v / np.hypot(*v), 0.5 * t])
    u = v / np.hypot(*v)
    force = np.outer(2.0 + 0.1 * np.sin(7 * t), u)
    meta, (rec,) = records_from_pushes(
        "mem", [RawPush("push-000", t, pusher, pose, force)], RecordingMeta("line")
    )
    assert len(meta.notes) == 1 and "resampled" in meta.notes[0]
    np.testing.assert_allclose(np.diff(rec.time), 1 / meta.rate, rtol=1e-9)
    want = p0 + np.outer(rec.time + t[0], v)
    np.testing.assert_allclose(rec.pusher, want, atol=1e-12)
    np.testing.assert_allclose(rec.pose[:, 2], 0.5 * (rec.time + t[0]), atol=1e-12)


def test_identify_from_a_recording_gives_the_shards_result(tiny, tmp_path):
    """A simulated object written as a recording is read back with the shard's settings and
    pushes, and identified to the very same estimate."""
    from pushtoknow.identification.fit import identify
    from pushtoknow.identification.identify_config import IdentifyConfig
    from pushtoknow.identification.recordings import load_recorded_objects, replay_scene

    ep = _episode(tiny)
    path = write_recording(tmp_path / "rec.h5", ep.records, recording_meta(ep.spec, SHORT))
    (from_shard,) = load_recorded_objects(tiny)
    (from_file,) = load_recorded_objects(path)
    assert from_file.sim_config == from_shard.sim_config
    np.testing.assert_array_equal(from_file.truth, from_shard.truth)
    cfg = IdentifyConfig(workers=1)
    want = identify(from_shard.records[:1], replay_scene(from_shard), cfg, seed=0)
    got = identify(from_file.records[:1], replay_scene(from_file), cfg, seed=0)
    np.testing.assert_allclose(got.mean, want.mean, rtol=1e-9)
    np.testing.assert_allclose(got.std, want.std, rtol=1e-9)
    assert got.unidentified == want.unidentified


def test_identify_cli_reads_a_recording(tiny, tmp_path):
    """`pushtoknow identify --pushes FILE` on a recording without a noise level or the
    release push: estimates as JSON, the unknown truth as null."""
    import json
    import os
    import subprocess
    from dataclasses import replace

    ep = _episode(tiny)
    meta = replace(recording_meta(ep.spec, SHORT), force_noise_std=None)
    meta = replace(meta, truth=np.r_[meta.truth[:1], np.nan, meta.truth[2:]])
    path = write_recording(tmp_path / "rec.h5", ep.records[:1], meta)
    r = subprocess.run(
        [*CLI, "identify", "--pushes", str(path), "--workers", "1", "--json"],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        check=False,
    )
    assert r.returncode == 0, r.stderr
    (obj,) = json.loads(r.stdout)["objects"]
    assert obj["name"] == "tiny" and obj["truth"][1] is None
    lo, hi = obj["mu_m"]["interval"]
    assert lo <= 0.25 <= hi


def test_pushes_of_different_lengths_are_replayed_each_over_its_own(tiny, tmp_path):
    """The longest push sets the replay's horizon and follows its profile; a shorter one is
    replayed along its recorded pad track, over its own length."""
    from pushtoknow.identification.fit import tracks_from_records
    from pushtoknow.identification.recordings import load_recorded_objects

    rec = _episode(tiny).records[0]
    short = PushRecord(
        rec.push, rec.time[:15], rec.pose[:15], rec.tactile[:15], rec.force_clean[:15],
        rec.pusher[:15], None, None, None,
    )  # fmt: skip
    path = write_recording(tmp_path / "rec.h5", [rec, short], recording_meta(SPEC, SHORT))
    (obj,) = load_recorded_objects(path)
    long_track, short_track = tracks_from_records(obj.records, obj.sim_config)
    assert long_track.pad is None
    assert short_track.pad is not None and len(short_track.pad) == len(short_track.pose) == 15


def test_pusher_friction_is_read_checked_and_reaches_the_replay_settings(tmp_path):
    from pushtoknow.identification.prior import EVERYDAY_PRIOR
    from pushtoknow.identification.recordings import load_recorded_objects

    meta, _ = read_recording(_write_raw(tmp_path / "plain.h5", [_synthetic()]))
    assert meta.pusher_friction == 0.0  # absent: the testbed's frictionless pad
    path = _write_raw(tmp_path / "f.h5", [_synthetic()], pusher_friction=0.3)
    assert read_recording(path)[0].pusher_friction == 0.3
    (obj,) = load_recorded_objects(path)
    assert obj.sim_config.pad.friction == 0.3
    assert obj.prior == EVERYDAY_PRIOR  # a recording is of a real object
    _check_fails(_write_raw(tmp_path / "bad.h5", [_synthetic()], pusher_friction=-0.1),
                 "pusher_friction=-0.1")  # fmt: skip


def test_a_finer_pusher_track_reaches_the_replay_only_where_the_pad_track_is_replayed(tiny):
    """`PushRecord.pusher_fine` drives a replayed pad track (a real pusher's); a push replayed
    by its own profile has no pad track and ignores it."""
    import dataclasses

    from pushtoknow.identification.fit import tracks_from_records

    rec = _episode(tiny).records[0]
    fine = np.column_stack([rec.time, rec.pusher])
    short = dataclasses.replace(
        rec, time=rec.time[:15], pose=rec.pose[:15], tactile=rec.tactile[:15],
        force_clean=rec.force_clean[:15], pusher=rec.pusher[:15], rgb=None, depth=None,
        s0=None, pusher_fine=fine[:20],
    )  # fmt: skip
    whole = dataclasses.replace(rec, rgb=None, depth=None, s0=None, pusher_fine=fine)
    long_track, short_track = tracks_from_records([whole, short], SHORT)
    assert long_track.pad is None and long_track.pad_fine is None
    np.testing.assert_array_equal(short_track.pad_fine, fine[:20])
