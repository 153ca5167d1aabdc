"""The real-data benchmark (`pushtoknow evaluate-real`, docs/DESIGN.md §11): every estimator on
every object of a folder of real pushes, against each object's known parameters.

**Objects.** The folder is searched recursively, whatever its layout:

- MIT Push files (``motion_surface=…`` ``.json``/``.h5``, `datasets.mit_push`), grouped by
  (surface, shape) as `import-mit` groups them; key ``surface:shape``. Each file is read at
  `PHYSICS_RATE_HZ` as recorded and checked (`mit_push.check_mit_push`): a frozen stream,
  clocks that barely overlap or a flipped force sign stop the benchmark with a one-line
  `DatasetError` naming the file; a push without contact (the probe missed) is skipped and
  listed with its reason. Truth: the MIT catalogue's m and I_z, the CoM at the centroid, and
  μ measured on the object's pure translations (`evaluation.real_object.friction_reference`, every
  accepted push), so μ·m's truth is that μ times the catalogue mass.
- The project's recordings (`datasets.recording` files) and datasets (``shard-*.h5``, one
  object each), read by `identification.recordings.load_recorded_objects`; key
  ``surface:name`` (surface: the recording's or an import's, else ``unknown``). Truth: what
  they store.

**Methods** (rows of `RealBenchmark.objects[key]["methods"]`):

- ``physics``: the physics filter (`inference.physics_filter.PhysicsFilterEstimator`) through
  `inference.session.infer_recorded`, each push from its recorded pose, with the object's known
  outline (MIT: the catalogue polygon; a recording or dataset: the stored one) and its tracked
  (motion-capture) poses, no images: the pushes at `PHYSICS_RATE_HZ` on their recorded clock.
- ``vt-addf``: the learned filter over RGB-D rendered at the recorded poses
  (`datasets.mit_import.convert_push`, as ``estimate-real`` does), each push time-rescaled to
  the model's training speed (exact for quasi-static pushing only); for a dataset, its own
  images. Skipped, with the reason, where there are none (recordings: no camera model).
- ``prior``: the first estimator's estimate before any push.
- ``forest`` (with `forest_data`): `baselines.random_forest` fitted on that simulated dataset's
  pushes and applied to the rendered pushes' features (ground-truth poses), as in
  ``estimate-real``; interval mean ± 1.645 std.

Per parameter: mean, std, interval90 (SI, docs/DESIGN.md §2), z (the truth's standardised error
under the reported distribution: log-normal m, μ, I_z, the CoM truncated to the footprint;
Gaussian for the forest) and covered (the truth inside interval90); None where the truth is
unknown. μ·m: mean, std (log-normal for the filters) and its error relative to the truth.
**Surfaces:** per surface and method, μ's mean and std (ddof 0) over the objects on it, and
their spread (max − min) / mean: one surface has one μ, a check that needs no truth.
"""

from __future__ import annotations

import dataclasses
import functools
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from scipy.special import ndtri

from pushtoknow.common.errors import DatasetError, PushToKnowError
from pushtoknow.common.estimators import ESTIMATOR_NAMES
from pushtoknow.common.files import find_files
from pushtoknow.common.params import PARAM_NAMES, product_moments
from pushtoknow.datasets.mit_push import (
    DEFAULT_RATE_HZ,
    MIT_SHAPES,
    PUSHER_RADIUS,
    MitPush,
    MitPushMeta,
    check_mit_push,
    dataset_to_centroid_pose,
    find_mit_push_files,
    mit_object,
    read_mit_push,
)
from pushtoknow.identification.force_balance import (
    ForceBalanceConfig,
    MassReading,
    RawPush,
    inertial_mass,
    probe_mass,
)
from pushtoknow.identification.prior import EVERYDAY_PRIOR, PriorRanges
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig

__all__ = [
    "ESTIMATORS",
    "PHYSICS_RATE_HZ",
    "RealBenchmark",
    "RealObject",
    "estimate_rows",
    "evaluate_real",
    "find_real_objects",
    "gaussian_rows",
]

ESTIMATORS: tuple[str, ...] = ("physics", "vt-addf")
PHYSICS_RATE_HZ = DEFAULT_RATE_HZ  # Hz: the testbed's clock, the physics filter's replays
Z90 = float(ndtri(0.95))  # two-sided 90% quantile of the standard normal
UNKNOWN_SURFACE = "unknown"
# display: (label, SI → shown factor)
DISPLAY = {
    "mass": ("m (kg)", 1.0),
    "friction": ("μ", 1.0),
    "com_x": ("c_x (mm)", 1e3),
    "com_y": ("c_y (mm)", 1e3),
    "inertia": ("I_z (g·m²)", 1e3),
}


# ============================================================================================
# Rows
# ============================================================================================
def _num(v: float | None) -> float | None:
    return None if v is None or not math.isfinite(float(v)) else float(v)


def _row(mean: float, std: float, lo: float, hi: float, z: float, truth: float) -> dict:
    known = math.isfinite(truth)
    return {
        "mean": float(mean),
        "std": float(std),
        "interval90": [float(lo), float(hi)],
        "z": _num(z) if known else None,
        "covered": bool(lo <= truth <= hi) if known else None,
    }


def gaussian_rows(mean: np.ndarray, std: np.ndarray, truth: np.ndarray) -> dict:
    """{param: row} of a Gaussian estimate in SI (the forest's): interval90 = mean ± 1.645·std,
    z = (truth − mean) / std; truth (5,) SI, NaN where unknown."""
    mean, std, truth = (np.asarray(a, dtype=np.float64) for a in (mean, std, truth))
    z = (truth - mean) / np.maximum(std, 1e-300)
    return {
        n: _row(mean[i], std[i], mean[i] - Z90 * std[i], mean[i] + Z90 * std[i], z[i], truth[i])
        for i, n in enumerate(PARAM_NAMES)
    }


def estimate_rows(estimate, truth: np.ndarray) -> dict:
    """{param: row} of a `PushEstimate`: its SI mean, std and 90% interval, and z from
    `PushEstimate.zscore` (normalised space; the truncated CoM's CDF); truth (5,) SI, NaN where
    unknown."""
    truth = np.asarray(truth, dtype=np.float64)
    known = np.isfinite(truth)
    filled = np.where(known, truth, estimate.mean)  # a placeholder: its z is dropped
    z = estimate.zscore(filled)
    lo, hi = estimate.interval()
    return {
        n: _row(estimate.mean[i], estimate.std[i], lo[i], hi[i], z[i], truth[i])
        for i, n in enumerate(PARAM_NAMES)
    }


def _fmt(v: float) -> str:
    """3 significant digits; values below 1e-9 (a centred CoM's rounding) shown as 0."""
    return "0" if abs(v) < 1e-9 else f"{v:.3g}"


def _mu_m_row(mean: float, std: float, truth: float | None) -> dict:
    rel = None if truth is None else mean / truth - 1.0
    return {"mean": float(mean), "std": float(std), "rel_error": _num(rel)}


# ============================================================================================
# Objects
# ============================================================================================
@dataclass(frozen=True, eq=False)
class RealObject:
    """One object's pushes, ready for every estimator.

    key: "surface:shape" (or "surface:name"); source: "mit-push", "recording" or "dataset";
    records: the pushes for the physics filter (tracked poses, no images) and sim_config their
    settings (clock, pad radius); shape / height: the known outline (polygon spec, object frame,
    m) or None; truth (5,) SI, NaN where unknown; image_records: the pushes with RGB-D for the
    learned filter and the forest (None: none, `image_note` says why); skipped: pushes left
    out, each {"file", "reason"}; friction_reference: `friction_reference`'s dict (MIT only);
    prior: the ranges of m, μ and I_z the physics filter starts from; raw_pushes: the used
    pushes' raw streams (MIT only) for `identification.force_balance`, and probe_pushes every
    checked push's, those without contact included (their free probe motion weighs the probe).
    """

    key: str
    surface: str | None
    name: str
    source: str
    files: tuple[str, ...]
    records: tuple[PushRecord, ...]
    sim_config: SimConfig
    shape: dict | None
    height: float
    truth: np.ndarray
    truth_source: dict
    image_records: tuple[PushRecord, ...] | None = None
    image_camera: object = None
    image_note: str = ""
    skipped: tuple[dict, ...] = ()
    friction_reference: dict | None = None
    notes: tuple[str, ...] = ()
    prior: PriorRanges = EVERYDAY_PRIOR
    raw_pushes: tuple[RawPush, ...] = ()
    probe_pushes: tuple[RawPush, ...] = ()


def _raw_push(push: MitPush) -> RawPush:
    """A checked MIT push's raw streams for `force_balance`: poses of the centroid frame, the
    force on the object (the reading tared and negated, `mit_push` module doc)."""
    raw, shape = push.raw, push.meta.shape
    pose = raw.object_pose.copy()
    pose[:, 1:] = dataset_to_centroid_pose(pose[:, 1:], shape)
    force = raw.ft_wrench[:, :3].copy()
    force[:, 1:] = -(force[:, 1:] - push.force_offset)
    return RawPush(
        push.path.name, raw.tip_pose[:, :3], pose, force, push.obj.polygon, PUSHER_RADIUS
    )


def _group_mit(root: Path) -> dict[tuple[str, str], list[tuple[Path, MitPushMeta]]]:
    groups: dict[tuple[str, str], list[tuple[Path, MitPushMeta]]] = {}
    for p, meta in find_mit_push_files(root):
        groups.setdefault((meta.surface, meta.shape), []).append((p, meta))
    return dict(sorted(groups.items(), key=lambda kv: (kv[0][0], MIT_SHAPES.index(kv[0][1]))))


def _mit_object(
    root: Path,
    surface: str,
    shape: str,
    files: list[tuple[Path, MitPushMeta]],
    max_pushes: int | None,
    train_speed: float | None,
) -> RealObject | None:
    """One MIT object (module doc); None when every push was skipped. train_speed (m/s): render
    the pushes for the learned filter, time-rescaled to it; None: no images."""
    from pushtoknow.datasets.mit_import import (
        MIT_HEIGHT,
        MitRenderer,
        convert_push,
        mit_object_spec,
        mit_sim_config,
    )
    from pushtoknow.evaluation.real_object import friction_reference

    sim = mit_sim_config(PHYSICS_RATE_HZ)
    spec = mit_object_spec(shape, 0.5, surface=surface)  # μ unused: shape and rendering only
    renderer = MitRenderer(spec, sim)
    accepted, skipped, records, raw = [], [], [], []
    try:
        for p, meta in files:
            push = read_mit_push(p, PHYSICS_RATE_HZ)
            check_mit_push(push, contact=False)  # DatasetError: frozen, clocks, sign
            raw.append(_raw_push(push))
            if not push.contact.any():
                reason = f"no contact: ‖F‖ never exceeds {push.contact_threshold:g} N"
                skipped.append({"file": str(p.relative_to(root)), "reason": reason})
                continue
            rec, _ = convert_push(push, renderer)
            records.append(dataclasses.replace(rec, rgb=None, depth=None))
            accepted.append((p, meta, raw[-1]))
        if not records:
            return None
        obj = mit_object(shape)
        fric = friction_reference(records, obj.mass)  # every accepted push
        for row, (p, _, _) in zip(fric["pushes"], accepted, strict=True):
            row["file"] = str(p.relative_to(root))
        used = accepted[:max_pushes] if max_pushes else accepted
        image_records = None
        if train_speed is not None:
            image_records = []
            for p, meta, _ in used:
                s = meta.speed / train_speed
                rec, _ = convert_push(read_mit_push(p, PHYSICS_RATE_HZ * s), renderer, s)
                image_records.append(rec)
    finally:
        renderer.close()
    mu = fric["value"]
    truth = np.array([obj.mass, np.nan if mu is None else mu, 0.0, 0.0, obj.inertia])
    uniform = "footprint centroid (MIT Push objects are uniform steel plates)"
    return RealObject(
        key=f"{surface}:{shape}",
        surface=surface,
        name=shape,
        source="mit-push",
        files=tuple(str(p.relative_to(root)) for p, _, _ in used),
        records=tuple(records[: len(used)]),
        sim_config=sim,
        shape=spec.shape,
        height=MIT_HEIGHT,
        truth=truth,
        truth_source={
            "mass": f"MIT Push catalogue ({shape})",
            "friction": f"measured: {fric['rule']}" if mu is not None else "none measured",
            "com_x": uniform,
            "com_y": uniform,
            "inertia": f"MIT Push catalogue ({shape}, uniform density)",
        },
        image_records=None if image_records is None else tuple(image_records),
        image_camera=sim.camera.model(),
        image_note="" if train_speed is not None else "not requested",
        skipped=tuple(skipped),
        friction_reference=fric,
        raw_pushes=tuple(r for _, _, r in used),
        probe_pushes=tuple(raw),
        notes=()
        if train_speed is None
        else (
            f"vt-addf and forest: pushes rendered and time-rescaled to {train_speed} m/s "
            "(exact for quasi-static pushing only)",
        ),
    )


def _surface_of_shard(shard: Path) -> dict[int, str]:
    """object_index → surface stored by an import (``mit_surface``), where there is one."""
    from pushtoknow.datasets.shards import open_shard

    out = {}
    with open_shard(shard) as f:
        for key, g in f["objects"].items():
            if "mit_surface" in g.attrs:
                out[int(g.attrs.get("object_index", key))] = str(g.attrs["mit_surface"])
    return out


def _recorded_objects(root: Path, max_pushes: int | None, images: bool) -> list[RealObject]:
    """The recordings and datasets under `root` (module doc)."""
    import h5py

    from pushtoknow.datasets.mit_push import FILE_PREFIX
    from pushtoknow.datasets.recording import is_recording
    from pushtoknow.datasets.shards import SHARD_GLOB, read_shard
    from pushtoknow.identification.recordings import load_recorded_objects

    out: list[RealObject] = []
    camera = None
    shards = find_files(root, SHARD_GLOB)
    recordings = sorted(
        p
        for p in find_files(root, "*.h5")
        if not p.name.startswith(FILE_PREFIX) and p not in shards and is_recording(p)
    )
    for path in recordings:
        (obj,) = load_recorded_objects(path)
        with h5py.File(path, "r") as f:
            surface = f.attrs.get("surface", "")
        surface = surface.decode() if isinstance(surface, bytes) else str(surface)
        out.append(_generic(root, path, obj, surface or None, max_pushes, None, None, "recording"))
    for shard in shards:
        surfaces = _surface_of_shard(shard)
        episodes = {}
        if images:
            from pushtoknow.datasets.shards import open_shard
            from pushtoknow.testbed.sim_config import stored_sim_config

            with open_shard(shard) as f:
                camera = stored_sim_config(f.attrs.get("sim_config")).camera.model()
            episodes = {ep.object_index: ep for ep in read_shard(shard)}
        for obj in load_recorded_objects(shard):
            ep = episodes.get(obj.index)
            recs = None if ep is None else tuple(ep.records)
            surface = surfaces.get(obj.index)
            out.append(_generic(root, shard, obj, surface, max_pushes, recs, camera))
    return out


def _generic(
    root: Path,
    path: Path,
    obj,
    surface: str | None,
    max_pushes: int | None,
    image_records: tuple[PushRecord, ...] | None,
    camera,
    source: str = "dataset",
) -> RealObject:
    """A `RecordedObject` as a `RealObject`; image_records: its pushes with RGB-D, if any."""
    records = obj.records[:max_pushes] if max_pushes else obj.records
    truth = np.full(len(PARAM_NAMES), np.nan) if obj.truth is None else np.asarray(obj.truth)
    if image_records is not None:
        image_records = image_records[: len(records)]
        if any(r.rgb is None for r in image_records):
            image_records = None
    note = "" if image_records is not None else f"no RGB-D frames with a camera model ({source})"
    return RealObject(
        key=f"{surface or UNKNOWN_SURFACE}:{obj.name}",
        surface=surface,
        name=obj.name,
        source=source,
        files=(str(path.relative_to(root)),),
        records=tuple(records),
        sim_config=obj.sim_config,
        shape=obj.shape,
        height=obj.height,
        truth=truth.astype(np.float64),
        truth_source={n: f"stored with the pushes ({source})" for n in PARAM_NAMES},
        image_records=image_records,
        image_camera=camera,
        image_note=note,
        notes=tuple(obj.notes),
        prior=obj.prior,
    )


def _surface_friction(objects: list[RealObject]) -> list[RealObject]:
    """Objects without a μ measurement of their own (no pure translation) take their surface's:
    the mean of the other objects' measured μ on it (one surface, one μ), said in
    truth_source."""
    measured: dict[str, dict[str, float]] = {}
    for o in objects:
        ref = o.friction_reference
        if o.surface is not None and ref is not None and ref["value"] is not None:
            measured.setdefault(o.surface, {})[o.name] = float(ref["value"])
    out = []
    for o in objects:
        others = measured.get(o.surface or "", {})
        if o.source == "mit-push" and np.isnan(o.truth[1]) and others:
            truth = o.truth.copy()
            truth[1] = float(np.mean(list(others.values())))
            source = dict(o.truth_source)
            source["friction"] = (
                f"surface {o.surface}'s μ, measured on {', '.join(others)} ({o.name} has no "
                "pure translation)"
            )
            o = dataclasses.replace(o, truth=truth, truth_source=source)
        out.append(o)
    return out


def find_real_objects(
    data_dir: Path, max_pushes: int | None = None, train_speed: float | None = None
) -> tuple[list[RealObject], list[dict]]:
    """Every object under `data_dir` (module doc) and the objects whose every push was skipped
    ({"object", "skipped"}). train_speed (m/s): render MIT pushes at it for the learned filter.
    Raises `DatasetError` naming the folder when it holds no object, or naming a bad file."""
    root = Path(data_dir)
    if not root.is_dir():
        raise DatasetError(root, "no such folder (expected MIT Push files, recordings or datasets)")
    objects, empty = [], []
    for (surface, shape), files in _group_mit(root).items():
        obj = _mit_object(root, surface, shape, files, max_pushes, train_speed)
        if obj is None:
            empty.append({"object": f"{surface}:{shape}", "skipped": len(files)})
        else:
            objects.append(obj)
    objects += _recorded_objects(root, max_pushes, train_speed is not None)
    if not objects:
        raise DatasetError(
            root,
            "no objects found: no MIT Push files (motion_surface=….json/.h5), recordings or "
            "datasets (shard-*.h5) with a push in contact, searched recursively",
        )
    objects = _surface_friction(objects)
    seen: dict[str, int] = {}
    for i, o in enumerate(objects):  # the same object twice (e.g. raw files and an import)
        if o.key in seen:
            objects[i] = dataclasses.replace(o, key=f"{o.key}@{o.files[0]}")
        seen[o.key] = i
    return objects, empty


# ============================================================================================
# Estimators
# ============================================================================================
def _physics(model, obj: RealObject, seed: int, prior: PriorRanges | None = None):
    """(prior, final estimate, per-push diagnostics) of the physics filter on `obj`, starting
    from `prior` (None: the object's, `RealObject.prior`)."""
    from pushtoknow.identification.recursive import PhysicsFilterConfig
    from pushtoknow.identification.replay import ReplayScene
    from pushtoknow.inference.estimator import InferenceConfig
    from pushtoknow.inference.physics_filter import PhysicsFilterEstimator
    from pushtoknow.inference.session import infer_recorded

    cfg = InferenceConfig(estimator="physics", pushes=len(obj.records))
    sim = obj.sim_config.model_copy(update={"render": False})
    scene = None if obj.shape is None else ReplayScene(obj.shape, obj.height, sim)
    ranges = prior or obj.prior
    filter_config = PhysicsFilterConfig(prior=ranges)
    est = PhysicsFilterEstimator(model, cfg, seed, obj.sim_config, filter_config, scene=scene)
    try:
        res = infer_recorded(
            model, list(obj.records), cfg, seed, None, obj.key, estimator=est,
            sim_config=obj.sim_config,
        )  # fmt: skip
    finally:
        est.close()
    updates = [
        {
            "reduced_chi2": float(u.chi2),
            "poor_fit": bool(u.poor_fit),
            "identified": int(u.identified),
            "replays": int(u.replays),
            "inflation": float(u.inflation),
            "noise_scale": [float(v) for v in u.noise_scale],
        }
        for u in est.updates
    ]
    return (
        res.prior,
        res.estimates[-1],
        {"prior": ranges.model_dump(mode="json"), "updates": updates},
    )


def _learned(model, obj: RealObject, seed: int):
    """(prior, final estimate, extras) of the learned filter on `obj`'s rendered pushes."""
    from pushtoknow.evaluation.real_object import real_inference_config
    from pushtoknow.inference.learned_filter import LearnedFilterEstimator, outside_training
    from pushtoknow.inference.session import infer_recorded
    from pushtoknow.testbed.shapes import footprint_from_shape

    if obj.image_records is None:
        raise DatasetError(obj.key, f"vt-addf needs RGB-D: {obj.image_note}")
    if obj.image_camera != model.camera:
        raise DatasetError(obj.key, "images of another camera than the model was trained with")
    recs = list(obj.image_records)
    cfg = real_inference_config(len(recs))
    est = LearnedFilterEstimator(model, cfg, seed)
    res = infer_recorded(model, recs, cfg, seed, None, obj.key, estimator=est)
    footprint = None if obj.shape is None else footprint_from_shape(obj.shape)
    reasons = outside_training(obj.records, footprint, obj.sim_config, model.info)
    return res.prior, res.estimates[-1], {"outside_training": list(reasons)} if reasons else {}


def _forest_model(forest_data: Path, seed: int, trees: int):
    """The forest fitted on a complete simulated dataset (`DatasetError` naming it otherwise)."""
    from pushtoknow.baselines.random_forest import ForestBaseline, ForestConfig
    from pushtoknow.datasets.shards import dataset_info
    from pushtoknow.evaluation.real_object import _training_features

    forest_data = Path(forest_data)
    if not forest_data.is_dir():
        raise DatasetError(forest_data, "--forest-data: no such dataset folder")
    info = dataset_info(forest_data)
    if info.complete is False:
        raise DatasetError(
            forest_data,
            f"forest data incomplete: {info.objects} of {info.expected_objects} objects "
            "(resume it with `pushtoknow simulate`)",
        )
    X, Y, _ = _training_features(forest_data)
    return ForestBaseline(ForestConfig(n_estimators=trees, seed=seed)).fit(X, Y), len(X)


def _mass_row(reading: MassReading, truth: float | None) -> dict:
    """A force-balance reading as a row: the reading's fields, with interval90, z, covered
    and rel_error against the truth (None where either is unknown)."""
    row = reading.to_json()
    m, sd = reading.mass, reading.std
    known = m is not None and sd is not None and truth is not None
    row["interval90"] = None if m is None or sd is None else [m - Z90 * sd, m + Z90 * sd]
    row["z"] = (truth - m) / sd if known else None  # type: ignore[operator]
    row["covered"] = abs(row["z"]) <= Z90 if known else None
    row["rel_error"] = (m - truth) / truth if known else None  # type: ignore[operator]
    return row


def _force_balance(obj: RealObject, probe, config: ForceBalanceConfig) -> dict:
    """m read off force and acceleration (`identification.force_balance`): the object's
    pushes together, then each alone at the object's band (where it has one)."""
    truth = _num(obj.truth[0])
    whole = inertial_mass(obj.raw_pushes, probe, config)
    band = whole.band_hz if whole.identified else None
    pushes = []
    for f, r in zip(obj.files, obj.raw_pushes, strict=True):
        if band is None:
            row = {"file": f, "identified": False, "reason": "the object's m is not identified"}
        else:
            row = {"file": f, **_mass_row(inertial_mass([r], probe, config, band), truth)}
        pushes.append(row)
    return {"object": _mass_row(whole, truth), "pushes": pushes}


# ============================================================================================
# The benchmark
# ============================================================================================
@dataclass(frozen=True)
class RealBenchmark:
    """The result of `evaluate_real`. objects: {key: {"source", "surface", "files",
    "skipped", "truth", "truth_source", "methods": {name: {param: row}}, "mu_m": {"truth",
    "methods": {name: {mean, std, rel_error}}}, "skipped_methods": {name: reason}, "seconds":
    {name: s}, "physics": diagnostics, "vt-addf": {"outside_training": [reason]} where the
    object lies outside what it was trained on, "force_balance": {"object": row, "pushes":
    [row]} where the raw streams are known (m from force and acceleration, `_mass_row`),
    "friction_reference", "notes"}}; surfaces: {surface: {"objects": [...], "friction":
    {method: {mean, std, spread, values}}}}; probe_mass: `force_balance.ProbeMass` over every
    MIT push in the folder (one rig), None without MIT pushes; all SI."""

    data_dir: str
    seed: int
    estimators: tuple[str, ...]
    forest_data: str | None
    max_pushes: int | None
    objects: dict = field(default_factory=dict)
    surfaces: dict = field(default_factory=dict)
    empty_objects: tuple = ()
    notes: tuple[str, ...] = ()
    seconds: float = 0.0
    probe_mass: dict | None = None

    def to_json(self) -> dict:
        return {
            "data_dir": self.data_dir,
            "seed": self.seed,
            "estimators": list(self.estimators),
            "forest_data": self.forest_data,
            "max_pushes": self.max_pushes,
            "params": list(PARAM_NAMES),
            "objects": self.objects,
            "surfaces": self.surfaces,
            "probe_mass": self.probe_mass,
            "empty_objects": list(self.empty_objects),
            "notes": list(self.notes),
            "seconds": self.seconds,
        }

    def methods(self) -> list[str]:
        """Method names in table order."""
        names = {m for o in self.objects.values() for m in o["methods"]}
        order = [*self.estimators, "forest", "prior"]
        return [m for m in order if m in names]

    def table_rows(self) -> tuple[list[str], list[list[str]]]:
        """(header, rows) of the per-object table: estimate ± std (|z|) per method, then μ·m
        (relative error)."""
        methods = self.methods()
        header = ["object", "parameter", "truth", *methods]
        rows = []
        for key, o in self.objects.items():
            for n in PARAM_NAMES:
                label, k = DISPLAY[n]
                t = o["truth"][n]
                cells = []
                for m in methods:
                    r = o["methods"].get(m, {}).get(n)
                    if r is None:
                        cells.append("–")
                        continue
                    z = "" if r["z"] is None else f" ({abs(r['z']):.1f})"
                    miss = "" if r["covered"] in (None, True) else "*"
                    cells.append(f"{_fmt(r['mean'] * k)} ± {r['std'] * k:.2g}{z}{miss}")
                rows.append([key, label, "–" if t is None else f"{t * k:.4g}", *cells])
            mm = o["mu_m"]
            cells = []
            for m in methods:
                r = mm["methods"].get(m)
                if r is None:
                    cells.append("–")
                    continue
                rel = "" if r["rel_error"] is None else f" ({100 * r['rel_error']:+.0f}%)"
                cells.append(f"{r['mean']:.3f} ± {r['std']:.2g}{rel}")
            truth = "–" if mm["truth"] is None else f"{mm['truth']:.3f}"
            rows.append([key, "μ·m (kg)", truth, *cells])
        return header, rows

    def surface_rows(self) -> tuple[list[str], list[list[str]]]:
        """(header, rows): μ per surface and method over its objects."""
        header = ["surface", "method", "μ mean ± std over objects", "spread", "objects"]
        rows = []
        for s, d in self.surfaces.items():
            for m, f in d["friction"].items():
                spread = "–" if f["spread"] is None else f"{100 * f['spread']:.0f}%"
                vals = ", ".join(f"{k.split(':', 1)[1]} {v:.3f}" for k, v in f["values"].items())
                rows.append([s, m, f"{f['mean']:.3f} ± {f['std']:.3f}", spread, vals])
        return header, rows

    def mass_rows(self) -> tuple[list[str], list[list[str]]]:
        """(header, rows): m read off force and acceleration, per object (rows empty without
        raw streams)."""
        header = ["object", "m (kg) from force and acceleration", "truth", "band (Hz)", "each push"]
        rows = []
        for key, o in self.objects.items():
            fb = o.get("force_balance")
            if fb is None:
                continue
            r, truth = fb["object"], o["truth"]["mass"]
            if r["identified"]:
                z = "" if r["z"] is None else f" ({abs(r['z']):.1f})"
                miss = "" if r["covered"] in (None, True) else "*"
                rel = "" if r["rel_error"] is None else f", {100 * r['rel_error']:+.0f}%"
                cell = f"{r['mass']:.3f} ± {r['std']:.2g}{z}{miss}{rel}"
                band = f"{min(r['band_hz']):.1f}–{max(r['band_hz']):.1f}"
            else:
                cell, band = f"not identified: {r['reason']}", "–"
            each = [p for p in fb["pushes"] if p["identified"]]
            per = ", ".join(f"{p['mass']:.2f}" for p in each)
            pushes = f"{len(each)} of {len(fb['pushes'])} read at the band" + (
                f": {per}" if per else ""
            )
            rows.append([key, cell, "–" if truth is None else f"{truth:.4g}", band, pushes])
        return header, rows

    def probe_text(self) -> str:
        """The probe's own mass as weighed (`force_balance.probe_mass`), in words."""
        pm = self.probe_mass
        if pm is None or pm["mass"] is None:
            return "unknown (no free probe motion)"
        return (
            f"{pm['mass']:.3f} ± {pm['std']:.2g} kg from {pm['samples']} free samples of "
            f"{len(pm['pushes'])} pushes"
        )

    def table(self) -> str:
        """The report as markdown: the per-object table, the per-surface μ table and the mass
        read off force and acceleration."""
        out = []
        mass = self.mass_rows()
        tables = [self.table_rows(), self.surface_rows()]
        if mass[1]:
            tables.append(mass)
        for header, rows in tables:
            out.append("| " + " | ".join(header) + " |")
            out.append("|" + "---|" * len(header))
            out += ["| " + " | ".join(r) + " |" for r in rows]
            out.append("")
        out.append(
            "Cells: estimate ± std (|z|); * the truth lies outside the 90% interval. μ truth: "
            "measured on the pure translations; μ·m: relative error against measured μ × mass."
        )
        if self.probe_mass is not None and mass[1]:
            out.append(
                "m from force and acceleration (`identification.force_balance`): Re H of force "
                "over acceleration in the coherent band, less the probe's mass, "
                f"{self.probe_text()}; not fused into any estimator."
            )
        return "\n".join(out) + "\n"

    def results_section(self, command: str) -> str:
        """A RESULTS.md section of this benchmark: the command, what ran, the tables, notes,
        per-object physics fit quality and the time."""
        lines = [
            "## Real objects (`evaluate-real`)",
            "",
            "Generated by:",
            "",
            f"    {command}",
            "",
            f"{len(self.objects)} objects, seed {self.seed}, estimators "
            f"{', '.join(self.estimators)}; {self.seconds / 60:.1f} min on this machine.",
            "",
            self.table(),
        ]
        fits = []
        for key, o in self.objects.items():
            ups = (o.get("physics") or {}).get("updates") or []
            if ups:
                chi2 = [u["reduced_chi2"] for u in ups]
                poor = sum(u["poor_fit"] for u in ups)
                fits.append(
                    f"- {key}: physics filter, {len(ups)} updates, reduced χ² "
                    f"{min(chi2):.1f}–{max(chi2):.1f}, {poor} poor fits (m at fixed μ·m and "
                    "I_z then keep the prior)"
                )
        for key, o in self.objects.items():
            ref, mu = o.get("friction_reference") or {}, o["truth"]["friction"]
            if ref.get("lower_bound") is not None and mu is not None:
                i = ref["lower_bound_push"]
                push = Path(ref["pushes"][i].get("file", f"push {i}")).name
                fits.append(
                    f"- {key}: its pushes' mean contact force / (m g) reaches "
                    f"{ref['lower_bound']:.3f} ({push}), a lower bound of μ (a quasi-static "
                    f"push's force is at most μ m g), against the μ taken as truth, {mu:.3f}"
                    + (": one μ does not describe these pushes" * (ref["lower_bound"] > 1.05 * mu))
                )
        for key, o in self.objects.items():
            for reason in (o.get("vt-addf") or {}).get("outside_training", []):
                fits.append(f"- {key}: outside what vt-addf was trained on: {reason}")
        if fits:
            lines += ["", *fits]
        if self.notes:
            lines += ["", *(f"- {n}" for n in self.notes)]
        return "\n".join(lines) + "\n"


def _surfaces(objects: dict) -> dict:
    by: dict[str, list[str]] = {}
    for key, o in objects.items():
        if o["surface"] is not None:
            by.setdefault(o["surface"], []).append(key)
    out = {}
    for s, keys in sorted(by.items()):
        per: dict[str, dict[str, float]] = {}
        for k in keys:
            o = objects[k]
            ref = o["friction_reference"]
            if ref is not None and ref["value"] is not None:
                per.setdefault("measured", {})[k] = ref["value"]
            for m, rows in o["methods"].items():
                per.setdefault(m, {})[k] = rows["friction"]["mean"]
        friction = {}
        for m, values in per.items():
            v = np.array(list(values.values()))
            mean = float(v.mean())
            friction[m] = {
                "mean": mean,
                "std": float(v.std()),
                "spread": float(np.ptp(v) / mean) if len(v) > 1 else None,
                "values": values,
            }
        out[s] = {"objects": keys, "friction": friction}
    return out


def evaluate_real(
    data_dir: Path,
    forest_data: Path | None = None,
    seed: int = 0,
    estimators: Sequence[str] = ESTIMATORS,
    max_pushes: int | None = None,
    *,
    model: str | Path = "pretrained",
    forest_trees: int = 200,
    progress=None,
    prior: PriorRanges | None = None,
) -> RealBenchmark:
    """Every estimator on every object under `data_dir` (module doc). model: the perception /
    learned-filter checkpoint ("pretrained" or a run directory); max_pushes: the first K
    accepted pushes of each object; progress(text): told as each method starts; prior: the
    ranges the physics filter's prior spreads m, μ and I_z over (None: each object's,
    everyday objects' for real ones).
    Raises `DatasetError` (no objects, a bad file, incomplete forest data) or
    `CheckpointError`."""
    from pushtoknow.baselines.random_forest import features_from_records
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path

    t_start = time.perf_counter()
    estimators = tuple(estimators)
    bad = [e for e in estimators if e not in ESTIMATOR_NAMES]
    if bad or len(set(estimators)) != len(estimators):
        raise ValueError(f"estimators: distinct names among {ESTIMATOR_NAMES}, not {estimators}")
    if max_pushes is not None and max_pushes < 1:
        raise ValueError(f"max_pushes: a positive number, not {max_pushes}")
    forest = None
    if forest_data is not None:  # checked before any work
        forest, forest_pushes = _forest_model(Path(forest_data), seed, forest_trees)
    trained = load_checkpoint(resolve_model_path(str(model)))
    images = "vt-addf" in estimators or forest is not None
    train_speed = trained.sim_config.push.speed if images else None
    found, empty = find_real_objects(Path(data_dir), max_pushes, train_speed)
    say = progress or (lambda text: None)
    runners = {"physics": functools.partial(_physics, prior=prior), "vt-addf": _learned}
    balance = ForceBalanceConfig()
    probe_pushes = [r for o in found for r in o.probe_pushes]
    probe = probe_mass(probe_pushes, balance) if probe_pushes else None
    objects = {}
    for obj in found:
        methods, mu_m, skipped_methods, seconds, extra = {}, {}, {}, {}, {}
        t = obj.truth
        mu_m_truth = _num(t[0] * t[1])
        for name in estimators:
            say(f"{obj.key}: {name} ({len(obj.records)} pushes)")
            t0 = time.perf_counter()
            try:
                prior, final, more = runners[name](trained, obj, seed)
            except PushToKnowError as e:
                skipped_methods[name] = str(e)
                continue
            seconds[name] = time.perf_counter() - t0
            methods[name] = estimate_rows(final, t)
            mu_m[name] = _mu_m_row(*product_moments(final.mean_norm, final.cov_norm), mu_m_truth)
            if "prior" not in methods:
                methods["prior"] = estimate_rows(prior, t)
                mu_m["prior"] = _mu_m_row(
                    *product_moments(prior.mean_norm, prior.cov_norm), mu_m_truth
                )
                extra["prior_of"] = name
            if more:
                extra[name] = more
        if forest is not None:
            if obj.image_records is None or any(r.s0 is None for r in obj.image_records):
                skipped_methods["forest"] = f"needs S_0 of every push: {obj.image_note}"
            else:
                feats = features_from_records(list(obj.image_records), obj.image_camera)
                f_mean, f_std = (a[-1] for a in forest.predict_object(feats))
                methods["forest"] = gaussian_rows(f_mean, f_std, t)
                m, mu = f_mean[0], f_mean[1]
                std = math.hypot(mu * f_std[0], m * f_std[1])  # first order
                mu_m["forest"] = _mu_m_row(m * mu, std, mu_m_truth)
        objects[obj.key] = {
            "source": obj.source,
            "surface": obj.surface,
            "files": list(obj.files),
            "pushes": len(obj.records),
            "skipped": list(obj.skipped),
            "truth": {n: _num(v) for n, v in zip(PARAM_NAMES, t, strict=True)},
            "truth_source": obj.truth_source,
            "methods": methods,
            "mu_m": {"truth": mu_m_truth, "methods": mu_m},
            "skipped_methods": skipped_methods,
            "seconds": seconds,
            **extra,
            **({"force_balance": _force_balance(obj, probe, balance)} if obj.raw_pushes else {}),
            "friction_reference": obj.friction_reference,
            "notes": list(obj.notes),
        }
    notes = [
        f"physics: pushes on their recorded clock at {PHYSICS_RATE_HZ:g} Hz, the known outline "
        "and the tracked (motion-capture) poses, no images; the filter's settings as shipped "
        "(pose noise set for VisNet tracks), none chosen on these objects",
        "prior: the first estimator's estimate before any push",
    ]
    if forest is None:
        notes.append("forest: not run (no --forest-data)")
    else:
        notes.append(f"forest: {forest_trees} trees fitted on {forest_pushes} simulated pushes")
    return RealBenchmark(
        data_dir=str(data_dir),
        seed=seed,
        estimators=estimators,
        forest_data=None if forest_data is None else str(forest_data),
        max_pushes=max_pushes,
        objects=objects,
        surfaces=_surfaces(objects),
        empty_objects=tuple(empty),
        notes=tuple(notes),
        seconds=time.perf_counter() - t_start,
        probe_mass=None if probe is None else probe.to_json(),
    )
