"""Reading pushes to identify from a dataset, and the footprint choices."""

import dataclasses

import h5py
import numpy as np
import pytest
from identify_data import SHORT, SPEC, write_tiny_dataset

from pushtoknow.common.errors import DatasetError, IdentificationError
from pushtoknow.datasets.shards import shard_path
from pushtoknow.identification.fit import tracks_from_records
from pushtoknow.identification.recordings import (
    footprint_from_mask,
    load_recorded_objects,
    parse_shape,
    replay_scene,
)
from pushtoknow.testbed.shapes import footprint_from_shape


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    return write_tiny_dataset(tmp_path_factory.mktemp("ds"))


def test_reads_objects_pushes_truth_and_settings(tiny):
    (obj,) = load_recorded_objects(tiny)
    assert obj.name == "tiny" and len(obj.records) == 1
    np.testing.assert_allclose(obj.truth, SPEC.params.as_array())
    assert obj.sim_config.push.horizon == 2.0
    assert obj.records[0].rgb is None and obj.records[0].s0 is not None
    tracks = tracks_from_records(obj.records, obj.sim_config)
    assert tracks[0].force.shape == (21, 2)


def test_footprint_from_mask_is_close_to_the_true_one(tiny):
    (obj,) = load_recorded_objects(tiny)
    shape, offset = footprint_from_mask(obj)
    est = footprint_from_shape(shape).polygon
    true = SPEC.footprint.polygon
    # traced on the 256 px mask (2.4 mm pixels) on the object's top plane, smoothed by 5 mm:
    # measured area −1.1 %, Hausdorff 4.1 mm at the rounded corners (on the 64 px S_0: 5.7 mm)
    assert est.area == pytest.approx(true.area, rel=0.02)
    assert est.hausdorff_distance(true) < 5e-3
    assert np.hypot(*offset) < 1e-3
    scene = replay_scene(obj, "from-mask")
    assert scene.frame_offset == offset and scene.sim_config.render is False


def test_empty_dataset_missing_shape_and_wrong_schema_name_the_problem(tmp_path, tiny):
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(IdentificationError, match="empty dataset"):
        load_recorded_objects(empty)
    with pytest.raises(IdentificationError, match="no such dataset"):
        load_recorded_objects(tmp_path / "nowhere")
    with pytest.raises(IdentificationError, match="no such file or shape name"):
        parse_shape("no-such-shape")
    (obj,) = load_recorded_objects(tiny)
    with pytest.raises(IdentificationError, match="no such file or shape name"):
        replay_scene(obj, "no-such-shape")
    bad = tmp_path / "bad"
    bad.mkdir()
    with h5py.File(shard_path(bad, 0), "w") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(DatasetError, match="schema version 99"):
        load_recorded_objects(bad)


def test_given_shapes_parse(tmp_path):
    assert parse_shape("rect1")["type"] == "rectangle"
    assert parse_shape('{"type": "ellipse", "a": 0.05, "b": 0.04}')["a"] == 0.05
    f = tmp_path / "obj.yaml"
    f.write_text("shape: {type: rectangle, width: 0.1, height: 0.05}\nmass: 1\n")
    assert parse_shape(str(f))["width"] == 0.1


def test_a_pad_track_off_its_profile_is_replayed_along_the_recording(tiny):
    """A push that follows its speed profile over the whole horizon is replayed with it; one
    whose pad departs from it (a real pusher) or that is shorter (a profile replays the whole
    horizon) is replayed along its recorded track, so pushes may differ in length; a
    non-finite track is refused, naming the push and the track."""
    (obj,) = load_recorded_objects(tiny)
    rec = obj.records[0]
    assert tracks_from_records([rec], obj.sim_config)[0].pad is None
    bent = dataclasses.replace(rec, pusher=rec.pusher.copy())
    bent.pusher[5:] += 0.01
    short = dataclasses.replace(
        rec, time=rec.time[:12], pose=rec.pose[:12], tactile=rec.tactile[:12],
        pusher=rec.pusher[:12],
    )  # fmt: skip
    tracks = tracks_from_records([bent, short], obj.sim_config)
    np.testing.assert_array_equal(tracks[0].pad, bent.pusher)
    np.testing.assert_array_equal(tracks[1].pad, short.pusher)
    assert len(tracks[1].pose) == 12
    broken = dataclasses.replace(rec, pose=rec.pose.copy())
    broken.pose[3, 0] = np.nan
    with pytest.raises(IdentificationError, match="push 1: non-finite values in its pose"):
        tracks_from_records([rec, broken], obj.sim_config)


def test_an_inference_run_keeps_its_pushes_for_identify(tmp_path, tiny):
    """`write_run_pushes` (what `infer --out RUN` calls) keeps the executed pushes in
    RUN/pushes, and `--pushes RUN` reads them back with the object's spec."""
    from pushtoknow.datasets.shards import read_shard, write_run_pushes

    (episode,) = read_shard(next(iter(sorted(tiny.glob("shard-*.h5")))))
    run = tmp_path / "run"
    write_run_pushes(run, episode.spec, episode.records, SHORT.model_dump_json())
    (obj,) = load_recorded_objects(run)
    assert obj.name == "tiny" and len(obj.records) == len(episode.records)
    np.testing.assert_array_equal(obj.records[0].pusher, episode.records[0].pusher)
    assert obj.sim_config == SHORT
    with pytest.raises(IdentificationError, match="nor an inference run"):
        load_recorded_objects(tmp_path)


def test_identify_with_the_footprint_from_the_mask(tiny):
    """With the footprint traced on the outline-resolution mask, μ·m comes out within 5%; the
    CoM, which one 2 s push barely shows, is reported in the record's frame and within its
    uncertainty (measured: 10 mm off, z 0.9 and −0.3)."""
    from pushtoknow.identification.fit import identify
    from pushtoknow.identification.identify_config import IdentifyConfig

    (obj,) = load_recorded_objects(tiny)
    res = identify(obj.records, replay_scene(obj, "from-mask"), IdentifyConfig(workers=1))
    assert abs(res.mu_m / (0.5 * 0.5) - 1) < 0.05
    assert np.hypot(*(res.mean[2:4] - SPEC.params.as_array()[2:4])) < 0.015
    z = res.zscore(SPEC.params.as_array())
    assert np.isfinite(z).all() and (np.abs(z[2:4]) < 2).all()
    # the CoM is reported from the posterior truncated to the fit footprint's hull less the
    # testbed's margin, moved into the record's frame like the CoM itself
    from pushtoknow.common.estimate import com_region, estimate_from_belief
    from pushtoknow.testbed.objects import COM_MARGIN

    scene = replay_scene(obj, "from-mask")
    offset = np.array(scene.frame_offset)
    region = com_region(scene.footprint.vertices, COM_MARGIN) + offset
    outline = scene.footprint.vertices + offset  # bounds I_z ≤ m·r²
    want = estimate_from_belief(res.mean_norm, res.cov_norm, region, res.level, outline)
    np.testing.assert_array_equal(res.mean, want.mean)
    np.testing.assert_array_equal(res.upper, want.upper)
    assert ((res.lower <= res.mean) & (res.mean <= res.upper)).all()
