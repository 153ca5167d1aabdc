"""MIT Push → shards: rendering from recorded poses, the shift, actions, filters and resume."""

from __future__ import annotations

import dataclasses
import json
import math
from pathlib import Path

import h5py
import numpy as np
import pytest

from helpers import iou, rasterise_footprint
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import GRAVITY
from pushtoknow.datasets.mit_import import (
    FALLBACK_FRICTION,
    IMPORT_FILE,
    IMPORT_VERSION,
    TACTILE_CONVENTION,
    MitImportResult,
    import_mit_dataset,
    mit_sim_config,
    push_action,
    speed_from_mm_per_s,
)
from pushtoknow.datasets.mit_push import (
    PUSHER_RADIUS,
    estimate_friction,
    mit_object,
    mit_polygon,
    read_mit_push,
)
from pushtoknow.datasets.shards import dataset_info, read_shard, shard_path

SAMPLE_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets" / "mit-push-sample"
CENTRE_PUSH = "motion_surface=plywood_shape=rect1_a=0_v=100_i=1.000_s=0.500_t=0.000.json"
T0 = 1_476_729_000.0  # Unix s, like the real files
CAMERA = mit_sim_config().camera.model()

# Synthetic rect3 push (see _streams): pusher along the object's +x axis at θ0.
THETA0, V, OMEGA, FORCE = 0.6, 0.05, 0.2, 3.0  # rad, m/s, rad/s, N
DRIFT, SIDE = 0.3, 0.02  # rad between the object's and the pusher's motion; m of side-step
C0 = np.array([0.35, 0.02])  # m, robot frame, like the real files
GAP, T_MOVE, T_STOP, T_END = 0.0125, 0.5, 2.5, 3.0  # m, s, s, s
T_CONTACT = T_MOVE + GAP / V  # 0.75 s
RECT3_HALF_X = 0.135 / 2


# ------------------------------------------------------------------------------------------
# helpers
# ------------------------------------------------------------------------------------------
def _name(shape="rect3", surface="abs", a="0", v="50", i="0.000", s="0.500", t="0.000", ext="json"):
    return f"motion_surface={surface}_shape={shape}_a={a}_v={v}_i={i}_s={s}_t={t}.{ext}"


def _streams(touch: bool = True) -> dict[str, np.ndarray]:
    """rect3 at rest with its centroid at C0, yaw THETA0. The probe first slides SIDE m
    sideways (along n ⊥ u) during [0, 0.3] s, then rests, then approaches along
    u = (cos θ0, sin θ0) from T_MOVE and touches at T_CONTACT; the object then translates at
    V along u_obj (u turned by DRIFT) and turns at OMEGA until T_STOP. The probe reads
    -FORCE·u while touching (0 if not `touch`, and then the object stays put). Streams at
    250/200/500 Hz, common span [0, T_END], Unix times; force samples sit between 10 Hz
    window edges (50 per window) and start 0.1 s early (window 0, [-0.1, 0) s, has them).
    Contact [T_CONTACT, T_STOP) = [0.75, 2.5) s: windows [t_k - 0.1, t_k) of samples 8
    (half) to 25."""
    u = np.array([math.cos(THETA0), math.sin(THETA0)])
    n = np.array([-u[1], u[0]])
    u_obj = np.array([math.cos(THETA0 + DRIFT), math.sin(THETA0 + DRIFT)])
    t_tip, t_obj = (np.arange(int(T_END * r) + 1) / r for r in (250, 200))
    t_ft = -0.1 + (np.arange(int((T_END + 0.2) * 500)) + 0.5) / 500  # off the window edges
    d = V * np.clip(t_tip - T_MOVE, 0.0, T_STOP - T_MOVE)
    side = SIDE * np.clip(1.0 - t_tip / 0.3, 0.0, 1.0)
    tip_xy = C0 - (RECT3_HALF_X + PUSHER_RADIUS + GAP) * u + d[:, None] * u + side[:, None] * n
    s = np.clip(t_obj - T_CONTACT, 0.0, T_STOP - T_CONTACT) * (1.0 if touch else 0.0)
    obj_xy = C0 + (V * s)[:, None] * u_obj
    f = np.where((t_ft >= T_CONTACT) & (t_ft < T_STOP) & touch, FORCE, 0.0)
    return {
        "tip_pose": np.column_stack([T0 + t_tip, tip_xy, 0 * t_tip]),
        "object_pose": np.column_stack([T0 + t_obj, obj_xy, THETA0 + OMEGA * s]),
        "ft_wrench": np.column_stack([T0 + t_ft, -f * u[0], -f * u[1], 0 * t_ft]),
    }


def _write(path: Path, streams: dict[str, np.ndarray]) -> Path:
    """Same schema as the dataset: .json lists of [t, ., ., .] rows, .h5 N×4 root datasets."""
    if path.suffix == ".json":
        path.write_text(json.dumps({k: v.tolist() for k, v in streams.items()}))
    else:
        with h5py.File(path, "w") as h5:
            for k, v in streams.items():
                h5.create_dataset(k, data=v)
    return path


def _object_mask(rgb: np.ndarray) -> np.ndarray:
    """Object pixels of a rendered frame by colour (orange object with its near-black orientation
    marker, grey table, blue pad)."""
    r, g, b = (rgb[..., i].astype(int) for i in range(3))
    return ((r > 150) & (r - b > 100)) | (np.maximum(np.maximum(r, g), b) < 90)


def _mask_centroid(mask: np.ndarray) -> np.ndarray:
    v, u = np.nonzero(mask)
    return np.array([u.mean(), v.mean()])


def _shards(out: Path):
    return [ep for p in sorted(out.glob("shard-*.h5")) for ep in read_shard(p)]


@pytest.fixture(scope="module")
def sample_dir() -> Path:
    if not SAMPLE_DIR.is_dir():
        pytest.skip(f"MIT Push sample files not found at {SAMPLE_DIR} (real-data tests skipped)")
    return SAMPLE_DIR.resolve()


@pytest.fixture(scope="module")
def sample_import(sample_dir, tmp_path_factory) -> tuple[Path, MitImportResult]:
    out = tmp_path_factory.mktemp("mit_sample")
    res = import_mit_dataset(sample_dir, out, acceleration=0, speed=0.1, progress=False)
    return out, res


@pytest.fixture(scope="module")
def synth_dir(tmp_path_factory) -> Path:
    """Four files: rect3 a=0 v=50 (json), rect3 a=0 v=20 (h5), rect3 a=1 v=50 (json),
    tri1 a=0 v=50 without contact (h5), all on surface 'abs'."""
    d = tmp_path_factory.mktemp("mit_synth")
    _write(d / _name(), _streams())
    _write(d / _name(v="20", ext="h5"), _streams())
    _write(d / _name(a="1"), _streams())
    _write(d / _name(shape="tri1", ext="h5"), _streams(touch=False))
    return d


@pytest.fixture(scope="module")
def synth_import(synth_dir, tmp_path_factory) -> tuple[Path, MitImportResult]:
    out = tmp_path_factory.mktemp("mit_synth_out")
    res = import_mit_dataset(synth_dir, out, shape="rect3", acceleration=0, speed=0.05,
                             progress=False)  # fmt: skip
    return out, res


# ------------------------------------------------------------------------------------------
# real sample files
# ------------------------------------------------------------------------------------------
def test_sample_counts_and_readers(sample_import):
    out, res = sample_import
    assert res.to_json() == {
        "files": 3,
        "pushes": 3,
        "objects": 1,
        "shards_written": 1,
        "shards_skipped": 0,
    }
    info = dataset_info(out)
    expected_steps = sum(len(read_mit_push(p)) for p in sorted(SAMPLE_DIR.glob("*.json")))
    assert (info.shards, info.objects, info.pushes) == (1, 1, 3)
    assert info.steps == expected_steps
    assert info.image_shape == [64, 64, 3]
    assert info.profiles == {"constant": 3}

    from pushtoknow.datasets.torch_dataset import PushDataset

    ds = PushDataset(out)
    assert len(ds) == 3
    item = ds[0]
    T = item["time"].shape[0]
    assert item["rgb"].shape == (T, 3, 64, 64) and item["depth"].shape == (T, 1, 64, 64)
    assert item["s0"].shape == (1, 64, 64) and item["s0"].sum() > 50
    np.testing.assert_allclose(item["params"][[0, 4]].numpy(), [0.8374, 1.131e-3], rtol=1e-6)


def test_sample_spec_shift_and_tactile(sample_import, sample_dir):
    out, _ = sample_import
    (ep,) = _shards(out)
    obj = mit_object("rect1")
    p = ep.spec.params
    assert (p.mass, p.inertia, p.com_x, p.com_y) == (obj.mass, obj.inertia, 0.0, 0.0)
    assert ep.spec.height == 0.013 and ep.spec.shape["type"] == "polygon"
    np.testing.assert_allclose(ep.spec.footprint.vertices, mit_polygon("rect1"), atol=1e-12)
    pushes = [read_mit_push(sample_dir / f) for f in _files_of(out)]
    assert p.friction == pytest.approx(np.median([estimate_friction(m) for m in pushes]))
    with h5py.File(shard_path(out, 0)) as f:
        assert f.attrs["source"] == "mit-push"
        shifts = [f["objects/0/pushes"][str(k)].attrs["mit_shift"] for k in range(3)]
    for rec, mit, shift in zip(ep.records, pushes, shifts):
        np.testing.assert_array_equal(rec.pose[0, :2], [0.0, 0.0])  # initial centroid at origin
        np.testing.assert_allclose(shift, -mit.object_pose[0, :2])
        np.testing.assert_allclose(rec.pose[:, :2] - shift, mit.object_pose[:, :2], atol=1e-12)
        np.testing.assert_array_equal(rec.pose[:, 2], mit.object_pose[:, 2])
        np.testing.assert_allclose(rec.pusher - shift, mit.tip_pose, atol=1e-12)
        np.testing.assert_array_equal(rec.tactile[:, :2], mit.force)
        np.testing.assert_array_equal(rec.tactile[:, 2], mit.contact.astype(float))
        assert rec.force_clean is None  # a real push has no noiseless force
        np.testing.assert_array_equal(rec.time, mit.times)
        assert rec.push.speed == 0.1 and rec.push.profile == "constant"


def _files_of(out: Path) -> list[str]:
    info = json.loads((out / IMPORT_FILE).read_text())
    return [f for sh in info["shards"] for o in sh["objects"] for f in o["files"]]


def test_sample_rendered_frames_follow_recorded_pose(sample_import):
    out, _ = sample_import
    (ep,) = _shards(out)
    poly = mit_polygon("rect1")
    for rec in ep.records:
        truth0 = rasterise_footprint(poly, rec.pose[0], CAMERA)
        assert iou(rec.s0, truth0) >= 0.8
        # The colour mask of the first RGB frame is S_0 (the renderer's two passes agree).
        assert iou(_object_mask(rec.rgb[0]), rec.s0) >= 0.95
        last = _object_mask(rec.rgb[-1])
        err = np.linalg.norm(_mask_centroid(last) - CAMERA.world_to_pixel(rec.pose[-1, :2]))
        assert err <= 1.5
        # The object really moved: the last frame is not where the first one was.
        moved_px = np.linalg.norm(CAMERA.world_to_pixel(rec.pose[-1, :2]) - CAMERA.principal_point)
        assert moved_px > 2.0
        assert np.linalg.norm(_mask_centroid(last) - _mask_centroid(rec.s0)) > 2.0
        # Depth: table at the camera height, the object's top 13 mm closer.
        assert rec.depth[0][~rec.s0].max() == pytest.approx(0.75, abs=2e-3)
        assert np.median(rec.depth[0][rec.s0]) == pytest.approx(0.75 - 0.013, abs=2e-3)


def test_sample_actions(sample_import, sample_dir):
    out, _ = sample_import
    (ep,) = _shards(out)
    poly = mit_polygon("rect1")
    for name, rec in zip(_files_of(out), ep.records):
        mit = read_mit_push(sample_dir / name)
        first = int(np.argmax(mit.contact))
        assert first >= 1  # no sample file is in contact in window 0
        k = first - 1  # onset: the last sample before contact, the window start of first contact
        tip = rec.pusher[k]
        cp = np.asarray(rec.push.contact)
        # cp lies on the initial boundary, about one probe radius from the tip at the onset.
        c, s = math.cos(rec.pose[0, 2]), math.sin(rec.pose[0, 2])
        cp_obj = np.array([[c, s], [-s, c]]) @ (cp - rec.pose[0, :2])
        assert np.max(np.abs(cp_obj)) == pytest.approx(0.045, abs=1e-9)  # on rect1's square
        assert abs(np.linalg.norm(cp - tip) - PUSHER_RADIUS) < 1e-3
        assert rasterise_footprint(poly, rec.pose[0], CAMERA).any()
    centre = _files_of(out).index(CENTRE_PUSH)
    # Centre push: the pusher moves along world +y (see the reader's module doc).
    assert ep.records[centre].push.direction == pytest.approx(math.pi / 2, abs=math.radians(5))


# ------------------------------------------------------------------------------------------
# synthetic files
# ------------------------------------------------------------------------------------------
def test_synthetic_conversion_exact(synth_import, synth_dir):
    out, res = synth_import
    assert res.to_json() == {
        "files": 1,
        "pushes": 1,
        "objects": 1,
        "shards_written": 1,
        "shards_skipped": 0,
    }
    (ep,) = _shards(out)
    (rec,) = ep.records
    assert len(rec.time) == 30  # 3 s at 10 Hz
    u = np.array([math.cos(THETA0), math.sin(THETA0)])
    np.testing.assert_array_equal(rec.pose[0], [0.0, 0.0, THETA0])
    s_end = T_STOP - T_CONTACT
    u_obj = np.array([math.cos(THETA0 + DRIFT), math.sin(THETA0 + DRIFT)])
    np.testing.assert_allclose(rec.pose[-1, :2], V * s_end * u_obj, atol=1e-9)
    assert rec.pose[-1, 2] == pytest.approx(THETA0 + OMEGA * s_end, abs=1e-9)
    start = -(RECT3_HALF_X + PUSHER_RADIUS + GAP) * u + SIDE * np.array([-u[1], u[0]])
    np.testing.assert_allclose(rec.pusher[0], start, atol=1e-9)
    # Action: direction of the tip's travel while in contact (not the object's motion, not
    # the whole tip path with its side-step), cp at the middle of the pushed (-x) face.
    assert rec.push.direction == pytest.approx(THETA0, abs=1e-9)
    np.testing.assert_allclose(rec.push.contact, -RECT3_HALF_X * u, atol=1e-9)
    assert rec.push.speed == 0.05
    # Tactile: force on the object along u while touching, in the windows [t_k - 0.1, t_k)
    # ending at samples 8 (half: contact from 0.75 s) to 25 ([2.4, 2.5)), as the simulator.
    contact = rec.tactile[:, 2]
    np.testing.assert_array_equal(np.flatnonzero(contact), np.arange(8, 26))
    np.testing.assert_allclose(rec.tactile[10, :2], FORCE * u, atol=1e-9)
    np.testing.assert_allclose(rec.tactile[25, :2], FORCE * u, atol=1e-9)
    np.testing.assert_allclose(rec.tactile[8, :2], 0.5 * FORCE * u, atol=1e-9)  # half window
    for k in (0, 7, 26, 29):  # window 0 lies before t_start: raw samples there, at rest
        np.testing.assert_array_equal(rec.tactile[k, :2], 0.0)
    mean_f = (0.5 * FORCE + 17 * FORCE) / 18
    assert ep.spec.params.friction == pytest.approx(mean_f / (mit_object("rect3").mass * GRAVITY))


def test_synthetic_frames_rotate_and_move_with_the_pose(synth_import):
    """rect3 is elongated: a wrong yaw sign or a missing shift would fail these IoUs."""
    out, _ = synth_import
    (rec,) = _shards(out)[0].records
    poly = mit_polygon("rect3")
    assert iou(rec.s0, rasterise_footprint(poly, rec.pose[0], CAMERA)) >= 0.8
    assert iou(rec.s0, rasterise_footprint(poly, [0, 0, -THETA0], CAMERA)) < 0.6
    last = _object_mask(rec.rgb[-1])
    assert iou(last, rasterise_footprint(poly, rec.pose[-1], CAMERA)) >= 0.8
    assert iou(last, rasterise_footprint(poly, rec.pose[0], CAMERA)) < 0.5
    err = np.linalg.norm(_mask_centroid(last) - CAMERA.world_to_pixel(rec.pose[-1, :2]))
    assert err <= 1.5
    for k in (10, 20):  # intermediate frames too
        mask = _object_mask(rec.rgb[k])
        assert iou(mask, rasterise_footprint(poly, rec.pose[k], CAMERA)) >= 0.8


def test_import_json_and_attrs(synth_import, synth_dir):
    out, _ = synth_import
    info = json.loads((out / IMPORT_FILE).read_text())
    assert info["source"]["directory"] == str(synth_dir.resolve())
    assert info["filters"]["speed_m_per_s"] == 0.05 and info["filters"]["speed_mm_per_s"] == 50
    assert info["filters"]["acceleration"] == 0 and info["filters"]["shape"] == "rect3"
    assert "shift" in info["shift_convention"] and info["rate_hz"] == 10.0
    assert info["shards"][0]["objects"][0]["files"] == [_name()]
    with h5py.File(shard_path(out, 0)) as f:
        assert f.attrs["fingerprint"] == info["fingerprint"]
        g = f["objects/0"]
        assert g.attrs["mit_shape"] == "rect3" and g.attrs["mit_surface"] == "abs"
        pa = g["pushes/0"].attrs
        assert pa["mit_file"] == _name()
        np.testing.assert_allclose(pa["mit_shift"], -C0, atol=1e-12)
        assert pa["mit_t0"] == T0
        assert list(pa["mit_contact_span"]) == [8, 25]
        assert "[t_k - 1/rate, t_k)" in f.attrs["tactile_convention"]
        assert json.loads(pa["mit_meta"])["speed_m_per_s"] == 0.05
    assert info["import_version"] == IMPORT_VERSION == 3
    assert info["tactile_convention"] == TACTILE_CONVENTION


def test_filters_select_subset(synth_dir, tmp_path):
    # speed 50 mm/s, constant speed: rect3 (json) and tri1 → two objects, one per shard.
    res = import_mit_dataset(synth_dir, tmp_path / "a", acceleration=0,
                             speed=speed_from_mm_per_s(50), objects_per_shard=1,
                             progress=False)  # fmt: skip
    assert res.to_json() == {
        "files": 2,
        "pushes": 2,
        "objects": 2,
        "shards_written": 2,
        "shards_skipped": 0,
    }
    eps = _shards(tmp_path / "a")
    assert [e.spec.name for e in eps] == ["mit:abs:rect3", "mit:abs:tri1"]
    assert [e.object_index for e in eps] == [0, 1]
    assert all(r.push.speed == 0.05 for e in eps for r in e.records)
    # tri1 was never touched: no valid friction estimate → the documented fallback.
    assert eps[1].spec.params.friction == FALLBACK_FRICTION
    with h5py.File(shard_path(tmp_path / "a", 1)) as f:
        assert f["objects/1"].attrs["friction_source"] == "fallback"
        assert math.isnan(f["objects/1/pushes/0"].attrs["mit_friction"])
    # No acceleration filter: rect3 at 50 mm/s with a=0 and a=1.
    res = import_mit_dataset(synth_dir, tmp_path / "b", shape="rect3", speed=0.05, progress=False)
    assert (res.files, res.objects, dataset_info(tmp_path / "b").pushes) == (2, 1, 2)
    # Only a speed filter at 20 mm/s: the .h5 file.
    res = import_mit_dataset(synth_dir, tmp_path / "c", speed=0.02, progress=False)
    assert res.files == 1
    (ep,) = _shards(tmp_path / "c")
    assert ep.records[0].push.speed == 0.02
    assert speed_from_mm_per_s(20) == 0.02


def test_no_contact_action_falls_back(synth_dir):
    push = read_mit_push(synth_dir / _name(shape="tri1", ext="h5"))
    assert not push.contact.any()
    a = push_action(push)
    travel = push.tip_pose[-1] - push.tip_pose[0]  # whole tip travel, side-step included
    assert a.direction == pytest.approx(math.atan2(travel[1], travel[0]), abs=1e-9)
    assert abs(a.direction - THETA0) > 0.05
    poly = mit_polygon("tri1")
    c, s = math.cos(THETA0), math.sin(THETA0)
    cp_obj = np.array([[c, s], [-s, c]]) @ np.asarray(a.contact)  # initial centroid at 0
    from shapely.geometry import Point, Polygon

    assert Polygon(poly).exterior.distance(Point(*cp_obj)) < 1e-9


def test_action_uses_the_sample_before_first_contact(synth_dir):
    """cp/direction use the onset sample (first contact - 1), clamped to 0 when contact is
    already felt in window 0 (it lies before t_start)."""
    push = read_mit_push(synth_dir / _name())
    assert int(np.argmax(push.contact)) == 8
    a = push_action(push)
    u = np.array([math.cos(THETA0), math.sin(THETA0)])
    shift = -C0
    np.testing.assert_allclose(a.contact, -RECT3_HALF_X * u, atol=1e-9)  # tip at t_7: at rest
    assert a.direction == pytest.approx(THETA0, abs=1e-9)
    # The first contact sample itself (t_8) would not do: the object has moved and turned.
    moved = push.object_pose[8] - push.object_pose[0]
    assert np.linalg.norm(moved[:2]) > 1e-3 and abs(moved[2]) > 5e-3
    # Contact from window 0: onset = sample 0, direction over the whole contact phase
    # (here the whole push, side-step included).
    early = dataclasses.replace(push, contact=np.ones(len(push), dtype=bool))
    b = push_action(early, shift)
    d = push.tip_pose[-1] - push.tip_pose[0]
    assert b.direction == pytest.approx(math.atan2(d[1], d[0]), abs=1e-12)
    th0 = push.object_pose[0, 2]
    c, s = math.cos(th0), math.sin(th0)
    tip_obj = np.array([[c, s], [-s, c]]) @ (push.tip_pose[0] - push.object_pose[0, :2])
    cp_obj = np.array([[c, s], [-s, c]]) @ (np.asarray(b.contact) - shift - C0)
    assert cp_obj[0] == pytest.approx(-RECT3_HALF_X, abs=1e-9)  # on the pushed face
    assert cp_obj[1] == pytest.approx(tip_obj[1], abs=1e-9)  # straight across from the tip
    # A single contact sample: direction from the tip's travel over that one window.
    one = np.zeros(len(push), dtype=bool)
    one[12] = True
    d1 = push.tip_pose[12] - push.tip_pose[11]
    g = push_action(dataclasses.replace(push, contact=one), shift)
    assert np.linalg.norm(d1) == pytest.approx(V / 10, rel=1e-5)  # Unix-time rounding
    assert g.direction == pytest.approx(math.atan2(d1[1], d1[0]), abs=1e-12)


def test_resume_skips_finished_shards(synth_dir, tmp_path):
    kw = dict(acceleration=0, speed=0.05, objects_per_shard=1, progress=False)
    out = tmp_path / "out"
    first = import_mit_dataset(synth_dir, out, **kw)
    assert (first.shards_written, first.shards_skipped) == (2, 0)
    stamps = [shard_path(out, i).stat().st_mtime_ns for i in range(2)]
    again = import_mit_dataset(synth_dir, out, **kw)
    assert (again.shards_written, again.shards_skipped, again.pushes) == (0, 2, 0)
    assert [shard_path(out, i).stat().st_mtime_ns for i in range(2)] == stamps
    # An interrupted run: one shard missing, a stale part file left behind.
    shard_path(out, 1).unlink()
    (out / "shard-00001.h5.part").write_bytes(b"partial")
    third = import_mit_dataset(synth_dir, out, **kw)
    assert (third.shards_written, third.shards_skipped, third.pushes) == (1, 1, 1)
    assert shard_path(out, 0).stat().st_mtime_ns == stamps[0]
    assert not list(out.glob("*.part")) and not list(out.glob("*.tmp"))
    assert dataset_info(out).pushes == 2
    # Other settings into the same directory: refused.
    with pytest.raises(DatasetError, match="other files or settings"):
        import_mit_dataset(synth_dir, out, **{**kw, "speed": 0.02})


def test_no_match_names_directory_and_filters(synth_dir, tmp_path):
    with pytest.raises(DatasetError) as e:
        import_mit_dataset(synth_dir, tmp_path / "o", surface="delrin", speed=0.02,
                           progress=False)  # fmt: skip
    msg = str(e.value)
    assert str(synth_dir) in msg and "surface=delrin" in msg and "speed_m_per_s=0.02" in msg
    assert not (tmp_path / "o").exists()
    empty = tmp_path / "empty"
    empty.mkdir()
    with pytest.raises(DatasetError, match="no MIT Push files"):
        import_mit_dataset(empty, tmp_path / "o", progress=False)


def test_fine_pusher_follows_the_raw_tip_without_its_stamp_jitter(tmp_path):
    """The raw tip stream on the record's clock, shifted: 4 ms apart from one sample before the
    first to one after the last, on the tip's path (a moving average of a straight line is the
    line), its speed steady where the raw rows', read between jittered stamps, spike."""
    from pushtoknow.datasets.mit_import import FINE_PERIOD, fine_pusher

    streams = _streams()
    rng = np.random.default_rng(0)
    tip = streams["tip_pose"].copy()
    tip[1:-1, 0] += rng.uniform(-1.5e-3, 1.5e-3, len(tip) - 2)  # stamps jitter, rows do not
    streams["tip_pose"] = tip
    push = read_mit_push(_write(tmp_path / _name(), streams))
    shift = np.array([0.1, -0.2])
    fine = fine_pusher(push, shift)
    t = fine[:, 0]
    np.testing.assert_allclose(np.diff(t), FINE_PERIOD, atol=1e-9)
    assert t[0] == pytest.approx(0.0, abs=FINE_PERIOD)  # the raw stream starts at t_start
    assert t[-1] == pytest.approx(push.times[-1] + 0.1, abs=FINE_PERIOD)
    u = np.array([math.cos(THETA0), math.sin(THETA0)])
    true_xy = C0 - (RECT3_HALF_X + PUSHER_RADIUS + GAP) * u + V * np.clip(
        t - T_MOVE, 0.0, T_STOP - T_MOVE
    )[:, None] * u  # fmt: skip
    steady = (t > T_MOVE + 0.05) & (t < T_STOP - 0.05)
    # within the stamps' jitter × speed (75 µm), averaged over 5 rows
    np.testing.assert_allclose(fine[steady, 1:] - shift, true_xy[steady], atol=5e-5)
    speed = np.linalg.norm(np.diff(fine[:, 1:], axis=0), axis=1) / FINE_PERIOD
    raw_speed = np.linalg.norm(np.diff(tip[:, 1:3], axis=0), axis=1) / np.diff(tip[:, 0])
    moving = (tip[:-1, 0] - T0 > T_MOVE + 0.05) & (tip[:-1, 0] - T0 < T_STOP - 0.05)
    assert raw_speed[moving].max() > 2 * V
    assert speed[steady[:-1] & steady[1:]].max() < 1.3 * V
