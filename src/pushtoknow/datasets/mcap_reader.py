"""Pushes from ROS 2 bags and MCAP files, without ROS (the pure-Python `rosbags` package;
docs/RECORDING.md, "ROS 2 bags").

Three topics map to the recording format (`datasets.recording`): the pusher (the pad centre;
geometry_msgs/PoseStamped or PointStamped), the object (PoseStamped: x, y and the yaw of its
quaternion) and the force (geometry_msgs/WrenchStamped: force.x, force.y, by the pad on the
object; `flip_force` when the sensor gives the force on the pad). Every message of the three
must carry one frame_id (`frame`, or the same for all three): the format is in world axes.
Times are the headers' stamps (the log times where a topic's stamps are all zero); each
stream is sorted by them, duplicates keeping the last message.

The streams are cut into **segments** wherever any of them pauses longer than `gap` s, and each
segment is resampled at `rate` Hz on its common span, as MIT Push files are (`mit_push`):
positions and yaw (unwrapped) interpolated linearly, the force averaged over the messages of
each window (t_k − 1/rate, t_k] (the testbed's tactile timing; a window without a message takes
the force interpolated at its centre). split="gaps" makes each segment a push;
split="contact" (default) makes a push of each contact phase (‖F‖ > `contact_force`; phases
less than `merge_gap` s apart are one), from `lead` s before its first contact to `tail` s
after its last, within its segment and never past the midpoint to a neighbouring phase. The
pushes then go through the recording format's checks (`records_from_pushes`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any, Literal

import numpy as np
from pydantic import Field, field_validator

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.datasets.mit_push import window_means
from pushtoknow.datasets.recording import RawPush, RecordingMeta, records_from_pushes
from pushtoknow.testbed.objects import DEFAULT_HEIGHT
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import PadConfig

__all__ = ["BagOptions", "is_bag", "read_bag"]

POSE_TYPES = ("geometry_msgs/msg/PoseStamped", "geometry_msgs/msg/PointStamped")
OBJECT_TYPES = ("geometry_msgs/msg/PoseStamped",)
FORCE_TYPES = ("geometry_msgs/msg/WrenchStamped",)
BAG_SUFFIXES = (".mcap", ".db3")
# of a step: stamps are moved this much earlier so a message stamped t_k falls in the window
# (t_k − 1/rate, t_k] of sample k, as the testbed's tactile sensor averages
WINDOW_EPSILON = 1e-6


class BagOptions(Config):
    """How a bag maps to the recording format (YAML keys = these names)."""

    pusher_topic: str = Field("/pusher/pose", description="PoseStamped or PointStamped")
    object_topic: str = Field("/object/pose", description="PoseStamped")
    force_topic: str = Field("/pusher/wrench", description="WrenchStamped")
    frame: str | None = Field(None, description="every topic's frame_id (None: all the same)")
    flip_force: bool = Field(False, description="the wrench is the force on the pad: negate")
    rate: float = Field(10.0, gt=0, description="Hz of the pushes' clock")
    split: Literal["contact", "gaps"] = "contact"
    contact_force: float = Field(0.5, gt=0, description="N: contact is ‖F‖ above this")
    merge_gap: float = Field(0.5, ge=0, description="s: closer contact phases are one push")
    lead: float = Field(0.5, ge=0, description="s kept before a push's first contact")
    tail: float = Field(1.0, ge=0, description="s kept after a push's last contact")
    gap: float = Field(0.5, gt=0, description="s: a longer pause of any topic ends a segment")
    name: str | None = Field(None, description="object name (default: the bag's name)")
    height: float = Field(DEFAULT_HEIGHT, gt=0, description="m")
    outline: list[tuple[float, float]] | None = Field(None, description="(V, 2) m, object frame")
    truth: dict[str, float] = Field(default_factory=dict, description="known parameters, SI")
    surface: str = ""
    pusher_radius: float = Field(PadConfig().radius, gt=0, description="m")
    pusher_friction: float = Field(
        PadConfig().friction, ge=0, description="Coulomb coefficient, pusher on object"
    )
    force_noise_std: float | None = Field(None, gt=0, description="N (None: unknown)")

    @field_validator("truth")
    @classmethod
    def _known_parameters(cls, v: dict[str, float]) -> dict[str, float]:
        unknown = sorted(set(v) - set(PARAM_NAMES))
        if unknown:
            raise ValueError(f"unknown parameter(s) {unknown}; known: {list(PARAM_NAMES)}")
        return v

    def meta(self, default_name: str) -> RecordingMeta:
        """The recording meta these options describe."""
        return RecordingMeta(
            name=self.name or default_name,
            height=self.height,
            outline=None if self.outline is None else np.asarray(self.outline, dtype=np.float64),
            truth=np.array([self.truth.get(n, np.nan) for n in PARAM_NAMES], dtype=np.float64),
            surface=self.surface,
            pusher_radius=self.pusher_radius,
            pusher_friction=self.pusher_friction,
            force_noise_std=self.force_noise_std,
        )


def is_bag(path: str | Path) -> bool:
    """A rosbag2 folder (with metadata.yaml) or a bare .mcap / .db3 file."""
    path = Path(path)
    if path.is_dir():
        return (path / "metadata.yaml").is_file()
    return path.is_file() and path.suffix.lower() in BAG_SUFFIXES


def _yaw(q) -> float:
    """Yaw (rad) of a quaternion message (x, y, z, w)."""
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def _values(role: str, msg) -> tuple[float, ...]:
    if role == "force":
        f = msg.wrench.force
        return (f.x, f.y)
    if hasattr(msg, "point"):
        return (msg.point.x, msg.point.y)
    p = msg.pose
    return (p.position.x, p.position.y, _yaw(p.orientation))


def _read_streams(path: Path, opts: BagOptions) -> dict[str, np.ndarray]:
    """{role: (N, 1 + c) rows [t, values...]} of the three topics, frames checked."""
    from rosbags.highlevel import AnyReader, AnyReaderError
    from rosbags.rosbag2 import ReaderError
    from rosbags.typesys import Stores, get_typestore

    topics = {
        "pusher": (opts.pusher_topic, POSE_TYPES, "--pusher-topic"),
        "object": (opts.object_topic, OBJECT_TYPES, "--object-topic"),
        "force": (opts.force_topic, FORCE_TYPES, "--force-topic"),
    }
    rows: dict[str, list] = {k: [] for k in topics}
    stamps: dict[str, list] = {k: [] for k in topics}  # (header stamp, log time) in ns
    frames: dict[str, set[str]] = {k: set() for k in topics}
    try:
        with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_HUMBLE)) as reader:
            found = {c.topic: c for c in reader.connections}
            role_of = {}
            for role, (topic, types, option) in topics.items():
                if topic not in found:
                    have = ", ".join(sorted(found)) or "none"
                    raise DatasetError(path, f"{option} {topic}: no such topic (topics: {have})")
                if found[topic].msgtype not in types:
                    raise DatasetError(
                        path,
                        f"{option} {topic}: type {found[topic].msgtype}, expected "
                        f"{' or '.join(types)}",
                    )
                role_of[topic] = role
            conns = [c for c in reader.connections if c.topic in role_of]
            for conn, logtime, raw in reader.messages(connections=conns):
                msg: Any = reader.deserialize(raw, conn.msgtype)
                role = role_of[conn.topic]
                stamp = msg.header.stamp.sec * 10**9 + msg.header.stamp.nanosec
                stamps[role].append((stamp, logtime))
                rows[role].append(_values(role, msg))
                frames[role].add(msg.header.frame_id)
    except (AnyReaderError, ReaderError, OSError, KeyError, ValueError) as e:
        raise DatasetError(path, f"not a readable ROS 2 bag / MCAP file ({e})") from None
    want = opts.frame
    for role, (topic, _, _) in topics.items():
        if not rows[role]:
            raise DatasetError(path, f"{topic}: no messages")
        fs = sorted(frames[role])
        if len(fs) > 1:
            raise DatasetError(path, f"{topic}: messages in several frames {fs}; need one")
        if want is None:
            want = fs[0]
        elif fs[0] != want:
            raise DatasetError(
                path,
                f"{topic}: frame_id {fs[0]!r}, other topics in {want!r}: the format needs every "
                "topic in the same world frame (transform it first, or set frame)",
            )
    ns = {}
    for role, st in stamps.items():
        a = np.asarray(st, dtype=np.int64)
        ns[role] = a[:, 0] if (a[:, 0] != 0).any() else a[:, 1]
    origin = min(int(t.min()) for t in ns.values())  # relative times keep ns resolution
    out = {}
    for role, t_ns in ns.items():
        order = np.argsort(t_ns, kind="stable")
        t = (t_ns[order] - origin) * 1e-9
        values = np.asarray(rows[role], dtype=np.float64)[order]
        keep = np.append(np.diff(t) > 0, True)  # of equal stamps, the last message
        out[role] = np.column_stack([t[keep], values[keep]])
    if opts.flip_force:
        out["force"][:, 1:] *= -1.0
    return out


def _segments(streams: dict[str, np.ndarray], gap: float) -> list[tuple[float, float]]:
    """(start, end) s of the stretches where every stream has messages without a pause > gap."""
    start = max(a[0, 0] for a in streams.values())
    end = min(a[-1, 0] for a in streams.values())
    pauses = []
    for a in streams.values():
        d = np.diff(a[:, 0])
        pauses += [(a[i, 0], a[i + 1, 0]) for i in np.flatnonzero(d > gap)]
    segments, t = [], start
    for p0, p1 in sorted(pauses):
        if p0 > t:
            segments.append((t, min(p0, end)))
        t = max(t, p1)
    if t < end:
        segments.append((t, end))
    return [(a, b) for a, b in segments if b > a]


def _resampled(streams: dict[str, np.ndarray], t0: float, t1: float, rate: float) -> dict:
    """The streams on the clock t0 + k / rate within [t0, t1]."""
    k = int(math.floor((t1 - t0) * rate + 1e-6)) + 1
    t = np.arange(k) / rate
    pusher = streams["pusher"]
    obj = streams["object"].copy()
    obj[:, 3] = np.unwrap(obj[:, 3])
    force = streams["force"]
    tf = force[:, 0] - t0 - WINDOW_EPSILON / rate
    return {
        "time": t,
        "pusher": np.column_stack([np.interp(t, pusher[:, 0] - t0, c) for c in pusher[:, 1:3].T]),
        "object_pose": np.column_stack([np.interp(t, obj[:, 0] - t0, c) for c in obj[:, 1:4].T]),
        "force": window_means(tf, force[:, 1:3], rate, k)[0],
    }


def _windows(contact: np.ndarray, opts: BagOptions) -> list[tuple[int, int]]:
    """(first, last) sample index of each push of a segment split by contact phases."""
    idx = np.flatnonzero(contact)
    if idx.size == 0:
        return []
    merge = max(1, int(round(opts.merge_gap * opts.rate)))
    breaks = np.flatnonzero(np.diff(idx) > merge)
    phases = list(zip(idx[np.r_[0, breaks + 1]], idx[np.r_[breaks, len(idx) - 1]]))
    lead, tail = int(round(opts.lead * opts.rate)), int(round(opts.tail * opts.rate))
    out = []
    for i, (a, b) in enumerate(phases):
        lo = a - lead if i == 0 else max(a - lead, (phases[i - 1][1] + a) // 2 + 1)
        hi = b + tail if i == len(phases) - 1 else min(b + tail, (b + phases[i + 1][0]) // 2)
        out.append((max(lo, 0), min(hi, len(contact) - 1)))
    return out


def read_bag(
    path: str | Path, options: BagOptions | None = None
) -> tuple[RecordingMeta, list[PushRecord]]:
    """Read the pushes of a ROS 2 bag folder or an .mcap / .db3 file (module doc): (meta,
    records), as `read_recording`. Raises DatasetError naming the bag, topic or push."""
    path = Path(path)
    opts = options or BagOptions()
    if not path.exists():
        raise DatasetError(path, "no such bag or MCAP file")
    streams = _read_streams(path, opts)
    raws: list[RawPush] = []
    for t0, t1 in _segments(streams, opts.gap):
        seg = _resampled(streams, t0, t1, opts.rate)
        if len(seg["time"]) < 2:
            continue
        contact = np.linalg.norm(seg["force"], axis=1) > opts.contact_force
        spans = [(0, len(contact) - 1)] if opts.split == "gaps" else _windows(contact, opts)
        for a, b in spans:
            if b - a < 1:
                continue
            raws.append(
                RawPush(
                    group=f"push-{len(raws):03d}",
                    time=np.arange(b - a + 1) / opts.rate,
                    pusher=seg["pusher"][a : b + 1],
                    object_pose=seg["object_pose"][a : b + 1],
                    force=seg["force"][a : b + 1],
                    contact=contact[a : b + 1].astype(np.float64),
                )
            )
    if not raws:
        raise DatasetError(
            path,
            f"no pushes found (split={opts.split}: no contact above {opts.contact_force} N)"
            if opts.split == "contact"
            else f"no pushes found (split={opts.split}: no stretch of common messages)",
        )
    name = path.stem if path.is_file() else path.name
    return records_from_pushes(path, raws, opts.meta(name), opts.rate)
