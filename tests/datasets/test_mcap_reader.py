"""ROS 2 bags and MCAP files (datasets.mcap_reader): simulated pushes written with rosbags'
writer come back as the same pushes; topics, frames and splitting; `identify` on a bag."""

import json
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from rosbags.rosbag2 import StoragePlugin, Writer
from rosbags.typesys import Stores, get_typestore

from pushtoknow.common.errors import DatasetError
from pushtoknow.datasets.mcap_reader import BagOptions, is_bag, read_bag
from pushtoknow.datasets.shards import read_shard

sys.path.insert(0, str(Path(__file__).parents[1] / "identification"))
from identify_data import write_tiny_dataset

TS = get_typestore(Stores.ROS2_HUMBLE)
T0 = 1_700_000_000  # s: a Unix time, as a robot's clock stamps


def _stamp(t: float):
    ns = T0 * 10**9 + int(round(t * 1e9))
    return TS.types["builtin_interfaces/msg/Time"](sec=ns // 10**9, nanosec=ns % 10**9), ns


def _header(t: float, frame: str):
    stamp, ns = _stamp(t)
    return TS.types["std_msgs/msg/Header"](stamp=stamp, frame_id=frame), ns


def _pose_msg(t, x, y, yaw, frame):
    m = TS.types
    header, ns = _header(t, frame)
    q = m["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=np.sin(yaw / 2), w=np.cos(yaw / 2))
    pose = m["geometry_msgs/msg/Pose"](
        position=m["geometry_msgs/msg/Point"](x=x, y=y, z=0.0), orientation=q
    )
    return m["geometry_msgs/msg/PoseStamped"](header=header, pose=pose), ns


def _point_msg(t, x, y, frame):
    m = TS.types
    header, ns = _header(t, frame)
    point = m["geometry_msgs/msg/Point"](x=x, y=y, z=0.0)
    return m["geometry_msgs/msg/PointStamped"](header=header, point=point), ns


def _wrench_msg(t, fx, fy, frame):
    m = TS.types
    header, ns = _header(t, frame)
    v = m["geometry_msgs/msg/Vector3"]
    wrench = m["geometry_msgs/msg/Wrench"](
        force=v(x=fx, y=fy, z=0.0), torque=v(x=0.0, y=0.0, z=0.0)
    )
    return m["geometry_msgs/msg/WrenchStamped"](header=header, wrench=wrench), ns


def write_bag(
    path: Path,
    records,
    starts,
    storage=StoragePlugin.MCAP,
    topics=("/pusher/pose", "/object/pose", "/pusher/wrench"),
    point_pusher=False,
    frames=("world", "world", "world"),
    sign=1.0,
) -> Path:
    """Each record's samples as messages stamped T0 + start + t_k (ns) (one message per topic and
    sample); nothing between records, so the bag pauses there."""
    pusher_type = "PointStamped" if point_pusher else "PoseStamped"
    with Writer(path, version=9, storage_plugin=storage) as w:
        conns = [
            w.add_connection(topics[0], f"geometry_msgs/msg/{pusher_type}", typestore=TS),
            w.add_connection(topics[1], "geometry_msgs/msg/PoseStamped", typestore=TS),
            w.add_connection(topics[2], "geometry_msgs/msg/WrenchStamped", typestore=TS),
        ]
        for r, start in zip(records, starts):
            for k, tk in enumerate(r.time):
                t = start + float(tk)
                px, py = r.pusher[k]
                msgs = [
                    _point_msg(t, px, py, frames[0])
                    if point_pusher
                    else _pose_msg(t, px, py, 0.0, frames[0]),
                    _pose_msg(t, *r.pose[k], frames[1]),
                    _wrench_msg(t, *(sign * r.tactile[k, :2]), frames[2]),
                ]
                for conn, (msg, ns) in zip(conns, msgs):
                    w.write(conn, ns, TS.serialize_cdr(msg, conn.msgtype))
    return path


@pytest.fixture(scope="module")
def sim_records(tmp_path_factory):
    """A simulated constant and release push on the tiny rect1 object (2 s, 10 Hz)."""
    ds = write_tiny_dataset(tmp_path_factory.mktemp("ds"), ("constant", "release"))
    (ep,) = read_shard(ds / "shard-00000.h5")
    return ep.records


def _assert_same_push(got, want):
    np.testing.assert_allclose(got.time, want.time, atol=1e-12)
    np.testing.assert_allclose(got.pusher, want.pusher, atol=1e-9)
    np.testing.assert_allclose(got.pose, want.pose, atol=1e-9)
    np.testing.assert_allclose(got.tactile[:, :2], want.tactile[:, :2], atol=1e-9)


@pytest.mark.parametrize(
    "storage", [StoragePlugin.MCAP, StoragePlugin.SQLITE3], ids=["mcap", "sqlite3"]
)
def test_a_bag_round_trip_split_by_gaps(sim_records, tmp_path, storage):
    """Pushes written as a bag (MCAP or sqlite3), 3 s apart with no messages between, come
    back as the same pushes; the folder and the bare storage file both read."""
    bag = write_bag(tmp_path / "bag", sim_records, [0.0, 5.0], storage)
    assert is_bag(bag)
    meta, records = read_bag(bag, BagOptions(split="gaps", name="box", truth={"mass": 0.5}))
    assert meta.name == "box" and meta.rate == 10.0 and meta.notes == ()
    assert meta.truth[0] == 0.5 and np.isnan(meta.truth[1:]).all()
    assert len(records) == 2
    for got, want in zip(records, sim_records):
        _assert_same_push(got, want)
    # the constant push is derived from the pad's track: its direction and speed
    assert records[0].push.direction == pytest.approx(sim_records[0].push.direction, abs=1e-6)
    assert records[0].push.speed == pytest.approx(0.02, rel=1e-3)
    (storage_file,) = [p for p in bag.iterdir() if p.suffix in (".mcap", ".db3")]
    _, again = read_bag(storage_file, BagOptions(split="gaps"))
    _assert_same_push(again[1], sim_records[1])


def test_a_continuous_bag_is_split_by_contact(sim_records, tmp_path):
    """One continuous stream (the second push right after the first, at another place) is
    cut at the contact phases: each push starts `lead` s before its first contact."""
    rec = sim_records[0]
    bag = write_bag(tmp_path / "bag", [rec, rec], [0.0, 2.1], point_pusher=True)
    meta, records = read_bag(bag, BagOptions(lead=0.3, tail=0.0))
    assert len(records) == 2 and meta.rate == 10.0
    first = int(np.flatnonzero(np.linalg.norm(rec.tactile[:, :2], axis=1) > 0.5)[0])
    for got in records:
        n = len(got.time)
        np.testing.assert_allclose(got.pusher, rec.pusher[first - 3 : first - 3 + n], atol=1e-9)


def test_missing_topic_wrong_type_and_frames_name_the_problem(sim_records, tmp_path):
    bag = write_bag(tmp_path / "bag", sim_records[:1], [0.0])
    with pytest.raises(DatasetError, match=r"--force-topic /ft: no such topic \(topics: "):
        read_bag(bag, BagOptions(force_topic="/ft"))
    with pytest.raises(DatasetError, match="--object-topic /pusher/wrench: type geometry_msgs"):
        read_bag(bag, BagOptions(object_topic="/pusher/wrench"))
    tool = write_bag(tmp_path / "tool", sim_records[:1], [0.0], frames=("world", "world", "tool0"))
    with pytest.raises(DatasetError, match="/pusher/wrench: frame_id 'tool0', other topics in"):
        read_bag(tool)
    with pytest.raises(DatasetError, match="/pusher/pose: frame_id 'world', other topics in 'map'"):
        read_bag(bag, BagOptions(frame="map"))


def test_a_sensor_force_on_the_pad_is_refused_unless_flipped(sim_records, tmp_path):
    bag = write_bag(tmp_path / "bag", sim_records[:1], [0.0], sign=-1.0)
    with pytest.raises(DatasetError, match="push-000/force: points against the push"):
        read_bag(bag)
    _, (rec,) = read_bag(bag, BagOptions(split="gaps", flip_force=True))
    _assert_same_push(rec, sim_records[0])


def test_bag_options_from_yaml_reject_unknown_keys(tmp_path):
    from pushtoknow.common.errors import ConfigError

    good = tmp_path / "bag.yaml"
    good.write_text("force_topic: /ft\nflip_force: true\ntruth: {mass: 0.8}\n")
    assert BagOptions.from_yaml(good).force_topic == "/ft"
    bad = tmp_path / "bad.yaml"
    bad.write_text("force_topik: /ft\ntruth: {weight: 1}\n")
    with pytest.raises(ConfigError, match="force_topik"):
        BagOptions.from_yaml(bad)


def test_identify_cli_on_a_bag_with_named_topics(sim_records, tmp_path):
    """`identify --pushes BAG` with its own topic names and the footprint given."""
    topics = ("/pad", "/box", "/ft")
    bag = write_bag(tmp_path / "bag", sim_records[:1], [0.0], topics=topics)
    cfg = tmp_path / "bag.yaml"
    cfg.write_text("split: gaps\nname: box\n")
    args = ["identify", "--pushes", str(bag), "--shape", "rect1", "--bag-config", str(cfg)]
    args += ["--pusher-topic", "/pad", "--object-topic", "/box", "--force-topic", "/ft"]
    r = subprocess.run(
        [sys.executable, "-m", "pushtoknow.cli", *args, "--workers", "1", "--json"],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        check=False,
    )
    assert r.returncode == 0, r.stderr
    (obj,) = json.loads(r.stdout)["objects"]
    assert obj["name"] == "box" and obj["truth"] is None
    lo, hi = obj["mu_m"]["interval"]
    assert lo <= 0.25 <= hi  # μ·m of the tiny object
    r = subprocess.run(
        [sys.executable, "-m", "pushtoknow.cli", *args, "--force-topic", "/nope"],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        check=False,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert len(r.stderr.strip().splitlines()) == 1 and "--force-topic /nope" in r.stderr


def test_convert_recording_writes_the_bags_pushes_as_a_recording(sim_records, tmp_path):
    from pushtoknow.datasets.recording import read_recording

    bag = write_bag(tmp_path / "bag", sim_records, [0.0, 5.0], topics=("/pad", "/box", "/ft"))
    cfg = tmp_path / "bag.yaml"
    cfg.write_text("pusher_topic: /pad\nobject_topic: /box\nsplit: gaps\nheight: 0.02\n")
    out = tmp_path / "rec.h5"
    args = ["convert-recording", str(bag), "--out", str(out), "--bag-config", str(cfg)]
    r = subprocess.run(
        [sys.executable, "-m", "pushtoknow.cli", *args, "--force-topic", "/ft"],
        capture_output=True,
        text=True,
        env=dict(os.environ),
        check=False,
    )
    assert r.returncode == 0, r.stderr
    assert "wrote 2 pushes of bag at 10 Hz" in r.stdout
    meta, records = read_recording(out)
    want_meta, want = read_bag(
        bag, BagOptions.from_yaml(cfg).model_copy(update={"force_topic": "/ft"})
    )
    assert meta.height == 0.02 == want_meta.height and meta.name == "bag"
    for got, exp in zip(records, want, strict=True):
        assert got == exp
