"""Reader for the MIT Push dataset (Yu, Bauza, Fazeli, Rodriguez, IROS 2016), docs/DESIGN.md §11.

Files are named ``motion_surface=<s>_shape=<o>_a=<acc>_v=<mm/s>_i=<side>_s=<pos>_t=<angle>``
with suffix ``.json`` or ``.h5``. Each holds three tables of rows [t, ., ., .] (t in Unix s):
``tip_pose`` [t, x, y, yaw], ``object_pose`` [t, x, y, yaw] and ``ft_wrench`` [t, f_x, f_y, τ_z],
each at ~250 Hz and not synchronised. JSON stores them as lists of rows, HDF5 as N×4 datasets at
the file's root.

What the reader does (`read_mit_push`), in order:

1. **Validate** each table: present, numeric, shape (N, 4), N >= 2, all finite. Any failure, and
   corrupt JSON/HDF5, raises `DatasetError` naming the file and the problem.
2. **Make time strictly increasing.** Rows stay in file order; rows whose timestamps break the
   order are dropped, keeping the longest strictly increasing run of timestamps. In the real
   files only ``object_pose`` has such rows (5-11 a file): a message arriving late is stamped a
   few ms late, while the poses in file order keep moving steadily, so file order is the true
   order and sorting by timestamp would zig-zag the trajectory. Of rows with the *same*
   timestamp only the last in file order is kept (the most recent message for that time).
3. **Force offset (tare).** The F/T readings carry a constant offset that differs from file to
   file: (-1.53, -0.53) N in two sample files, ~0 in the third. It cannot be a contact force:
   it is the same before and after the push with the object at rest, and on the centre push it
   lies almost along the face the probe rests on, far outside the friction cone.
   The offset is the median reading while the pusher is at rest before it starts and after it
   stops (pusher within `TARE_REST_TOLERANCE` of its first/last position, `TARE_GUARD` away from
   the motion); it is subtracted and reported in `MitPush.force_offset`.
4. **Force frame and sign.** ``ft_wrench`` f_x, f_y are in world axes: on the centre push of
   rect1 (``i=1.000_s=0.500_t=0.000``; object yaw 92°, pusher moving along world +y) the
   tared mean reading over the push points 180.4° away from the pusher's motion. In object axes
   it would be 92° off. They are the force the *object exerts on the probe*. `MitPush.force` is
   their negative, the force the pusher applies to the object, as the simulator's tactile
   sensor reports it (docs/DESIGN.md §3). The probe's own frame cannot be told apart from the
   world's here, because its yaw stays ~0.
5. **Resample to a common clock** at ``rate`` Hz (default 10), with the simulator's tactile
   timing (`pushtoknow.testbed.sim`): the common span is the intersection [t_start, t_end] of
   the three streams. There are K = floor((t_end - t_start)·rate + `SAMPLE_COUNT_TOLERANCE`)
   samples at t_k = t_start + k/rate, k = 0..K-1 (so t_{K-1} + 1/rate <= t_end, up to the
   tolerance). Positions are linearly interpolated at t_k. Object yaw is unwrapped
   (``np.unwrap``) before interpolation and stays unwrapped. The force of sample k is the mean
   of the raw samples in the window that *ends* at t_k, [t_k - 1/rate, t_k) (a raw sample
   stamped exactly t_k belongs to sample k+1): the force felt while the object moved into the
   pose of t_k, as the simulator's tactile sensor averages over (t_k - 1/rate, t_k]. Window 0,
   [t_start - 1/rate, t_start), lies before the common span; it uses the raw force samples
   there when the force stream starts early enough to have any. A window with no raw sample
   (for window 0: the force stream starts at t_start, as in all three sample files) takes
   ``np.interp`` of the raw force at its centre t_k - 1/rate/2, linear between the raw samples
   on either side; ``np.interp`` clamps to the first raw value before the stream starts, so in
   that case sample 0 is the first raw reading (tared, sign flipped). The simulator's sample 0
   is zero instead (its pad has not moved yet); a recording may already be pushing at t_start.
   `MitPush.force_samples` counts the raw samples of each window (0: interpolated). Raw force
   samples after t_{K-1} are not used. Times are re-zeroed: ``times = k / rate``; ``t0`` keeps
   the Unix time of t_start.
6. **Object frame.** `MitPush.object_pose` is the pose of the footprint centroid (docs/DESIGN.md
   §2). For the triangles the dataset's frame is not at the centroid (see `mit_object`); the raw
   poses stay in `MitPush.raw`.
7. **Contact** is ‖force‖ > `CONTACT_FORCE_THRESHOLD` (0.5 N) on the window-averaged force, so
   contact[k] refers to the window ending at t_k. Noise at rest averages to < 0.1 N, while
   pushing rect1 on plywood gives > 1.5 N.

MIT's own preprocessing (pdproc) corrects yaw jumps of multiples of π/2 in the full dataset.
These are motion-capture flips on symmetric shapes. This reader does *not* correct them. A step
larger than `YAW_JUMP_WARNING` between consecutive raw samples raises a `MitPushWarning`.

Reading does not judge whether a push can be fitted: `check_mit_push` refuses a frozen stream,
clocks that barely overlap, a flipped force sign and (optionally) a push without contact, with a
one-line `DatasetError` naming the file (`pushtoknow evaluate-real` calls it on every file).
"""

from __future__ import annotations

import bisect
import json
import math
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import cache
from pathlib import Path

import numpy as np

from pushtoknow.common.errors import DatasetError, ObjectSpecError
from pushtoknow.common.files import find_files
from pushtoknow.common.params import GRAVITY, ObjectParams

__all__ = [
    "CONTACT_FORCE_THRESHOLD",
    "DEFAULT_RATE_HZ",
    "MIT_SHAPES",
    "PUSHER_RADIUS",
    "MitObject",
    "MitPush",
    "MitPushMeta",
    "MitPushWarning",
    "MitRawStreams",
    "check_mit_push",
    "contact_phase_force",
    "dataset_to_centroid_pose",
    "estimate_friction",
    "find_mit_push_files",
    "iter_mit_push",
    "load_mit_streams",
    "mit_object",
    "mit_polygon",
    "parse_mit_filename",
    "read_mit_push",
    "window_means",
]

# --- file format -----------------------------------------------------------------------------
STREAMS: tuple[str, ...] = ("tip_pose", "object_pose", "ft_wrench")
STREAM_COLUMNS = 4  # [t, a, b, c]
MIN_ROWS = 2
FILE_PREFIX = "motion_surface="
SUFFIXES: tuple[str, ...] = (".json", ".h5")
PREFERRED_SUFFIX = ".h5"  # when a push exists as both .json and .h5, iterate over this one
_NUM = r"[-+]?\d+(?:\.\d*)?(?:[eE][-+]?\d+)?"
_NAME_RE = re.compile(
    rf"^motion_surface=(?P<surface>[A-Za-z0-9]+)_shape=(?P<shape>[A-Za-z0-9]+)"
    rf"_a=(?P<a>{_NUM})_v=(?P<v>{_NUM})_i=(?P<i>{_NUM})_s=(?P<s>{_NUM})_t=(?P<t>{_NUM})"
    rf"\.(?P<ext>json|h5)$"
)
NAME_PATTERN = "motion_surface=<s>_shape=<o>_a=<acc>_v=<mm/s>_i=<side>_s=<pos>_t=<rad>.{json,h5}"
MM_PER_M = 1000.0

# --- processing ------------------------------------------------------------------------------
DEFAULT_RATE_HZ = 10.0  # the filter's rate (docs/DESIGN.md §3)
# In samples: absorbs float64 rounding of Unix timestamps (2.4e-7 s at 1.5e9 s), so a span that
# is nominally an integer number of periods is not one sample short.
SAMPLE_COUNT_TOLERANCE = 1e-4
CONTACT_FORCE_THRESHOLD = 0.5  # N, on the window-averaged, tared force
TARE_REST_TOLERANCE = 5e-4  # m: pusher within this of its first/last position counts as at rest
TARE_GUARD = 0.05  # s kept clear of the start/end of the pusher's motion when taring
TARE_MIN_SAMPLES = 10  # fewer rest samples than this: no tare (offset 0)
YAW_JUMP_WARNING = 0.5  # rad between consecutive raw object samples
# `check_mit_push`: data errors a fit must refuse (docs/DESIGN.md §11)
FROZEN_SHARE = 0.5  # one force reading repeated over this share of the pusher's motion: frozen
MIN_MOTION_OVERLAP = 0.5  # share of the pusher's motion the three clocks must all cover
AGAINST_SHARE = 0.5  # more strong contact samples than this pointing against the push: flipped
STRONG_FORCE_SHARE = 0.5  # strong: ‖F‖ ≥ this share of the push's peak (and above contact)
SPEED_MATCH_TOLERANCE = 5e-4  # m/s (half of the file name's 1 mm/s resolution)
ACCELERATION_MATCH_TOLERANCE = 1e-9

# --- objects (docs/DESIGN.md §3, §11) ---
PUSHER_RADIUS = 4.745e-3  # m, point probe
# Coulomb coefficient of the steel probe on the steel plates: the median ratio of tangential to
# normal force at the contact over the in-contact samples of rect1, hex and ellip1 (0.14, 0.36,
# 0.25; the outline's normal at the probe), read off the force directions, not chosen on any
# estimate's accuracy. A frictionless probe cannot push with those tangential forces.
PUSHER_FRICTION = 0.25
ELLIPSE_VERTICES = 64
# Triangles: the dataset frame sits this far inside both legs from the right-angle corner
# (MIT's own processing code, pdproc `annotate.py`, and their triangle meshes agree).
TRI_FRAME_INSET = 0.045  # m
# butter: first-quadrant outline (m), traced at ~5 mm steps from the MIT group's 637-point
# outline (push-est-public, shape_db_butter_shape.h); mirrored about both axes. Non-convex:
# 0.0955 m wide at its widest, 0.0549 m at the waist, 0.156 m long.
_BUTTER_QUADRANT: tuple[tuple[float, float], ...] = (
    (0.02746, 0.0),
    (0.02794, 0.00373),
    (0.02967, 0.00871),
    (0.03220, 0.01367),
    (0.03523, 0.01862),
    (0.03846, 0.02355),
    (0.04161, 0.02846),
    (0.04438, 0.03334),
    (0.04647, 0.03818),
    (0.04759, 0.04299),
    (0.04775, 0.04419),
    (0.04749, 0.04775),
    (0.04618, 0.05242),
    (0.04379, 0.05691),
    (0.04042, 0.06116),
    (0.03621, 0.06509),
    (0.03127, 0.06864),
    (0.02572, 0.07172),
    (0.01970, 0.07427),
    (0.01331, 0.07621),
    (0.00667, 0.07746),
    (0.0, 0.07802),
)
# name: (kind, geometry in the dataset frame (m), mass (kg), I_z about the CoM (kg·m²))
_CATALOGUE: dict[str, tuple[str, tuple[float, ...], float, float]] = {
    "rect1": ("rectangle", (0.090, 0.090), 0.8374, 1.131e-3),
    "rect2": ("rectangle", (0.0899, 0.1126), 1.045, 1.808e-3),
    "rect3": ("rectangle", (0.1350, 0.0899), 1.2508, 2.744e-3),
    "tri1": ("right_triangle", (0.1259, 0.1259), 0.8028, 1.414e-3),
    "tri2": ("right_triangle", (0.1510, 0.1259), 0.9826, 2.108e-3),
    "tri3": ("right_triangle", (0.1765, 0.1256), 1.1326, 2.957e-3),
    "ellip1": ("ellipse", (0.0525, 0.0525), 0.8937, 1.231e-3),
    "ellip2": ("ellipse", (0.0525, 0.0654), 1.1104, 1.953e-3),
    "ellip3": ("ellipse", (0.0525, 0.0785), 1.3338, 2.973e-3),
    "hex": ("hexagon", (0.0605,), 0.9827, 1.497e-3),
    "butter": ("outline", (), 1.1974, 2.954e-3),
}
MIT_SHAPES: tuple[str, ...] = tuple(_CATALOGUE)


class MitPushWarning(UserWarning):
    """A recording looks suspicious but was read anyway (e.g. a motion-capture yaw flip)."""


# ============================================================================================
# File names
# ============================================================================================
@dataclass(frozen=True)
class MitPushMeta:
    """What a file name says about the push.

    acceleration: the name's ``a`` as written. 0 is a constant-speed push, the subset the paper
    uses. The name does not give the unit of nonzero values.
    speed: m/s (the name gives mm/s). side: index of the pushed side as written (``i``).
    position: where along that side, a fraction in [0, 1] (``s``). angle: push direction
    relative to the side's normal, rad (``t``).
    """

    surface: str
    shape: str
    acceleration: float
    speed: float
    side: float
    position: float
    angle: float


def parse_mit_filename(path: str | Path) -> MitPushMeta:
    """Parse a MIT Push file name. Raises `DatasetError` naming the file if it does not match."""
    name = Path(path).name
    m = _NAME_RE.match(name)
    if m is None:
        raise DatasetError(path, f"file name does not match {NAME_PATTERN}")
    shape = m["shape"]
    if shape not in _CATALOGUE:
        raise DatasetError(path, f"unknown shape {shape!r} (known: {', '.join(MIT_SHAPES)})")
    return MitPushMeta(
        surface=m["surface"],
        shape=shape,
        acceleration=float(m["a"]),
        speed=float(m["v"]) / MM_PER_M,
        side=float(m["i"]),
        position=float(m["s"]),
        angle=float(m["t"]),
    )


# ============================================================================================
# Object catalogue
# ============================================================================================
@dataclass(frozen=True)
class MitObject:
    """A MIT Push object: stainless steel, 13 mm thick, CoM at the footprint centroid.

    polygon: (V, 2) m, counter-clockwise, in the object frame centred on the centroid (axes as
    in the dataset). frame_offset: (2,) m, the centroid's position in the dataset's object frame,
    so centroid_world = p_dataset + R(θ)·frame_offset. It is zero except for the triangles.
    mass in kg, inertia (I_z about the vertical axis through the CoM) in kg·m².
    """

    name: str
    kind: str
    mass: float
    inertia: float
    polygon: np.ndarray = field(compare=False, repr=False)
    frame_offset: np.ndarray = field(compare=False)

    def params(self, friction: float) -> ObjectParams:
        """φ in SI with the given object–surface friction (the dataset does not give it)."""
        return ObjectParams(self.mass, float(friction), 0.0, 0.0, self.inertia)


def _dataset_frame_polygon(shape: str, ellipse_vertices: int) -> np.ndarray:
    """(V, 2) CCW footprint in the dataset's object frame (m)."""
    kind, dims, _, _ = _CATALOGUE[shape]
    if kind == "rectangle":
        hx, hy = dims[0] / 2, dims[1] / 2
        return np.array([[-hx, -hy], [hx, -hy], [hx, hy], [-hx, hy]])
    if kind == "right_triangle":
        # Right angle at (r, r); legs of length dims[0] along -x and dims[1] along -y.
        r = TRI_FRAME_INSET
        return np.array([[r, r], [r - dims[0], r], [r, r - dims[1]]])
    if kind == "ellipse":
        t = np.linspace(0.0, 2 * np.pi, ellipse_vertices, endpoint=False)
        return np.stack([dims[0] * np.cos(t), dims[1] * np.sin(t)], axis=1)
    if kind == "hexagon":
        t = np.arange(6) * np.pi / 3  # a vertex on +x
        return np.stack([dims[0] * np.cos(t), dims[0] * np.sin(t)], axis=1)
    q = np.asarray(_BUTTER_QUADRANT)  # from (x0, 0) to (0, y_max), counter-clockwise
    return np.vstack(
        [
            q,
            (q * [-1.0, 1.0])[::-1][1:],
            (q * [-1.0, -1.0])[1:],
            (q * [1.0, -1.0])[::-1][1:-1],
        ]
    )


def _polygon_centroid(v: np.ndarray) -> np.ndarray:
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = cross.sum() / 2
    return np.array([((x + x1) * cross).sum(), ((y + y1) * cross).sum()]) / (6 * area)


def _check_shape(shape: str) -> None:
    if shape not in _CATALOGUE:
        raise ObjectSpecError("shape", shape, f"unknown MIT shape (known: {', '.join(MIT_SHAPES)})")


def mit_polygon(
    shape: str, ellipse_vertices: int = ELLIPSE_VERTICES, frame: str = "centroid"
) -> np.ndarray:
    """Footprint of a MIT shape as a (V, 2) counter-clockwise polygon in metres.

    frame="centroid" (default) centres it on the footprint centroid (docs/DESIGN.md §2).
    frame="dataset" gives it in the dataset's object frame, the frame of the raw ``object_pose``.
    Ellipses are sampled at `ellipse_vertices` points on the ellipse.
    """
    _check_shape(shape)
    if frame not in ("centroid", "dataset"):
        raise ValueError(f"frame must be 'centroid' or 'dataset', got {frame!r}")
    if ellipse_vertices < 3:
        raise ValueError(f"ellipse_vertices must be >= 3, got {ellipse_vertices}")
    v = _dataset_frame_polygon(shape, ellipse_vertices)
    return v - _polygon_centroid(v) if frame == "centroid" else v


@cache
def mit_object(shape: str) -> MitObject:
    """Catalogue entry of a MIT shape: masses and I_z from docs/DESIGN.md §11, footprints from §3.

    Frames: rectangles, ellipses (semi-axis 0.0525 m along x) and the hexagon (a vertex on +x)
    are centred in the dataset frame. The right triangles are not. The dataset frame has its
    origin `TRI_FRAME_INSET` = 45 mm inside both legs from the right-angle corner, with legs
    along -x (tri1 0.1259, tri2 0.1510, tri3 0.1765 m) and -y (0.1259, 0.1259, 0.1256 m). So
    the centroid is at (0.045 - L_x/3, 0.045 - L_y/3) in that frame: tri1 (+3.0, +3.0) mm,
    tri2 (-5.3, +3.0) mm, tri3 (-13.8, +3.1) mm. This offset is taken from the MIT group's own
    code (pdproc `annotate.py` triangle corners; the tri1 mesh there has its corner at
    (45.05, 45.07) mm). It could not be checked on the sample files, which are all rect1.
    The stated I_z values match a uniform plate on these footprints about the centroid within
    0.2%, which supports "CoM at the centroid".
    butter is not the rounded convex shape docs/DESIGN.md §3 suggests. It is a non-convex "peanut"
    0.0955 m wide (waist 0.0549 m) and 0.156 m long, approximated by an 84-vertex polygon
    traced from the MIT outline. Its area gives the stated mass within 0.2% and I_z within 1%
    at the density of rect1. A 0.095 m rounded rectangle would be 30% too light.
    """
    _check_shape(shape)
    kind, _, mass, inertia = _CATALOGUE[shape]
    v = _dataset_frame_polygon(shape, ELLIPSE_VERTICES)
    c = _polygon_centroid(v)
    if kind != "right_triangle":  # symmetric shapes: exactly centred
        c = np.zeros(2)
    poly = v - c
    poly.setflags(write=False)
    c.setflags(write=False)
    return MitObject(shape, kind, mass, inertia, poly, c)


def dataset_to_centroid_pose(pose: np.ndarray, shape: str) -> np.ndarray:
    """Map (..., 3) poses of the dataset's object frame to poses of the centroid frame.

    x_c = x + R(θ)·frame_offset, θ unchanged (same axes). Units m, m, rad.
    """
    off = mit_object(shape).frame_offset
    pose = np.asarray(pose, dtype=np.float64)
    out = pose.copy()
    c, s = np.cos(pose[..., 2]), np.sin(pose[..., 2])
    out[..., 0] = pose[..., 0] + c * off[0] - s * off[1]
    out[..., 1] = pose[..., 1] + s * off[0] + c * off[1]
    return out


# ============================================================================================
# Loading and validation
# ============================================================================================
@dataclass(frozen=True, eq=False)
class MitRawStreams:
    """The three streams as read, with timestamps made strictly increasing (see module doc).

    Each is (N, 4) float64 [t (Unix s), ...], in the file's units and frames (yaw as recorded,
    force as measured on the probe, offset not removed). dropped: rows removed per stream.
    """

    tip_pose: np.ndarray
    object_pose: np.ndarray
    ft_wrench: np.ndarray
    dropped: dict[str, int]


def _load_json(path: Path) -> tuple[dict, list[str]]:
    try:
        with path.open("r", encoding="utf-8") as fh:
            data = json.load(fh)
    except json.JSONDecodeError as e:
        raise DatasetError(path, f"corrupt JSON: {e}") from None
    except UnicodeDecodeError as e:
        raise DatasetError(path, f"corrupt JSON (not UTF-8 text): {e}") from None
    if not isinstance(data, dict):
        raise DatasetError(path, f"corrupt JSON: top level is {type(data).__name__}, not an object")
    return data, sorted(data)


def _load_h5(path: Path) -> tuple[dict, list[str]]:
    import h5py

    try:
        with h5py.File(path, "r") as h5:
            out = {}
            for name in STREAMS:
                if name not in h5:
                    continue
                item = h5[name]
                if not isinstance(item, h5py.Dataset):
                    raise DatasetError(path, f"{name}: is an HDF5 group, expected an N×4 dataset")
                out[name] = item[()]
            keys = sorted(h5.keys())
    except DatasetError:
        raise
    except (OSError, KeyError, ValueError, RuntimeError) as e:
        raise DatasetError(path, f"corrupt or unreadable HDF5: {e}") from None
    return out, keys


def _as_table(path: Path, name: str, value) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError) as e:
        raise DatasetError(path, f"{name}: not a numeric N×{STREAM_COLUMNS} table ({e})") from None
    if a.ndim != 2 or a.shape[1] != STREAM_COLUMNS:
        raise DatasetError(
            path, f"{name}: expected shape (N, {STREAM_COLUMNS}) [t, ., ., .], got {a.shape}"
        )
    if a.shape[0] < MIN_ROWS:
        raise DatasetError(path, f"{name}: {a.shape[0]} row(s), need at least {MIN_ROWS}")
    bad = ~np.isfinite(a)
    if bad.any():
        rows = np.flatnonzero(bad.any(axis=1))
        raise DatasetError(
            path,
            f"{name}: {int(bad.sum())} non-finite value(s) (NaN/Inf), first in row {rows[0]}",
        )
    return a


def _increasing_rows(t: np.ndarray) -> np.ndarray:
    """Indices (file order) of the longest strictly increasing run of timestamps.

    Of equal timestamps the later row wins, so duplicates keep the last row.
    """
    if np.all(np.diff(t) > 0):
        return np.arange(len(t))
    tail_values: list[float] = []
    tail_index: list[int] = []
    prev = np.full(len(t), -1, dtype=np.int64)
    for i, v in enumerate(t.tolist()):
        j = bisect.bisect_left(tail_values, v)
        if j > 0:
            prev[i] = tail_index[j - 1]
        if j == len(tail_values):
            tail_values.append(v)
            tail_index.append(i)
        else:
            tail_values[j] = v
            tail_index[j] = i
    keep = []
    k = tail_index[-1]
    while k >= 0:
        keep.append(k)
        k = int(prev[k])
    return np.asarray(keep[::-1], dtype=np.int64)


def load_mit_streams(path: str | Path) -> MitRawStreams:
    """Load and validate the three streams of a ``.json`` or ``.h5`` file (Unix times kept).

    Raises `DatasetError` naming the file for unreadable files, missing streams, tables that
    are not (N >= 2, 4), non-finite values, or fewer than 2 rows left after ordering.
    """
    path = Path(path)
    if not path.is_file():
        raise DatasetError(path, "no such file")
    suffix = path.suffix.lower()
    if suffix == ".json":
        data, keys = _load_json(path)
    elif suffix == ".h5":
        data, keys = _load_h5(path)
    else:
        raise DatasetError(path, f"unsupported file type {path.suffix!r} (expected .json or .h5)")
    tables, dropped = {}, {}
    for name in STREAMS:
        if name not in data:
            raise DatasetError(
                path, f"missing stream {name!r} (found: {', '.join(keys) or 'none'})"
            )
        a = _as_table(path, name, data[name])
        keep = _increasing_rows(a[:, 0])
        if len(keep) < MIN_ROWS:
            raise DatasetError(path, f"{name}: fewer than {MIN_ROWS} rows with distinct timestamps")
        tables[name] = a[keep]
        dropped[name] = len(a) - len(keep)
    return MitRawStreams(dropped=dropped, **tables)


# ============================================================================================
# Synchronisation
# ============================================================================================
@dataclass(frozen=True, eq=False)
class MitPush:
    """One push resampled to a common clock (see the module doc for every rule).

    times: (K,) s from 0, = k/rate. t0: Unix time (s) of times[0].
    object_pose: (K, 3) world (x, y, θ) of the footprint centroid (m, m, rad), θ unwrapped.
    tip_pose: (K, 2) world (x, y) of the probe's centre (m). The probe is round, so its yaw
    is dropped; it is still in raw.tip_pose.
    force: (K, 2) N, world frame, force applied *to the object* by the pusher, tared, averaged
    over the window ending at sample k, [t_k - 1/rate, t_k), as in the simulator (module doc,
    item 5). Window 0 lies before t_start: its raw samples if the force stream has any there,
    else the first raw reading. force_samples: (K,) raw samples in each window (0: interpolated
    at the window's centre). contact: (K,) ‖force‖ > contact_threshold, so contact[k] says the
    pusher pushed during the window before t_k. force_offset: (2,) N, sensor offset subtracted
    from the raw f_x, f_y (probe sign convention).
    """

    path: Path
    meta: MitPushMeta
    obj: MitObject
    rate: float
    t0: float
    times: np.ndarray
    object_pose: np.ndarray
    tip_pose: np.ndarray
    force: np.ndarray
    force_samples: np.ndarray
    contact: np.ndarray
    contact_threshold: float
    force_offset: np.ndarray
    raw: MitRawStreams

    @property
    def duration(self) -> float:
        """Length of the common time span (s), K/rate <= duration < (K+1)/rate."""
        t = [self.raw.tip_pose[:, 0], self.raw.object_pose[:, 0], self.raw.ft_wrench[:, 0]]
        return float(min(a[-1] for a in t) - max(a[0] for a in t))

    def __len__(self) -> int:
        return len(self.times)


def _force_offset(tip: np.ndarray, ft: np.ndarray) -> np.ndarray:
    """Median raw (f_x, f_y) while the pusher rests before/after its motion; 0 if too few."""
    xy = tip[:, 1:3]
    moved_from_start = np.linalg.norm(xy - xy[0], axis=1) > TARE_REST_TOLERANCE
    away_from_end = np.linalg.norm(xy - xy[-1], axis=1) > TARE_REST_TOLERANCE
    t = ft[:, 0]
    if not moved_from_start.any():  # the pusher never moved: every sample is at rest
        rest = np.ones(len(t), dtype=bool)
    else:
        t_move = tip[np.argmax(moved_from_start), 0]
        t_stop = tip[len(xy) - 1 - np.argmax(away_from_end[::-1]), 0]
        rest = (t < t_move - TARE_GUARD) | (t > t_stop + TARE_GUARD)
    if rest.sum() < TARE_MIN_SAMPLES:
        return np.zeros(2)
    return np.median(ft[rest, 1:3], axis=0)


def window_means(t: np.ndarray, values: np.ndarray, rate: float, k: int) -> tuple:
    """Mean of values over the windows [(i - 1)/rate, i/rate), i < k, that end at the samples
    (t relative to t_start; window 0 lies before it). A window with no sample gets np.interp at
    its centre (i - 1/2)/rate, which clamps to the first/last value outside the stream."""
    edges = (np.arange(k + 1) - 1.0) / rate
    lo = np.searchsorted(t, edges[:-1], side="left")
    hi = np.searchsorted(t, edges[1:], side="left")
    counts = hi - lo
    csum = np.vstack([np.zeros((1, values.shape[1])), np.cumsum(values, axis=0)])
    out = np.empty((k, values.shape[1]))
    full = counts > 0
    out[full] = (csum[hi[full]] - csum[lo[full]]) / counts[full, None]
    if not full.all():
        centres = (np.flatnonzero(~full) - 0.5) / rate
        for j in range(values.shape[1]):
            out[~full, j] = np.interp(centres, t, values[:, j])
    return out, counts


def read_mit_push(
    path: str | Path,
    rate: float = DEFAULT_RATE_HZ,
    *,
    tare: bool = True,
    contact_threshold: float = CONTACT_FORCE_THRESHOLD,
) -> MitPush:
    """Read a MIT Push ``.json``/``.h5`` file and resample it to ``rate`` Hz (module doc).

    tare=False keeps the sensor offset in the force (force_offset is then 0).
    Raises `DatasetError` naming the file for bad names, unknown shapes, corrupt or invalid
    content, streams that do not overlap, or a common span shorter than 1/rate.
    """
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number of Hz, got {rate!r}")
    path = Path(path)
    meta = parse_mit_filename(path)
    obj = mit_object(meta.shape)
    raw = load_mit_streams(path)
    tip, objp, ft = raw.tip_pose, raw.object_pose, raw.ft_wrench

    t_start = max(tip[0, 0], objp[0, 0], ft[0, 0])
    t_end = min(tip[-1, 0], objp[-1, 0], ft[-1, 0])
    if t_end <= t_start:
        raise DatasetError(path, "the three streams do not overlap in time")
    k = math.floor((t_end - t_start) * rate + SAMPLE_COUNT_TOLERANCE)
    if k < 1:
        raise DatasetError(
            path, f"common time span {t_end - t_start:.4f} s is shorter than 1/rate = {1 / rate} s"
        )
    times = np.arange(k) / rate

    yaw = np.unwrap(objp[:, 3])
    steps = np.abs(np.diff(yaw))
    if steps.size and steps.max() > YAW_JUMP_WARNING:
        i = int(np.argmax(steps))
        warnings.warn(
            f"{path}: object yaw jumps by {math.degrees(steps[i]):.1f}° between consecutive "
            f"samples at t = {objp[i + 1, 0] - t_start:+.3f} s (a motion-capture flip?); "
            "not corrected",
            MitPushWarning,
            stacklevel=2,
        )
    to = objp[:, 0] - t_start
    pose = np.stack(
        [
            np.interp(times, to, objp[:, 1]),
            np.interp(times, to, objp[:, 2]),
            np.interp(times, to, yaw),
        ],
        axis=1,
    )
    pose = dataset_to_centroid_pose(pose, meta.shape)
    tt = tip[:, 0] - t_start
    tip_xy = np.stack([np.interp(times, tt, tip[:, 1]), np.interp(times, tt, tip[:, 2])], axis=1)

    offset = _force_offset(tip, ft) if tare else np.zeros(2)
    f_on_object = -(ft[:, 1:3] - offset)
    force, counts = window_means(ft[:, 0] - t_start, f_on_object, rate, k)
    contact = np.linalg.norm(force, axis=1) > contact_threshold

    return MitPush(
        path=path,
        meta=meta,
        obj=obj,
        rate=float(rate),
        t0=float(t_start),
        times=times,
        object_pose=pose,
        tip_pose=tip_xy,
        force=force,
        force_samples=counts,
        contact=contact,
        contact_threshold=float(contact_threshold),
        force_offset=offset,
        raw=raw,
    )


# ============================================================================================
# Selection and friction
# ============================================================================================
def _matches(meta: MitPushMeta, surface, shape, acceleration, speed) -> bool:
    if surface is not None and meta.surface != surface:
        return False
    if shape is not None and meta.shape != shape:
        return False
    if acceleration is not None and not math.isclose(
        meta.acceleration, acceleration, rel_tol=0.0, abs_tol=ACCELERATION_MATCH_TOLERANCE
    ):
        return False
    return speed is None or math.isclose(
        meta.speed, speed, rel_tol=0.0, abs_tol=SPEED_MATCH_TOLERANCE
    )


def find_mit_push_files(
    directory: str | Path,
    surface: str | None = None,
    shape: str | None = None,
    acceleration: float | None = None,
    speed: float | None = None,
) -> list[tuple[Path, MitPushMeta]]:
    """Files under `directory` (recursive) whose names match the filters, sorted by path.

    speed in m/s (e.g. 0.02 for the name's v=20). Only names starting with
    ``motion_surface=`` and ending in .json/.h5 are considered. A malformed one of those raises
    `DatasetError`. A push present as both .json and .h5 in one folder is listed once (.h5).
    """
    root = Path(directory)
    if not root.is_dir():
        raise DatasetError(root, "not a directory")
    chosen: dict[tuple[Path, str], Path] = {}
    for p in find_files(root, f"{FILE_PREFIX}*"):
        if p.suffix.lower() not in SUFFIXES:
            continue
        key = (p.parent, p.stem)
        if key not in chosen or p.suffix.lower() == PREFERRED_SUFFIX:
            chosen[key] = p
    out = []
    for p in sorted(chosen.values()):
        meta = parse_mit_filename(p)
        if _matches(meta, surface, shape, acceleration, speed):
            out.append((p, meta))
    return out


def iter_mit_push(
    directory: str | Path,
    surface: str | None = None,
    shape: str | None = None,
    acceleration: float | None = None,
    speed: float | None = None,
    *,
    rate: float = DEFAULT_RATE_HZ,
    tare: bool = True,
) -> Iterator[MitPush]:
    """Read every push under `directory` that matches the filters (see `find_mit_push_files`).

    The paper's subset: ``acceleration=0`` (constant speed) and one ``speed`` in m/s.
    """
    for p, _ in find_mit_push_files(directory, surface, shape, acceleration, speed):
        yield read_mit_push(p, rate, tare=tare)


def contact_phase_force(force: np.ndarray, contact: np.ndarray) -> np.ndarray:
    """‖F‖ (N) of every sample from the first to the last one in contact (empty: no contact).

    The friction rule of real pushes (docs/DESIGN.md §11): a pure translation at steady speed
    needs exactly μ·m·g of push on time average over its contact phase. The samples inside the
    phase whose force dropped below the contact threshold are kept: at 100 mm/s the probe
    bounces off the plate (stick-slip, 0–8 N at 50 Hz), and dropping them would bias μ up by a
    quarter (0.36 against 0.29 on the rect1 centre push, where this rule gives 0.29 at both 10
    and 50 Hz)."""
    idx = np.flatnonzero(np.asarray(contact, dtype=bool))
    if idx.size == 0:
        return np.zeros(0)
    return np.linalg.norm(np.asarray(force)[idx[0] : idx[-1] + 1, :2], axis=1)


def estimate_friction(push: MitPush) -> float:
    """Object–surface friction μ ≈ mean ‖F‖ / (m·g) over the push's contact phase
    (`contact_phase_force`).

    Valid for pure translations at constant speed, where all the table friction opposes the
    motion and balances the push. When the object also rotates, part of the friction acts as
    a torque, ‖F‖ < μ·m·g and μ is underestimated. Acceleration transients bias it the other
    way. Raises `DatasetError` if no sample is in contact.
    """
    phase = contact_phase_force(push.force, push.contact)
    if phase.size == 0:
        raise DatasetError(push.path, "no samples in contact: cannot estimate friction")
    return float(phase.mean()) / (push.obj.mass * GRAVITY)


# ============================================================================================
# Checks before a fit
# ============================================================================================
def _motion_span(tip: np.ndarray) -> tuple[float, float] | None:
    """(t_move, t_stop) Unix s of the pusher's motion (raw tip rows), None if it never moves."""
    xy = tip[:, 1:3]
    moved = np.linalg.norm(xy - xy[0], axis=1) > TARE_REST_TOLERANCE
    away = np.linalg.norm(xy - xy[-1], axis=1) > TARE_REST_TOLERANCE
    if not moved.any():
        return None
    return float(tip[np.argmax(moved), 0]), float(tip[len(xy) - 1 - np.argmax(away[::-1]), 0])


def _longest_repeat(values: np.ndarray) -> tuple[int, int]:
    """(length, first row) of the longest run of identical consecutive rows of (N, c)."""
    if len(values) == 0:
        return 0, 0
    same = np.all(np.diff(values, axis=0) == 0, axis=1)
    best, start, run = 1, 0, 1
    for i, s in enumerate(same, start=1):
        run = run + 1 if s else 1
        if run > best:
            best, start = run, i - run + 1
    return best, start


def strong_force_along(force: np.ndarray, unit: np.ndarray, among: np.ndarray) -> np.ndarray:
    """(S,) the force (N, 2) along `unit` (N) on its strong samples among the mask `among`
    (N,): ‖F‖ ≥ `STRONG_FORCE_SHARE` of their peak. A pushed object's force points along the
    push: more than `AGAINST_SHARE` of them below 0 is a flipped sign."""
    mag = np.linalg.norm(force, axis=1)
    strong = among & (mag >= STRONG_FORCE_SHARE * float(mag[among].max()))
    return force[strong] @ unit


def check_mit_push(push: MitPush, *, contact: bool = True) -> None:
    """Refuse a push no estimator may fit: `DatasetError` naming the file, in one line, for

    - a frozen stream: a pusher that never moves; the force (``ft_wrench`` f_x, f_y)
      repeating one reading unchanged over ≥ `FROZEN_SHARE` of its samples while the pusher
      moves (a real sensor's noise never repeats a reading; a stuck driver does, and taring
      would turn it into "no force"); the object's pose (``object_pose``) at one reading
      throughout a push in contact;
    - clocks that cover less than `MIN_MOTION_OVERLAP` of the pusher's motion in common;
    - no contact, when `contact`: no sample with ‖F‖ above the contact threshold (a push
      that missed the object tells nothing about it);
    - a flipped force sign: most strong contact samples (‖F‖ ≥ `STRONG_FORCE_SHARE` of the
      peak) point against the pusher's motion, while the force on the object must push it.
    """
    raw, path = push.raw, push.path
    span = _motion_span(raw.tip_pose)
    if span is None:
        raise DatasetError(path, "tip_pose: the pusher never moves")
    t_move, t_stop = span
    ft = raw.ft_wrench
    moving = (ft[:, 0] >= t_move) & (ft[:, 0] <= t_stop)
    run, first = _longest_repeat(ft[moving, 1:3])
    if moving.sum() >= 2 and run >= FROZEN_SHARE * moving.sum():
        value = ft[moving][first, 1:3].tolist()
        raise DatasetError(
            path,
            f"ft_wrench: frozen, (f_x, f_y) = {value} N unchanged over {run} of the "
            f"{int(moving.sum())} samples while the pusher moves",
        )
    t_end = push.t0 + push.duration
    covered = max(0.0, min(t_stop, t_end) - max(t_move, push.t0))
    if covered < MIN_MOTION_OVERLAP * (t_stop - t_move):
        raise DatasetError(
            path,
            f"the three clocks overlap over {covered:.3f} s of the pusher's "
            f"{t_stop - t_move:.3f} s motion (need {MIN_MOTION_OVERLAP:.0%})",
        )
    if not push.contact.any():
        if contact:
            raise DatasetError(
                path,
                f"no contact: ‖F‖ never exceeds {push.contact_threshold:g} N (the pusher "
                "missed the object)",
            )
        return
    pose = raw.object_pose[:, 1:]
    if (pose == pose[0]).all():
        raise DatasetError(
            path,
            f"object_pose: frozen, {pose[0].tolist()} at all {len(pose)} samples while the "
            "pusher pushes the object",
        )
    d = push.tip_pose[-1] - push.tip_pose[0]
    if float(np.linalg.norm(d)) <= TARE_REST_TOLERANCE:
        return
    along = strong_force_along(push.force, d / np.linalg.norm(d), push.contact)
    against = int((along < 0).sum())
    if against > AGAINST_SHARE * len(along):
        raise DatasetError(
            path,
            f"ft_wrench: the force on the object points against the push on {against} of "
            f"{len(along)} strong contact samples (mean {along.mean():+.3g} N along the "
            "pusher's motion): sign flipped?",
        )
