"""The recording format: pushes recorded on any robot, one object per file (docs/RECORDING.md).

Format "pushtoknow-recording", version 1, an HDF5 file:

    /            attrs: format, version, object (name), height (m), optional outline (V, 2) m
                        (object frame), truth_mass (kg), truth_friction, truth_com_x (m),
                        truth_com_y (m), truth_inertia (kg·m²), surface, pusher_radius (m),
                        pusher_friction (Coulomb coefficient, pusher on object), force_noise_std (N)
    /push-000    time (T,) s · pusher (T, 2) m · object_pose (T, 3) m, m, rad · force (T, 2) N
                 optional: contact (T,) 0..1 · rgb (T, H, W, 3) uint8 · depth (T, H, W) m
                 optional attrs (the commanded push): push_contact (2,) m, push_direction rad,
                 push_speed m/s, push_profile ("constant" | "release")

World frame, SI, the force *by the pad on the object* (docs/DESIGN.md §2), as `PushRecord`.
`read_recording` checks a file before returning its pushes (`records_from_pushes`: shapes,
finite values, clock, frozen channels, the force's sign, units) and raises a one-line
`DatasetError` naming the file, push group, dataset and value; `datasets.mcap_reader` feeds
ROS 2 bags through the same checks.
"""

from __future__ import annotations

import math
import os
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from pathlib import Path

import h5py
import numpy as np

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.common.version import __version__
from pushtoknow.datasets.mit_push import (
    AGAINST_SHARE,
    CONTACT_FORCE_THRESHOLD,
    strong_force_along,
    window_means,
)
from pushtoknow.datasets.pad_track import push_from_track
from pushtoknow.testbed.objects import DEFAULT_HEIGHT, FRICTION_LIMIT, ObjectSpec
from pushtoknow.testbed.push import PROFILES, Push
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import PadConfig, SimConfig

__all__ = [
    "FORMAT",
    "VERSION",
    "RawPush",
    "RecordingMeta",
    "is_recording",
    "read_recording",
    "recording_meta",
    "records_from_pushes",
    "write_recording",
]

FORMAT = "pushtoknow-recording"
VERSION = 1
GROUP_PREFIX = "push-"
COLUMNS = {"pusher": 2, "object_pose": 3, "force": 2}  # (T, c) datasets besides time (T,)
CLOCK_TOLERANCE = 1e-6  # of a step: a clock this close to k·dt is kept as it is
MAX_GAP_STEPS = 5.0  # a step longer than this many median steps is a gap (error)
MAX_POSITION = 10.0  # m: a larger |x| or |y| is taken for millimetres
MAX_HEIGHT_M = 1.0  # m: a larger height is taken for millimetres
CENTROID_TOLERANCE = 1e-6  # m: an outline whose centroid is farther from the origin is moved
WINDOW_EPSILON = 1e-6  # of a step: a sample stamped t_k belongs to the window ending at t_k


@dataclass(frozen=True, eq=False)
class RecordingMeta:
    """What a recording says about its object and sensors (root attributes).

    name; height (m); outline (V, 2) m in the object frame or None; truth (5,) SI in
    `PARAM_NAMES` order, NaN where unknown; surface; pusher_radius (m, the pad's);
    pusher_friction (the Coulomb coefficient between the pusher and the object; 0: a
    frictionless pusher, the testbed's pad); force_noise_std (N, None: unknown, `identify` then
    takes it from the misfit). The readers add rate (Hz, the pushes' common clock) and notes
    (what they changed, e.g. a resampling).
    """

    name: str
    height: float = DEFAULT_HEIGHT
    outline: np.ndarray | None = None
    truth: np.ndarray = field(default_factory=lambda: np.full(len(PARAM_NAMES), np.nan))
    surface: str = ""
    pusher_radius: float = PadConfig().radius
    pusher_friction: float = PadConfig().friction
    force_noise_std: float | None = None
    rate: float | None = None
    notes: tuple[str, ...] = ()


@dataclass(eq=False)
class RawPush:
    """One push as a file or bag holds it, before `records_from_pushes` checks it.

    group: its name ("push-000"); time (T,) s; pusher (T, 2) m; object_pose (T, 3) m, m, rad;
    force (T, 2) N (world, by the pad on the object); contact (T,) 0..1 or None (then
    ‖F‖ > 0.5 N); rgb (T, H, W, 3) uint8 and depth (T, H, W) m or None; commanded: the push
    as commanded, or None (then derived from the pad track, `pad_track.push_from_track`).
    """

    group: str
    time: np.ndarray
    pusher: np.ndarray
    object_pose: np.ndarray
    force: np.ndarray
    contact: np.ndarray | None = None
    rgb: np.ndarray | None = None
    depth: np.ndarray | None = None
    commanded: Push | None = None


def recording_meta(spec: ObjectSpec, sim_config: SimConfig) -> RecordingMeta:
    """The meta of a simulated object's recording: its name, height, footprint (as an
    outline), parameters (as the truth), pad radius and tactile noise (None when 0)."""
    noise = float(sim_config.tactile.force_noise_std)
    return RecordingMeta(
        name=spec.name or "object",
        height=float(spec.height),
        outline=np.asarray(spec.footprint.vertices, dtype=np.float64),
        truth=spec.params.as_array(),
        pusher_radius=float(sim_config.pad.radius),
        pusher_friction=float(sim_config.pad.friction),
        force_noise_std=noise if noise > 0 else None,
    )


# ============================================================================================
# Writing
# ============================================================================================
def write_recording(path: str | Path, pushes: Sequence[PushRecord], meta: RecordingMeta) -> Path:
    """Write `pushes` of one object as a recording file (atomic: a temp file, then renamed).

    Each record gives time, pusher, object_pose (its pose), force and contact (its tactile
    columns), rgb and depth (when present) and its push as the commanded one. Returns the path.
    """
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    try:
        with h5py.File(tmp, "w") as f:
            f.attrs.update(
                format=FORMAT,
                version=VERSION,
                object=meta.name,
                height=float(meta.height),
                surface=meta.surface,
                pusher_radius=float(meta.pusher_radius),
                pusher_friction=float(meta.pusher_friction),
                pushtoknow_version=__version__,
            )
            if meta.force_noise_std is not None:
                f.attrs["force_noise_std"] = float(meta.force_noise_std)
            if meta.outline is not None:
                f.attrs["outline"] = np.asarray(meta.outline, dtype=np.float64)
            for name, value in zip(PARAM_NAMES, np.asarray(meta.truth, dtype=np.float64)):
                if np.isfinite(value):
                    f.attrs[f"truth_{name}"] = float(value)
            for i, r in enumerate(pushes):
                g = f.create_group(f"{GROUP_PREFIX}{i:03d}")
                g.create_dataset("time", data=np.asarray(r.time, dtype=np.float64))
                g.create_dataset("pusher", data=np.asarray(r.pusher, dtype=np.float64))
                g.create_dataset("object_pose", data=np.asarray(r.pose, dtype=np.float64))
                g.create_dataset("force", data=np.asarray(r.tactile[:, :2], dtype=np.float64))
                g.create_dataset("contact", data=np.asarray(r.tactile[:, 2], dtype=np.float64))
                if r.rgb is not None:
                    g.create_dataset("rgb", data=r.rgb, compression="gzip")
                if r.depth is not None:
                    g.create_dataset("depth", data=r.depth.astype(np.float32), compression="gzip")
                g.attrs.update(
                    push_contact=np.asarray(r.push.contact, dtype=np.float64),
                    push_direction=float(r.push.direction),
                    push_speed=float(r.push.speed),
                    push_profile=r.push.profile,
                )
        with open(tmp, "rb+") as fh:
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    finally:
        tmp.unlink(missing_ok=True)
    return path


# ============================================================================================
# Reading
# ============================================================================================
def is_recording(path: str | Path) -> bool:
    """Whether `path` is an HDF5 file whose root attribute format is "pushtoknow-recording"."""
    path = Path(path)
    if not path.is_file() or not h5py.is_hdf5(path):
        return False
    with h5py.File(path, "r") as f:
        return _attr_str(f.attrs, "format", "") == FORMAT


def _attr_float(path: Path, attrs, name: str) -> float | None:
    """A number attribute (None when absent); DatasetError naming it when not a number."""
    if name not in attrs:
        return None
    try:
        return float(np.asarray(attrs[name]).reshape(()))
    except (TypeError, ValueError):
        raise DatasetError(path, f"attribute {name}={attrs[name]!r}: not a number") from None


def _attr_str(attrs, name: str, default: str) -> str:
    """A text attribute, variable- or fixed-length (bytes decoded as UTF-8)."""
    v = attrs.get(name, default)
    return v.decode("utf-8", "replace") if isinstance(v, bytes) else str(v)


def _read_meta(path: Path, attrs) -> RecordingMeta:
    fmt = _attr_str(attrs, "format", "")
    if fmt != FORMAT:
        raise DatasetError(path, f"format attribute {fmt!r}: not a {FORMAT} file")
    version = attrs.get("version")
    shown = None if version is None else np.asarray(version).tolist()
    if shown != VERSION:
        raise DatasetError(path, f"version {shown!r}: this pushtoknow reads version {VERSION}")
    height = _attr_float(path, attrs, "height")
    radius = _attr_float(path, attrs, "pusher_radius")
    pusher_friction = _attr_float(path, attrs, "pusher_friction")
    outline = None
    if "outline" in attrs:
        outline = np.asarray(attrs["outline"], dtype=np.float64)
    truth = [_attr_float(path, attrs, f"truth_{n}") for n in PARAM_NAMES]
    return RecordingMeta(
        name=_attr_str(attrs, "object", path.stem),
        height=DEFAULT_HEIGHT if height is None else height,
        outline=outline,
        truth=np.array([np.nan if v is None else v for v in truth], dtype=np.float64),
        surface=_attr_str(attrs, "surface", ""),
        pusher_radius=PadConfig().radius if radius is None else radius,
        pusher_friction=PadConfig().friction if pusher_friction is None else pusher_friction,
        force_noise_std=_attr_float(path, attrs, "force_noise_std"),
    )


def _commanded(path: Path, group: str, attrs) -> Push | None:
    keys = ("push_contact", "push_direction", "push_speed", "push_profile")
    if not any(k in attrs for k in keys):
        return None
    missing = [k for k in keys if k not in attrs]
    if missing:
        raise DatasetError(path, f"{group}: commanded push without attribute(s) {missing}")
    profile = _attr_str(attrs, "push_profile", "")
    if profile not in PROFILES:
        raise DatasetError(path, f"{group}/push_profile={profile!r}: not one of {list(PROFILES)}")
    try:
        cp = np.asarray(attrs["push_contact"], dtype=np.float64).reshape(2)
        pd, v = float(attrs["push_direction"]), float(attrs["push_speed"])
    except (TypeError, ValueError):
        raise DatasetError(path, f"{group}: commanded push attributes are not numbers") from None
    if not (np.isfinite(cp).all() and math.isfinite(pd) and math.isfinite(v)):
        raise DatasetError(path, f"{group}: commanded push has non-finite values")
    return Push((float(cp[0]), float(cp[1])), pd, profile, v)


def _load_push(path: Path, g: h5py.Group, images: bool) -> RawPush:
    group = g.name.lstrip("/")
    data = {}
    for name in ("time", *COLUMNS):
        if name not in g or not isinstance(g[name], h5py.Dataset):
            raise DatasetError(path, f"{group}/{name}: missing (required dataset)")
        data[name] = g[name][()]
    optional = ("contact", "rgb", "depth") if images else ("contact",)
    for name in optional:
        data[name] = g[name][()] if name in g else None
    return RawPush(group, commanded=_commanded(path, group, g.attrs), **data)


def read_recording(
    path: str | Path, rate: float | None = None, images: bool = True
) -> tuple[RecordingMeta, list[PushRecord]]:
    """Read and check a recording file: (meta, one PushRecord per push group, in name order).

    rate (Hz): resample every push to this clock (None: the recording's own). images=False
    skips rgb and depth. Raises DatasetError (one line: file, push group, dataset, value) for
    any problem `records_from_pushes` checks; what it changed is in meta.notes.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(path, "no such recording file")
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise DatasetError(path, f"not a readable HDF5 file ({e})") from None
    with f:
        meta = _read_meta(path, f.attrs)
        groups = sorted(k for k in f if k.startswith(GROUP_PREFIX))
        if not groups:
            raise DatasetError(path, f"no push groups ({GROUP_PREFIX}000, ...)")
        raws = [_load_push(path, f[k], images) for k in groups]
    return records_from_pushes(path, raws, meta, rate)


# ============================================================================================
# Checks and conversion
# ============================================================================================
def _as_array(where: Path, group: str, name: str, value, shape: tuple) -> np.ndarray:
    """value as float64 (uint8 for rgb) of `shape` (None: any length), else DatasetError."""
    try:
        a = np.asarray(value, dtype=np.uint8 if name == "rgb" else np.float64)
    except (TypeError, ValueError):
        raise DatasetError(where, f"{group}/{name}: not numeric") from None
    ok = a.ndim == len(shape) and all(s is None or s == n for s, n in zip(shape, a.shape))
    if not ok:
        want = "(" + ", ".join("T" if s is None else str(s) for s in shape) + ")"
        raise DatasetError(where, f"{group}/{name}: shape {a.shape}, expected {want}")
    return a


def _check_values(where: Path, raw: RawPush) -> dict[str, np.ndarray]:
    """The push's arrays, checked: shapes, finite, positions in metres, time, frozen channels."""
    g = raw.group
    t = _as_array(where, g, "time", raw.time, (None,))
    T = len(t)
    if T < 2:
        raise DatasetError(where, f"{g}/time: {T} sample(s), at least 2 are needed")
    arrays = {"time": t}
    for name, cols in COLUMNS.items():
        arrays[name] = _as_array(where, g, name, getattr(raw, name), (T, cols))
    if raw.contact is not None:
        arrays["contact"] = _as_array(where, g, "contact", raw.contact, (T,))
    for name, a in arrays.items():
        bad = ~np.isfinite(a)
        if bad.any():
            i = int(np.flatnonzero(bad.reshape(T, -1).any(axis=1))[0])
            raise DatasetError(where, f"{g}/{name}: non-finite value at sample {i} ({a[i]})")
    for name in ("pusher", "object_pose"):
        big = np.abs(arrays[name][:, :2]).max()
        if big > MAX_POSITION:
            raise DatasetError(
                where,
                f"{g}/{name}: position {big:.4g} m (> {MAX_POSITION:g} m): millimetres? "
                "positions must be in metres",
            )
    steps = np.diff(t)
    if (steps <= 0).any():
        i = int(np.flatnonzero(steps <= 0)[0]) + 1
        raise DatasetError(
            where, f"{g}/time: not strictly increasing at sample {i} ({t[i - 1]!r} → {t[i]!r} s)"
        )
    step = float(np.median(steps))
    if steps.max() > MAX_GAP_STEPS * step:
        i = int(np.argmax(steps)) + 1
        raise DatasetError(
            where,
            f"{g}/time: a gap of {steps.max():.4g} s before sample {i} (median step "
            f"{step:.4g} s): split the push there",
        )
    for name, what in (("force", "N"), ("object_pose", "m, m, rad"), ("pusher", "m")):
        a = arrays[name]
        if (a == a[0]).all():
            raise DatasetError(
                where, f"{g}/{name}: frozen, {a[0].tolist()} ({what}) at all {T} samples"
            )
    if raw.rgb is not None:
        if np.asarray(raw.rgb).dtype != np.uint8:
            raise DatasetError(where, f"{g}/rgb: dtype {np.asarray(raw.rgb).dtype}, expected uint8")
        arrays["rgb"] = _as_array(where, g, "rgb", raw.rgb, (T, None, None, 3))
    if raw.depth is not None:
        arrays["depth"] = _as_array(where, g, "depth", raw.depth, (T, None, None)).astype(
            np.float32
        )
    return arrays


def _resample(a: dict[str, np.ndarray], rate: float) -> dict[str, np.ndarray]:
    """The push on the uniform clock k / rate from its first sample: positions, pose and
    contact linearly interpolated; the force too, or averaged over the samples of each window
    (t_k − 1/rate, t_k] when the clock is more than 1.5 times coarser (as the testbed's
    tactile sensor); images of the latest frame at or before t_k."""
    t = a["time"] - a["time"][0]
    k = int(math.floor(t[-1] * rate + 1e-6)) + 1
    new = np.arange(k) / rate
    out = {"time": new}
    for name in ("pusher", "object_pose"):
        out[name] = np.column_stack([np.interp(new, t, c) for c in a[name].T])
    if _coarser(a["time"], rate):
        out["force"] = window_means(t - WINDOW_EPSILON / rate, a["force"], rate, k)[0]
    else:
        out["force"] = np.column_stack([np.interp(new, t, c) for c in a["force"].T])
    if "contact" in a:
        out["contact"] = (np.interp(new, t, a["contact"]) >= 0.5).astype(np.float64)
    frame = np.clip(np.searchsorted(t, new + 1e-9 / rate, side="right") - 1, 0, len(t) - 1)
    for name in ("rgb", "depth"):
        if name in a:
            out[name] = a[name][frame]
    return out


def _coarser(t: np.ndarray, rate: float) -> bool:
    """Whether the clock k / rate is more than 1.5 times coarser than the times t (T,) s."""
    return 1.0 / rate > 1.5 * float(np.median(np.diff(t)))


def _centred(meta: RecordingMeta, where: Path) -> tuple[RecordingMeta, np.ndarray]:
    """The meta with its outline about its centroid (the object frame's origin,
    docs/DESIGN.md §2), and the centroid's offset (2,) m in the recorded frame."""
    from shapely.geometry import Polygon

    if meta.outline is None:
        return meta, np.zeros(2)
    v = meta.outline
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3 or not np.isfinite(v).all():
        raise DatasetError(where, f"outline: shape {v.shape}, expected (V ≥ 3, 2) finite (m)")
    if np.abs(v).max() > MAX_POSITION:
        raise DatasetError(where, f"outline: vertex at {np.abs(v).max():.4g} m: millimetres?")
    poly = Polygon(v)
    if not poly.is_valid or poly.area <= 0:
        raise DatasetError(where, "outline: not a simple polygon")
    c = np.array([poly.centroid.x, poly.centroid.y])
    if np.hypot(*c) <= CENTROID_TOLERANCE:
        return meta, np.zeros(2)
    truth = meta.truth.copy()
    truth[2:4] -= c
    note = (
        f"object frame moved to the outline's centroid, ({c[0] * 1e3:+.2f}, {c[1] * 1e3:+.2f}) "
        "mm in the recorded frame: poses, outline and the true CoM refer to it"
    )
    return replace(meta, outline=v - c, truth=truth, notes=(*meta.notes, note)), c


def _check_sign(where: Path, group: str, force: np.ndarray, push: Push) -> None:
    """DatasetError when most strong-force samples push against the push direction."""
    mag = np.linalg.norm(force, axis=1)
    if float(mag.max()) < CONTACT_FORCE_THRESHOLD:
        return
    along = strong_force_along(force, push.unit, mag >= CONTACT_FORCE_THRESHOLD)
    against = int((along < 0).sum())
    if against > AGAINST_SHARE * len(along):
        raise DatasetError(
            where,
            f"{group}/force: points against the push on {against} of {len(along)} samples "
            f"(mean {along.mean():+.3g} N along the push direction "
            f"{math.degrees(push.direction):.0f}°): sign flipped? the format wants the force "
            "by the pad on the object",
        )


def _common_rate(steps: list[float]) -> float:
    """The recording's rate (Hz) from the pushes' median steps (s), rounded to 1 µHz."""
    rate = 1.0 / float(np.median(steps))
    return float(round(rate, 6))


def _is_uniform(t: np.ndarray, rate: float) -> bool:
    rel = t - t[0]
    return bool(np.abs(rel - np.arange(len(t)) / rate).max() <= CLOCK_TOLERANCE / rate)


def records_from_pushes(
    where: str | Path, raws: Sequence[RawPush], meta: RecordingMeta, rate: float | None = None
) -> tuple[RecordingMeta, list[PushRecord]]:
    """Check pushes and turn them into `PushRecord`s (the one path of every reader).

    where: the file or bag named in errors. Checks, each a one-line DatasetError naming
    `where`, the push group, the dataset and the value: shapes (time (T ≥ 2,), pusher (T, 2),
    object_pose (T, 3), force (T, 2), contact (T,), rgb (T, H, W, 3), depth (T, H, W)), finite
    values, positions ≤ 10 m (larger: millimetres), strictly increasing time without gaps
    (a step > 5 median steps), no frozen force, pose or pusher (the same value at every
    sample), the force not pointing against the push on most strong-force samples (a flipped
    sign). A clock off k / rate (jitter, or another rate than the recording's) is resampled
    (`_resample`) and said in the returned meta's notes, as is a move of the object frame to
    the outline's centroid. Records: time from 0 s, θ unwrapped, tactile = (force, contact),
    no force_clean (a recording has no noiseless force), no S_0.
    """
    where = Path(where)
    if not raws:
        raise DatasetError(where, "no pushes")
    if not (math.isfinite(meta.height) and 0 < meta.height <= MAX_HEIGHT_M):
        raise DatasetError(where, f"height={meta.height!r}: expected metres in (0, 1]")
    if not (math.isfinite(meta.pusher_radius) and 0 < meta.pusher_radius <= MAX_HEIGHT_M):
        raise DatasetError(
            where, f"pusher_radius={meta.pusher_radius!r}: expected metres in (0, 1]"
        )
    if not (math.isfinite(meta.pusher_friction) and 0 <= meta.pusher_friction <= FRICTION_LIMIT):
        raise DatasetError(
            where,
            f"pusher_friction={meta.pusher_friction!r}: expected a Coulomb coefficient in "
            f"[0, {FRICTION_LIMIT:g}]",
        )
    noise = meta.force_noise_std
    if noise is not None and not (math.isfinite(noise) and noise >= 0):
        raise DatasetError(where, f"force_noise_std={noise!r}: expected N ≥ 0")
    meta, centroid = _centred(meta, where)
    checked = [_check_values(where, r) for r in raws]
    own = _common_rate([float(np.median(np.diff(a["time"]))) for a in checked])
    target = own if rate is None else float(rate)
    notes = list(meta.notes)
    records = []
    for raw, a in zip(raws, checked):
        if not _is_uniform(a["time"], target):
            own_rate = 1.0 / float(np.median(np.diff(a["time"])))
            why = (
                f"a {own_rate:.4g} Hz clock"
                if _is_uniform(a["time"], own_rate)
                else ("a jittery clock")
            )
            how = "force window-averaged" if _coarser(a["time"], target) else "force interpolated"
            a = _resample(a, target)
            notes.append(
                f"{raw.group}: {why} resampled to {target:g} Hz ({len(a['time'])} samples; "
                f"positions interpolated linearly, {how})"
            )
        pose = a["object_pose"].copy()
        pose[:, 2] = np.unwrap(pose[:, 2])
        if centroid.any():
            c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
            pose[:, 0] += c * centroid[0] - s * centroid[1]
            pose[:, 1] += s * centroid[0] + c * centroid[1]
        force = a["force"]
        if "contact" in a:
            contact = a["contact"]
        else:
            contact = (np.linalg.norm(force, axis=1) > CONTACT_FORCE_THRESHOLD).astype(np.float64)
        time = a["time"] - a["time"][0]
        push = raw.commanded or push_from_track(
            a["pusher"],
            pose,
            contact >= 0.5,
            time,
            polygon=meta.outline,
            pad_radius=meta.pusher_radius,
        )
        _check_sign(where, raw.group, force, push)
        records.append(
            PushRecord(
                push=push,
                time=time,
                pose=pose,
                tactile=np.column_stack([force, contact]),
                force_clean=None,
                pusher=a["pusher"],
                rgb=a.get("rgb"),
                depth=a.get("depth"),
                s0=None,
            )
        )
    return replace(meta, rate=target, notes=tuple(notes)), records
