"""Convert MIT Push recordings into the project's HDF5 shards, with synthetic RGB-D (docs/DESIGN.md
§11).

The MIT Push dataset has no images. As the paper did, every 10 Hz sample is *rendered* with the
testbed's MuJoCo scene: the object is placed at its recorded pose and the pad at the recorded
tip position (qpos set directly, `mj_forward`, no physics stepping), so the filter gets the same
kind of observation as in simulation. One `PushSimulator` is built per MIT shape and reused.

Conventions of the converted data (all SI):

- **Shift.** MIT poses are in the robot's frame (objects near x ≈ 0.35 m, outside the
  camera's centre). Each push is *translated* (no rotation) so that the object's initial
  centroid is at the camera centre (0, 0): ``p_converted = p_mit + shift`` with
  ``shift = -object_pose[0, :2]`` (m), applied to the object poses, the tip positions and the
  contact point. θ is unchanged. Forces are unaffected (a translation). The shift of every push
  is stored in its shard group as attribute ``mit_shift`` (2,) m.
- **Object.** ``ObjectSpec`` with the shape ``{"type": "polygon", "vertices": mit_polygon(s)}``
  (centroid frame), the catalogue mass and I_z (`mit_object`), CoM at (0, 0), height 0.013 m.
  Friction is not given by the dataset: each push's `estimate_friction` (the contact-phase
  rule, `mit_push.contact_phase_force`, also the real-data evaluation's) is valid when the push
  has a contact sample and the estimate lies in `FRICTION_VALID_RANGE`; the object's μ is the
  median of its pushes' valid estimates, or `FALLBACK_FRICTION` when none is valid (the spec
  needs μ > 0). Per-push estimates are stored as ``mit_friction`` (NaN when invalid), and the
  object's ``friction_source`` says which rule gave μ. An object is one shape on one surface:
  pushes are grouped by (surface, shape), since μ depends on the surface.
- **Action.** profile "constant", speed = the file's v (m/s). Contact samples are first..last
  (the first and last sample with contact). Sample k's force is that of the window ending at
  t_k (see Tactile), so contact is first felt in [t_{first} - 1/rate, t_first) and the contact
  phase is the time from t_{onset} to t_last, onset = max(first - 1, 0): sample `onset` is the
  last one before contact, the pusher's position when it reaches the object (0 when contact is
  already felt in window 0). direction = angle of the tip's displacement from sample onset to
  sample last; if that is shorter than `MIN_DIRECTION_DISPLACEMENT` (the tip hardly moved
  while in contact), the displacement over the whole push; if that is short too, from the tip
  towards the centroid at sample onset. contact point = the point of the object's boundary
  nearest the tip at sample onset, found in the object frame at that sample and placed on the
  *initial* pose (the S_0 boundary, as simulated actions are), shifted. The tip centre itself
  is `PUSHER_RADIUS` (4.7 mm) outside it. A push with no contact sample uses sample 0 for
  both.
- **Tactile.** (F_x, F_y, contact) with the reader's force on the object in world axes, tared
  and averaged over the window ending at t_k, [t_k - 1/rate, t_k), the simulator's timing;
  contact ∈ {0, 1} (the reader's ‖F‖ > 0.5 N, not the simulator's contact share). Real data
  have no noiseless force: ``force_clean`` is None (not stored). Sample 0 differs
  from the simulator's, which is zero: it is the force of the window before t_start when the
  force stream has samples there, else the first force reading (see `read_mit_push`).
- **Pusher** = tip positions (shifted); the pad is rendered with the probe's radius. The raw
  tip stream (shifted, on the record's clock, resampled at 4 ms and averaged over 20 ms, as its
  stamps jitter) is kept as `PushRecord.pusher_fine`, so a replay drives the pad at that rate
  rather than linearly between 10 Hz samples.
- The camera model (`CameraConfig`) is the simulator's default, 64 × 64 px, overhead at 0.75 m.
- **Time rescaling (optional, ``as_speed``; off by default).** A model trained on pushes at
  speed v_train sees, per 10 Hz step, a pusher displacement of v_train / rate. A recording at
  v_file can be presented at v_train by slowing its clock down by s = v_file / v_train: the
  push is resampled at rate·s Hz of recorded time, the samples are relabelled
  ``time = k / rate`` (so the converted push lasts s times longer) and its action's speed is
  v_file / s = v_train. Poses, pusher positions and forces are unchanged: each force sample
  averages the recorded window [t_k - 1/(rate·s), t_k) of real time. This is exact only for
  **quasi-static** pushing, whose motion and forces depend on the path, not on the rate; the
  inertial part of the real force (m·a, free sliding after the pusher stops) is not rescaled.
  s is stored per push as ``mit_time_scale`` (1 without rescaling) and the rule in
  import.json (``time_scale_convention``).

Shards are written one at a time, atomically, with the per-push MIT attributes added before the
final rename (``mit_file``, ``mit_shift``, ``mit_t0``, ``mit_force_offset``, ``mit_friction``,
``mit_contact_span``, ``mit_meta``). An ``import.json`` records the source, filters, conventions
and the plan; a re-run with the same settings skips finished shards.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.files import atomic_write, file_sha256
from pushtoknow.datasets.lock import dataset_lock
from pushtoknow.datasets.mit_push import (
    MIT_SHAPES,
    MM_PER_M,
    PUSHER_FRICTION,
    PUSHER_RADIUS,
    MitPush,
    MitPushMeta,
    estimate_friction,
    find_mit_push_files,
    mit_object,
    mit_polygon,
    parse_mit_filename,
    read_mit_push,
)
from pushtoknow.datasets.pad_track import (
    MIN_DIRECTION_DISPLACEMENT,
    contact_span,
    push_from_track,
)
from pushtoknow.datasets.shards import (
    ObjectEpisode,
    shard_is_finished,
    shard_path,
    write_shard,
)
from pushtoknow.testbed.objects import DEFAULT_HEIGHT, ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord, PushSimulator, mujoco
from pushtoknow.testbed.sim_config import PadConfig, SimConfig, TactileConfig

__all__ = [
    "FALLBACK_FRICTION",
    "FRICTION_VALID_RANGE",
    "IMPORT_FILE",
    "IMPORT_VERSION",
    "MIN_DIRECTION_DISPLACEMENT",
    "TACTILE_CONVENTION",
    "TIME_SCALE_CONVENTION",
    "MitImportResult",
    "MitRenderer",
    "convert_push",
    "import_mit_dataset",
    "mit_object_spec",
    "mit_sim_config",
    "push_action",
    "push_friction",
    "push_shift",
    "speed_from_mm_per_s",
]

IMPORT_FILE = "import.json"
# bump when the conversion changes what is written. 2: tactile sample k averages the window
# ending at t_k (was: starting at t_k); contact spans shifted by one sample accordingly.
IMPORT_VERSION = 3  # 3: no force_clean stored (real pushes have none)
SOURCE_TAG = "mit-push"
MIT_HEIGHT = DEFAULT_HEIGHT  # m, 13 mm stainless steel plates
# μ placeholder when no push of an object gives a valid estimate: the middle of the catalogue's
# μ grid (docs/DESIGN.md §3). Not a measurement; flagged as friction_source = "fallback".
FALLBACK_FRICTION = 0.5
FRICTION_VALID_RANGE = (0.01, 2.0)  # estimates outside are rejected (ObjectSpec needs μ ≤ 2)
SHIFT_CONVENTION = (
    "p_converted = p_mit + shift, shift = -object_pose_mit[0, :2] (m), per push: the object's "
    "initial footprint centroid is at the camera centre (0, 0); theta unchanged; applied to "
    "pose, pusher and the action's contact point; stored per push as attribute mit_shift"
)
FRICTION_CONVENTION = (
    "object mu = median of the valid per-push estimates mean|F|/(m g) over contact samples "
    f"(valid: a contact sample and mu in {list(FRICTION_VALID_RANGE)}), else {FALLBACK_FRICTION} "
    "(placeholder); per-push estimates stored as attribute mit_friction (NaN when invalid)"
)
TACTILE_CONVENTION = (
    "tactile[k] = (F_x, F_y) on the object, world axes, tared, mean of the raw samples in "
    "[t_k - 1/rate, t_k) (the window ending at t_k, as in the simulator); sample 0: raw samples "
    "before t_start if any, else the first reading; contact = |F| > 0.5 N; mit_contact_span = "
    "(first, last) sample with contact"
)
TIME_SCALE_CONVENTION = (
    "as_speed v_target given: per push s = v_file / v_target; the recording is resampled at "
    "rate * s Hz of recorded time and relabelled time = k / rate, the action's speed = "
    "v_target; poses, pusher and forces unchanged (force windows of 1/(rate * s) s of real "
    "time). Assumes quasi-static pushing (rate-independent). s stored as mit_time_scale"
)
_PART_SUFFIX = ".part"
TIME_SCALE_ATTR = "mit_time_scale"  # per push attribute: the time rescaling s (1: as recorded)


# ============================================================================================
# Small helpers
# ============================================================================================
def speed_from_mm_per_s(speed_mm_per_s: float) -> float:
    """File-name / CLI speed (mm/s, e.g. ``v=20``) → m/s, the unit `import_mit_dataset` takes."""
    return float(speed_mm_per_s) / MM_PER_M


def mit_sim_config(rate: float = 10.0) -> SimConfig:
    """Testbed config of MIT pushes: default camera, the probe's radius (`PUSHER_RADIUS`, m) and
    friction on the objects (`PUSHER_FRICTION`), tactile rate = `rate` (Hz) and no tactile
    noise (real forces)."""
    return SimConfig(
        pad=PadConfig(radius=PUSHER_RADIUS, friction=PUSHER_FRICTION),
        tactile=TactileConfig(rate_hz=rate, force_noise_std=0.0),
    )


def mit_object_spec(shape: str, friction: float, *, surface: str | None = None) -> ObjectSpec:
    """`ObjectSpec` of a MIT object: polygon footprint (centroid frame, m), catalogue mass (kg)
    and I_z (kg·m²), CoM at the centroid, height 0.013 m, the given μ (> 0)."""
    obj = mit_object(shape)
    name = f"mit:{surface}:{shape}" if surface else f"mit:{shape}"
    return ObjectSpec(
        shape={"type": "polygon", "vertices": mit_polygon(shape).tolist()},
        params=obj.params(friction),
        height=MIT_HEIGHT,
        name=name,
    )


def push_friction(push: MitPush) -> float | None:
    """`estimate_friction` of the push when valid (a contact sample, μ within
    `FRICTION_VALID_RANGE`), else None."""
    if not push.contact.any():
        return None
    mu = estimate_friction(push)
    lo, hi = FRICTION_VALID_RANGE
    return mu if (math.isfinite(mu) and lo <= mu <= hi) else None


def push_shift(push: MitPush) -> np.ndarray:
    """(2,) m translation that puts the push's initial object centroid at (0, 0)."""
    return -np.asarray(push.object_pose[0, :2], dtype=np.float64)


def _contact_span(push: MitPush) -> tuple[int, int]:
    """(first, last) contact sample indices, (-1, -1) when the push never touches.

    Sample k's contact refers to the window ending at t_k, so the pusher pushed during
    [t_first - 1/rate, t_last).
    """
    return contact_span(push.contact)


def push_action(push: MitPush, shift: np.ndarray | None = None, time_scale: float = 1.0) -> Push:
    """The push a = (cp, pd, v) of a recording (`datasets.pad_track.push_from_track`'s rules).

    cp: world (m), after adding `shift` (default `push_shift`); pd: rad; v: the file's speed
    (m/s) divided by `time_scale` (see "Time rescaling" in the module doc); profile "constant".
    """
    shift = push_shift(push) if shift is None else np.asarray(shift, dtype=np.float64)
    return push_from_track(
        push.tip_pose,
        push.object_pose,
        push.contact,
        push.times,
        polygon=mit_polygon(push.meta.shape),
        speed=float(push.meta.speed) / float(time_scale),
        shift=shift,
    )


# ============================================================================================
# Rendering
# ============================================================================================
class MitRenderer:
    """Renders recorded poses of one MIT shape with the testbed's scene (no physics stepping).

    The object's planar joints and the pad's two slide joints are set from the recording, then
    `mj_forward` updates the kinematics before each render.
    """

    def __init__(self, spec: ObjectSpec, config: SimConfig | None = None):
        self.sim = PushSimulator(spec, config)
        m = self.sim.model
        px = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "pusher_x")
        self._pad_qpos = int(m.jnt_qposadr[px])
        self.camera = self.sim.camera

    def place(self, pose, pad_xy) -> None:
        """Object at pose (x, y, θ) (m, m, rad) resting on the table, pad centre at pad_xy (m)."""
        data = self.sim.data
        data.qpos[:] = self.sim.model.qpos0
        data.qvel[:] = 0.0
        self.sim.set_object_pose(pose)
        data.qpos[self._pad_qpos : self._pad_qpos + 2] = np.asarray(pad_xy, dtype=np.float64)
        mujoco.mj_forward(self.sim.model, data)

    def render(
        self, poses: np.ndarray, pad: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """poses (T, 3), pad (T, 2) → rgb (T, H, W, 3) uint8, depth (T, H, W) float32 m,
        S_0 (H, W) bool (object mask of frame 0) and S_0 at the outline resolution (kH, kW)."""
        c = self.sim.config.camera
        T = len(poses)
        rgb = np.zeros((T, c.height, c.width, 3), np.uint8)
        depth = np.zeros((T, c.height, c.width), np.float32)
        r = self.sim.renderer
        s0 = outline = None
        for k in range(T):
            self.place(poses[k], pad[k])
            if k == 0:
                s0 = r.segmentation(self.sim.data)
                outline = self.sim.outline_mask()
            rgb[k], depth[k] = r.rgbd(self.sim.data)
        return rgb, depth, s0, outline

    def close(self) -> None:
        self.sim.close()


FINE_PERIOD = 0.004  # s: the clock `fine_pusher` resamples the raw tip stream on
FINE_SMOOTHING = 5  # samples (20 ms): the raw tip stamps jitter by ±3 ms (spacing 1.2–6.6 ms)


def fine_pusher(push: MitPush, shift: np.ndarray, time_scale: float = 1.0) -> np.ndarray | None:
    """(N, 3) [t, x, y] the raw tip stream, shifted, on the record's clock (times × s) from one
    sample before the first to one after the last: resampled every `FINE_PERIOD` s and averaged
    over `FINE_SMOOTHING` samples, as its timestamps jitter (speeds read between two rows
    would spike to 2-3 × the push's). None when that leaves fewer than 2 rows."""
    tip = push.raw.tip_pose
    t_raw = tip[:, 0] - push.t0
    t = np.arange(-1.0 / push.rate, push.times[-1] + 1.0 / push.rate + 1e-9, FINE_PERIOD)
    t = t[(t >= t_raw[0]) & (t <= t_raw[-1])]
    if len(t) < max(2, FINE_SMOOTHING):
        return None
    kernel = np.ones(FINE_SMOOTHING) / FINE_SMOOTHING
    xy = [np.interp(t, t_raw, tip[:, i]) for i in (1, 2)]
    pad = FINE_SMOOTHING // 2
    xy = [np.convolve(np.pad(v, pad, mode="edge"), kernel, mode="valid") for v in xy]
    return np.column_stack([t * float(time_scale), xy[0] + shift[0], xy[1] + shift[1]])


def convert_push(
    push: MitPush, renderer: MitRenderer, time_scale: float = 1.0
) -> tuple[PushRecord, dict]:
    """One MIT push → (`PushRecord` in the shifted frame with rendered RGB-D, MIT attributes).

    time_scale s: `push` was read at rate·s Hz; its times are multiplied by s and the speed
    divided by s (module doc, "Time rescaling"); 1 leaves the recording as it is.
    The attributes (stored on the push's shard group): mit_file (str), mit_shift (2,) m,
    mit_t0 Unix s, mit_force_offset (2,) N, mit_friction (NaN if invalid),
    mit_contact_span (first, last) contact sample indices ((-1, -1) without contact; contact
    during [t_first - 1/rate, t_last), see `_contact_span`), mit_meta (JSON of the file-name
    fields), mit_time_scale (s).
    """
    shift = push_shift(push)
    pose = push.object_pose.copy()
    pose[:, :2] += shift
    pusher = push.tip_pose + shift
    rgb, depth, s0, outline = renderer.render(pose, pusher)
    force = np.asarray(push.force, dtype=np.float64)
    pusher_fine = fine_pusher(push, shift, time_scale)
    record = PushRecord(
        push=push_action(push, shift, time_scale),
        time=np.asarray(push.times, dtype=np.float64) * float(time_scale),
        pose=pose,
        tactile=np.column_stack([force, push.contact.astype(np.float64)]),
        force_clean=None,
        pusher=pusher,
        rgb=rgb,
        depth=depth,
        s0=s0,
        outline_mask=outline,
        pusher_fine=pusher_fine,
    )
    mu = push_friction(push)
    attrs = {
        "mit_shift": shift,
        "mit_t0": push.t0,
        "mit_force_offset": np.asarray(push.force_offset, dtype=np.float64),
        "mit_friction": np.nan if mu is None else mu,
        "mit_contact_span": np.array(_contact_span(push), dtype=np.int64),
        "mit_meta": json.dumps(_meta_dict(push.meta)),
        TIME_SCALE_ATTR: float(time_scale),
    }
    return record, attrs


def _meta_dict(meta: MitPushMeta) -> dict:
    return {
        "surface": meta.surface,
        "shape": meta.shape,
        "acceleration": meta.acceleration,
        "speed_m_per_s": meta.speed,
        "side": meta.side,
        "position": meta.position,
        "angle_rad": meta.angle,
    }


# ============================================================================================
# Import
# ============================================================================================
def _filters(surface, shape, acceleration, speed) -> dict:
    return {
        "surface": surface,
        "shape": shape,
        "acceleration": acceleration,
        "speed_m_per_s": speed,
        "speed_mm_per_s": None if speed is None else speed * MM_PER_M,
    }


def _plan(files: list[tuple[Path, MitPushMeta]], objects_per_shard: int) -> list[list[dict]]:
    """Objects (one per (surface, shape), sorted by surface then catalogue order) in shards."""
    groups: dict[tuple[str, str], list[Path]] = {}
    for p, meta in files:
        groups.setdefault((meta.surface, meta.shape), []).append(p)
    keys = sorted(groups, key=lambda k: (k[0], MIT_SHAPES.index(k[1])))
    objects = [
        {"object_index": i, "surface": s, "shape": o, "files": groups[(s, o)]}
        for i, (s, o) in enumerate(keys)
    ]
    k = objects_per_shard
    return [objects[i : i + k] for i in range(0, len(objects), k)]


def _fingerprint(src: Path, plan: list[list[dict]], settings: dict, digests: dict) -> str:
    """Hash of the plan's relative file names and the bytes of each file (`digests`: {path:
    SHA-256}), the import version and the settings."""
    files = [
        [[[str(f.relative_to(src)), digests[f]] for f in o["files"]] for o in shard]
        for shard in plan
    ]
    blob = json.dumps({"version": IMPORT_VERSION, "files": files, **settings}, sort_keys=True)
    return hashlib.sha256(blob.encode()).hexdigest()[:16]


def _refusal(old: dict, out: Path, src: Path, settings: dict, digests: dict) -> DatasetError:
    """Why `out`, whose import.json is `old`, cannot be resumed: source files whose bytes
    changed since (named), or other files or settings."""
    recorded = {
        name: digest
        for sh in old.get("shards", [])
        for o in sh.get("objects", [])
        for name, digest in zip(o.get("files", []), o.get("sha256", [None] * len(o["files"])))
    }
    now = {str(p.relative_to(src)): d for p, d in digests.items()}
    plain = json.loads(json.dumps(settings))
    same = recorded.keys() == now.keys() and all(
        old.get(k) == plain.get(k) for k in {*plain, "as_speed_m_per_s"}
    )
    changed = sorted(n for n in now if recorded.get(n) != now[n]) if same else []
    if changed and all(recorded[n] is not None for n in changed):
        more = f" (and {len(changed) - 1} other source files)" if len(changed) > 1 else ""
        return DatasetError(
            src / changed[0],
            f"changed since it was imported into {out} (its bytes differ){more}, so {out} holds "
            "an import of other inputs; use another --out directory",
        )
    if changed:
        return DatasetError(
            out,
            f"holds an import whose source files' bytes were not recorded (an older pushtoknow; "
            f"see {IMPORT_FILE}), so whether they changed is unknown; use another --out directory",
        )
    return DatasetError(
        out,
        f"holds a dataset imported with other files or settings (see {IMPORT_FILE}); "
        "use another --out directory",
    )


def _write_shard_with_attrs(
    path: Path,
    episodes: list[ObjectEpisode],
    object_attrs: list[dict],
    push_attrs: list[list[dict]],
    *,
    fingerprint: str,
    shard_index: int,
    sim_config_json: str,
) -> None:
    """`write_shard` (atomic) with the MIT provenance attributes."""
    write_shard(
        path,
        episodes,
        fingerprint=fingerprint,
        shard_index=shard_index,
        sim_config_json=sim_config_json,
        attrs={
            "source": SOURCE_TAG,
            "shift_convention": SHIFT_CONVENTION,
            "tactile_convention": TACTILE_CONVENTION,
        },
        object_attrs=object_attrs,
        push_attrs=push_attrs,
    )


@dataclass(frozen=True)
class MitImportResult:
    """The result of `import_mit_dataset` (`pushtoknow import-mit`): the MIT Push files matching
    the filters; the pushes converted by this call (0 when every shard was already finished);
    the objects (one per (surface, shape)) in the selection; the shards written by this call
    and those skipped as already finished."""

    files: int
    pushes: int
    objects: int
    shards_written: int
    shards_skipped: int

    def to_json(self) -> dict:
        return asdict(self)


def import_mit_dataset(
    src: Path,
    out: Path,
    *,
    surface: str | None = None,
    shape: str | None = None,
    acceleration: float | None = None,
    speed: float | None = None,
    rate: float = 10.0,
    objects_per_shard: int = 4,
    progress: bool = True,
    as_speed: float | None = None,
) -> MitImportResult:
    """Convert (or resume converting) MIT Push files under `src` into shards in `out`.

    Filters as in `find_mit_push_files`: surface (e.g. "plywood"), shape (e.g. "rect1"),
    acceleration (the name's ``a``; 0 = constant speed) and **speed in m/s** (the file names and
    the CLI's ``--speed`` are in mm/s: pass ``speed_from_mm_per_s(v)``, i.e. v / 1000). The
    paper's subset is ``acceleration=0`` and one speed. rate: resampling rate (Hz) of the
    converted clock. as_speed (m/s, default None = off): present every push as if pushed at
    this speed by time rescaling (module doc, "Time rescaling"; quasi-static assumption), e.g.
    the training data's push speed.
    One object = one (surface, shape) with all its selected pushes; `objects_per_shard`
    objects per shard. Peak memory ≈ one shard's rendered frames (≈ 28.7 kB per 64 × 64 frame).
    Resuming: finished shards whose fingerprint (relative file names, filters, rate, layout,
    render config) matches are skipped; the source's absolute path is recorded, not compared.

    Returns a `MitImportResult` (files matching, pushes converted by this call, objects in the
    selection, shards written and skipped).
    Raises `DatasetError` when no file matches (naming `src` and the filters), when `out` holds
    a dataset made with other settings, or naming a corrupt source file.
    """
    src, out = Path(src), Path(out)
    if objects_per_shard < 1:
        raise ValueError(f"objects_per_shard must be >= 1, got {objects_per_shard}")
    if not (math.isfinite(rate) and rate > 0):
        raise ValueError(f"rate must be a positive number of Hz, got {rate!r}")
    if as_speed is not None and not (math.isfinite(as_speed) and as_speed > 0):
        raise ValueError(f"as_speed must be a positive speed in m/s, got {as_speed!r}")
    filters = _filters(surface, shape, acceleration, speed)
    files = find_mit_push_files(src, surface, shape, acceleration, speed)
    if not files:
        shown = ", ".join(f"{k}={v}" for k, v in filters.items() if v is not None) or "none"
        raise DatasetError(src, f"no MIT Push files match the filters ({shown})")
    plan = _plan(files, objects_per_shard)
    cfg = mit_sim_config(rate)
    sim_json = cfg.model_dump_json()
    settings = {
        "filters": filters,
        "rate_hz": rate,
        "objects_per_shard": objects_per_shard,
        "sim": json.loads(sim_json),
        "fallback_friction": FALLBACK_FRICTION,
    }
    if as_speed is not None:  # only then: imports without rescaling keep their fingerprint
        settings["as_speed_m_per_s"] = float(as_speed)
    digests = {p: file_sha256(p) for objs in plan for o in objs for p in o["files"]}
    fingerprint = _fingerprint(src, plan, settings, digests)
    with dataset_lock(out):
        _prepare_out(out, src, files, plan, settings, fingerprint, digests, as_speed)
        return _import_pending(out, src, files, plan, fingerprint, cfg, rate, as_speed, progress)


def _prepare_out(out, src, files, plan, settings, fingerprint, digests, as_speed) -> None:
    """Accept `out` (refused when its import.json has another fingerprint, `_refusal`), write
    import.json on first use, and drop the temp files of an interrupted run."""
    info_file = out / IMPORT_FILE
    if info_file.exists():
        old = json.loads(info_file.read_text())
        if old.get("fingerprint") != fingerprint:
            raise _refusal(old, out, src, settings, digests)
    else:
        info = {
            "fingerprint": fingerprint,
            "format": "pushtoknow MIT Push import",
            "import_version": IMPORT_VERSION,
            "source": {"directory": str(src.resolve()), "files": len(files)},
            **settings,
            "shift_convention": SHIFT_CONVENTION,
            "friction_convention": FRICTION_CONVENTION,
            "tactile_convention": TACTILE_CONVENTION,
            "force_clean": "none (real data have no noiseless force)",
            "object": f"MIT catalogue mass and I_z, CoM at the centroid, height {MIT_HEIGHT} m",
            "shards": [
                {
                    "shard": shard_path(out, i).name,
                    "objects": [
                        {
                            "object_index": o["object_index"],
                            "surface": o["surface"],
                            "shape": o["shape"],
                            "pushes": len(o["files"]),
                            "files": [str(p.relative_to(src)) for p in o["files"]],
                            "sha256": [digests[p] for p in o["files"]],
                        }
                        for o in objs
                    ],
                }
                for i, objs in enumerate(plan)
            ],
        }
        if as_speed is not None:
            info["time_scale_convention"] = TIME_SCALE_CONVENTION
        atomic_write(info_file, json.dumps(info, indent=1))
    for stale in [*out.glob("*.h5.tmp"), *out.glob(f"*.h5{_PART_SUFFIX}")]:
        stale.unlink()


def _import_pending(
    out, src, files, plan, fingerprint, cfg, rate, as_speed, progress
) -> MitImportResult:
    """Convert and write the shards of `plan` not yet finished in `out`."""
    sim_json = cfg.model_dump_json()
    todo = [i for i in range(len(plan)) if not shard_is_finished(shard_path(out, i), fingerprint)]
    skipped = len(plan) - len(todo)
    total = sum(len(o["files"]) for i in todo for o in plan[i])

    from pushtoknow.common.progress import progress_bar

    renderers: dict[str, MitRenderer] = {}
    converted = 0
    try:
        with progress_bar(progress) as bar:
            task = bar.add_task(f"importing MIT Push ({skipped} shards already done)", total=total)
            for i in todo:
                episodes, object_attrs, push_attrs = [], [], []
                for o in plan[i]:
                    ep, oa, pa = _convert_object(o, src, rate, cfg, renderers, bar, task, as_speed)
                    episodes.append(ep)
                    object_attrs.append(oa)
                    push_attrs.append(pa)
                    converted += len(ep.records)
                _write_shard_with_attrs(
                    shard_path(out, i),
                    episodes,
                    object_attrs,
                    push_attrs,
                    fingerprint=fingerprint,
                    shard_index=i,
                    sim_config_json=sim_json,
                )
    finally:
        for r in renderers.values():
            r.close()
    return MitImportResult(
        files=len(files),
        pushes=converted,
        objects=sum(len(objs) for objs in plan),
        shards_written=len(todo),
        shards_skipped=skipped,
    )


def _convert_object(
    o: dict,
    src: Path,
    rate: float,
    cfg: SimConfig,
    renderers: dict[str, MitRenderer],
    bar,
    task,
    as_speed: float | None = None,
) -> tuple[ObjectEpisode, dict, list[dict]]:
    """All pushes of one (surface, shape) object → episode, object attrs, per-push attrs."""
    scales = [_time_scale(p, as_speed) for p in o["files"]]
    pushes = [read_mit_push(p, rate * s) for p, s in zip(o["files"], scales)]
    estimates = [push_friction(p) for p in pushes]
    valid = [m for m in estimates if m is not None]
    mu = float(np.median(valid)) if valid else FALLBACK_FRICTION
    spec = mit_object_spec(o["shape"], mu, surface=o["surface"])
    if o["shape"] not in renderers:  # μ does not change the rendering: reuse across surfaces
        renderers[o["shape"]] = MitRenderer(spec, cfg)
    renderer = renderers[o["shape"]]
    records, attrs = [], []
    for path, push, s in zip(o["files"], pushes, scales):
        rec, pa = convert_push(push, renderer, s)
        pa["mit_file"] = str(path.relative_to(src))
        records.append(rec)
        attrs.append(pa)
        bar.advance(task, 1)
    source = f"median of {len(valid)} valid per-push estimates" if valid else "fallback"
    object_attrs = {
        "mit_surface": o["surface"],
        "mit_shape": o["shape"],
        "friction_source": source,
    }
    return ObjectEpisode(spec, o["object_index"], records), object_attrs, attrs


def _time_scale(path: Path, as_speed: float | None) -> float:
    """s = v_file / as_speed (1 when as_speed is None); `DatasetError` for a file at speed 0."""
    if as_speed is None:
        return 1.0
    v = parse_mit_filename(path).speed
    if not v > 0:
        raise DatasetError(path, f"speed {v} m/s: cannot rescale a push to {as_speed} m/s")
    return v / as_speed
