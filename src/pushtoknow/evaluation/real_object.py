"""Estimates on real pushes (MIT Push, docs/DESIGN.md §11) against an object's known parameters.

`estimate_real_object` takes a dataset directory written by ``pushtoknow import-mit`` (one
object = one shape on one surface, with its converted pushes in file order), or a folder of raw
MIT Push files, and reports:

- **Conversion.** Raw MIT files are imported first (`import_mit_dataset`, into `import_dir` or
  a temporary directory), by default **time-rescaled to the model's training push speed**
  (``as_speed``; ``rescale=False`` converts them as recorded): the MIT pushes run at several
  speeds (the sample files at 100 mm/s) while the shipped model was trained at 20 mm/s and 10
  Hz, so at 100 mm/s every filter step would see five times the pusher travel the networks
  learned from. Rescaling keeps each push's path and forces and slows its clock (exact for
  quasi-static pushing only; see `pushtoknow.datasets.mit_import`). An existing import is used
  as it was converted.
- **Learned filter.** The trained model's filter runs over the pushes in order, replayed by a
  `RecordedExecutor`, the parameter posterior of each push being the next push's prior, as in
  `pushtoknow.inference.session.infer_object`. Unlike `infer_object`, each push's start pose
  (which defines the object frame of that push) is its recorded motion-capture pose: the real
  pushes are separate placements (the import translates each to the camera centre), so the
  previous push's end pose says nothing about the next start and VisNet re-localisation from it
  would be meaningless; for the same reason the previous push's orientation uncertainty is
  not carried into the next start (`real_inference_config`). The actions are the recorded ones
  (a recording cannot be re-pushed).
  Per push: mean ± std of every parameter (SI) and the filter's pose error at the push's end.
- **Random-forest baseline** (`pushtoknow.baselines.random_forest`), fitted on the features of
  the simulated pushes in `forest_data` (ground-truth poses), predicting from the real pushes'
  features computed from the recorded (motion-capture) poses: the ground-truth-pose variant.
  After k pushes: the mean of the first k per-push predictions (`ForestBaseline.predict_object`).
- **Prior-mean predictor**: the mean parameters of the objects in `forest_data` (docs/DESIGN.md §9).
- **Reference truth.** mass and I_z from the MIT catalogue (`mit_object`, docs/DESIGN.md §11), CoM
  at the footprint centroid, (0, 0). The dataset gives no friction, so the reference μ is
  measured from the pushes that are *pure translations*: |Δθ| < `PURE_TRANSLATION_DEG` (2°)
  between the first and the last sample. It is the import's friction rule
  (`datasets.mit_push.contact_phase_force`: mean ‖F‖ / (m·g) over each push's contact phase,
  every sample from the first to the last one in contact), with the samples of those pushes
  pooled. A pure translation at steady speed needs exactly μ·m·g of push to balance the
  table's friction.
  Uncertainties of this reference: the half-filled windows at the start and end of contact
  (biased low), and the object's free sliding after the probe stops (force 0; biased low by
  m·Δv/∫F dt, ~4% here). When no push qualifies the friction truth is None (said in ``notes``)
  and friction gets no error.
- **Errors**: the normalised error |estimate − truth| / (max − min of the parameter over the
  catalogue), the NRMSE of a single object (`evaluation.metrics.param_ranges`), per parameter,
  for the filter and the forest after every push and for the prior mean; ``overall`` = mean over
  the parameters with a truth. Also E[μ·m] (docs/DESIGN.md §10: quasi-static force reveals only
  μ·m), normalised by the range of μ·m over the catalogue.

Honest caveats (in ``notes`` of the report): the real object is not a catalogue object (its
mass and I_z lie inside the catalogue's ranges, not on the grid; plywood's μ ≈ 0.29 is below
the catalogue's μ range [0.35, 0.7], so the catalogue prior barely covers it); the shipped
model was trained on 6 s pushes at 20 mm/s (≈ 10.5 cm of object travel), while the MIT sample
pushes last ≈ 0.5 s at 100 mm/s (3–5 cm). Import with ``--as-speed 20`` to present them at
the training speed by time rescaling (exact only for quasi-static pushing; see
`pushtoknow.datasets.mit_import`).
"""

from __future__ import annotations

import hashlib
import json
import math
import tempfile
import time
import warnings
from dataclasses import dataclass, fields
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from pushtoknow.common.errors import DatasetError, IdentificationError, PushToKnowWarning
from pushtoknow.common.params import (
    GRAVITY,
    PARAM_NAMES,
    PARAM_RANGES,
    product_moments,
)
from pushtoknow.datasets.mit_import import IMPORT_FILE, TIME_SCALE_ATTR
from pushtoknow.datasets.mit_push import contact_phase_force, mit_object
from pushtoknow.datasets.shards import (
    list_shards,
    open_shard,
    read_shard,
    warn_if_incomplete,
)
from pushtoknow.evaluation.metrics import param_ranges
from pushtoknow.reporting.real_report import RealIdentification, RealReport

if TYPE_CHECKING:
    from pushtoknow.common.camera import CameraModel
    from pushtoknow.models.checkpoint import TrainedModel
    from pushtoknow.testbed.objects import ObjectSpec
    from pushtoknow.testbed.sim import PushRecord
    from pushtoknow.testbed.sim_config import SimConfig

__all__ = [
    "PURE_TRANSLATION_DEG",
    "REPORT_KEYS",
    "RealIdentification",
    "RealPushes",
    "RealReport",
    "estimate_real_object",
    "friction_reference",
    "identify_real",
    "load_real_object",
    "prepare_real_data",
    "real_inference_config",
]

PURE_TRANSLATION_DEG = 2.0  # |Δθ| below this over a push: a pure translation
MIN_SLIDE = 0.01  # m: a push whose object travelled less did not really slide (a glancing push)
# Push speed of the training data when the checkpoint does not record it (as `infer_object`):
# the simulator's default constant speed, that of the shipped model's data.
REPORT_KEYS = tuple(f.name for f in fields(RealReport))  # the keys of its JSON


# ============================================================================================
# Loading
# ============================================================================================
@dataclass(frozen=True)
class RealPushes:
    """One object of an ``import-mit`` dataset (`load_real_object`), SI."""

    spec: ObjectSpec  # the object as imported (MIT footprint and mass)
    # its pushes in file order: pose (T, 3) x, y (m), θ (rad) by motion capture, tactile
    # (T, 3) F_x, F_y (N) and contact, pusher (T, 2) (m), time (T,) (s)
    records: list[PushRecord]
    # per push, the MIT attributes of its HDF5 group ("mit_file", "mit_meta" JSON,
    # "mit_time_scale", …)
    attrs: list[dict]
    surface: str  # MIT names: "plywood", "rect1"
    shape: str
    camera: CameraModel  # the import's
    sim_config: SimConfig  # the import's: rate, pad, table
    import_info: dict  # the import's import.json

    @property
    def name(self) -> str:
        """``SURFACE:SHAPE``."""
        return f"{self.surface}:{self.shape}"


def load_real_object(data_dir: Path, obj: str | None = None) -> RealPushes:
    """One object of an ``import-mit`` dataset directory.

    obj: None (the directory must hold exactly one object), ``SHAPE`` or ``SURFACE:SHAPE``
    (e.g. ``rect1``, ``plywood:rect1``). Raises `DatasetError` when the directory is not an
    import-mit dataset or the object is absent or ambiguous (naming the objects it holds).
    """
    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise DatasetError(data_dir, "no such directory (expected a `pushtoknow import-mit` --out)")
    info_file = data_dir / IMPORT_FILE
    if not info_file.exists():
        raise DatasetError(
            data_dir,
            f"no {IMPORT_FILE}: not a MIT Push import (make one with "
            "`pushtoknow import-mit SRC --out DIR`)",
        )
    info = json.loads(info_file.read_text())
    found = []  # (surface, shape, shard, key)
    from pushtoknow.testbed.sim_config import SimConfig

    for s in list_shards(data_dir):
        with open_shard(s) as f:
            for key, g in f["objects"].items():
                found.append((str(g.attrs["mit_surface"]), str(g.attrs["mit_shape"]), s, key))
    if not found:
        raise DatasetError(data_dir, "holds no finished shard (was the import interrupted?)")
    names = [f"{su}:{sh}" for su, sh, _, _ in found]
    if obj is None:
        chosen = found if len(found) == 1 else []
        if not chosen:
            raise DatasetError(
                data_dir, f"holds {len(found)} objects ({', '.join(names)}); choose one"
            )
    else:
        surface, _, shape = obj.rpartition(":")
        chosen = [o for o in found if o[1] == shape and (not surface or o[0] == surface)]
        if len(chosen) != 1:
            what = "no object" if not chosen else f"{len(chosen)} objects"
            raise DatasetError(data_dir, f"{what} matching {obj!r} (it holds: {', '.join(names)})")
    surface, shape, shard, key = chosen[0]
    episodes = {str(ep.object_index): ep for ep in read_shard(shard)}
    ep = episodes[key]
    with open_shard(shard) as f:
        sim_config = SimConfig.model_validate(json.loads(f.attrs["sim_config"]))
        camera = sim_config.camera.model()
        pushes = f["objects"][key]["pushes"]
        attrs = [dict(pushes[k].attrs) for k in sorted(pushes, key=int)]
    if not ep.records:
        raise DatasetError(data_dir, f"object {surface}:{shape} has no pushes")
    return RealPushes(
        spec=ep.spec,
        records=ep.records,
        attrs=attrs,
        surface=surface,
        shape=shape,
        camera=camera,
        sim_config=sim_config,
        import_info=info,
    )


def _split_object(obj: str | None) -> tuple[str | None, str | None]:
    if obj is None:
        return None, None
    surface, _, shape = obj.rpartition(":")
    return (surface or None), shape


def prepare_real_data(
    data_dir: Path,
    obj: str | None = None,
    as_speed: float | None = None,
    import_dir: Path | None = None,
) -> tuple[Path, dict]:
    """(import-mit dataset directory, conversion info) for `data_dir`.

    An ``import-mit`` output (it has ``import.json``) is returned as it is. A folder of raw MIT
    Push files is imported into `import_dir` (required then), only the files of `obj`
    (``SHAPE`` or ``SURFACE:SHAPE``) when given, time-rescaled to `as_speed` (m/s; None: as
    recorded). Raises `DatasetError` for anything else, naming the directory.
    """
    from pushtoknow.datasets.mit_import import import_mit_dataset
    from pushtoknow.datasets.mit_push import find_mit_push_files

    data_dir = Path(data_dir)
    if not data_dir.is_dir():
        raise DatasetError(
            data_dir,
            "no such directory (expected MIT Push files or a `pushtoknow import-mit` --out)",
        )
    if (data_dir / IMPORT_FILE).exists():
        info = json.loads((data_dir / IMPORT_FILE).read_text())
        return data_dir, {
            "imported_here": False,
            "dir": str(data_dir),
            "as_speed_m_per_s": info.get("as_speed_m_per_s"),
        }
    surface, shape = _split_object(obj)
    if not find_mit_push_files(data_dir, surface, shape):
        what = f" of {obj!r}" if obj else ""
        raise DatasetError(
            data_dir,
            f"no {IMPORT_FILE} and no MIT Push files{what}: not a MIT Push import (make one "
            "with `pushtoknow import-mit SRC --out DIR`) nor a folder of MIT Push files",
        )
    if import_dir is None:
        raise ValueError("import_dir is needed to convert raw MIT Push files")
    res = import_mit_dataset(
        data_dir, import_dir, surface=surface, shape=shape, as_speed=as_speed, progress=False
    )
    return Path(import_dir), {
        "imported_here": True,
        "source": str(data_dir),
        "dir": str(import_dir),
        "as_speed_m_per_s": as_speed,
        "files": res.files,
    }


# ============================================================================================
# Reference friction
# ============================================================================================
def friction_reference(
    records,
    mass: float,
    max_rotation_deg: float = PURE_TRANSLATION_DEG,
    min_travel: float = MIN_SLIDE,
) -> dict:
    """Reference μ from the pure translations among `records` (module doc, "Reference truth"):
    pushes that turned the object by less than `max_rotation_deg` while moving it at least
    `min_travel` (m; a glancing push that barely moved it balanced less than the full sliding
    friction).

    Returns {"value": μ or None, "rule": text, "pushes": [{"rotation_deg", "travel_m",
    "pure_translation", "mu_contact_phase" (that push's own mean ‖F‖/(m·g), None without
    contact), "contact_samples"}], "lower_bound": the largest "mu_contact_phase" (None without
    contact), "lower_bound_push": its index}. A quasi-static push's force is at most μ·m·g
    (the limit surface's largest force is the pure translation's), so every push bounds μ from
    below, whatever it turned: a bound above "value" says one μ does not describe the pushes.
    """
    per, pooled = [], []
    for rec in records:
        rot = math.degrees(float(rec.pose[-1, 2] - rec.pose[0, 2]))
        travel = float(np.hypot(*(rec.pose[-1, :2] - rec.pose[0, :2])))
        f = contact_phase_force(rec.tactile[:, :2], rec.tactile[:, 2] > 0.5)
        pure = abs(rot) < max_rotation_deg and travel >= min_travel and f.size > 0
        if pure:
            pooled.append(f)
        per.append(
            {
                "rotation_deg": rot,
                "travel_m": travel,
                "pure_translation": bool(pure),
                "mu_contact_phase": float(f.mean() / (mass * GRAVITY)) if f.size else None,
                "contact_samples": int(f.size),
            }
        )
    value = float(np.concatenate(pooled).mean() / (mass * GRAVITY)) if pooled else None
    rule = (
        f"mean |F| / (m g) over the contact phase (first to last contact sample) of the pushes "
        f"with |rotation| < {max_rotation_deg} deg that moved the object ≥ {min_travel * 1e3:g} "
        "mm (pure translations that slid), samples pooled"
    )
    seen = [(p["mu_contact_phase"], i) for i, p in enumerate(per) if p["mu_contact_phase"]]
    bound, at = max(seen) if seen else (None, None)
    return {
        "value": value,
        "rule": rule,
        "pushes": per,
        "lower_bound": bound,
        "lower_bound_push": at,
    }


# ============================================================================================
# Estimation
# ============================================================================================
def _params_dict(mean, std=None) -> dict:
    if std is None:
        return {n: float(m) for n, m in zip(PARAM_NAMES, mean, strict=True)}
    return {
        n: {"mean": float(m), "std": float(s)}
        for n, m, s in zip(PARAM_NAMES, mean, std, strict=True)
    }


def _errors(pred: np.ndarray, truth: np.ndarray) -> dict:
    """|pred − truth| / catalogue range per parameter (None where truth is NaN), overall."""
    e = np.abs(np.asarray(pred, float) - truth) / param_ranges()
    out = {n: (None if np.isnan(v) else float(v)) for n, v in zip(PARAM_NAMES, e, strict=True)}
    known = e[~np.isnan(e)]
    out["overall"] = float(known.mean()) if known.size else None
    return out


def _product_range() -> float:
    lo = PARAM_RANGES["mass"][0] * PARAM_RANGES["friction"][0]
    hi = PARAM_RANGES["mass"][1] * PARAM_RANGES["friction"][1]
    return hi - lo


def _training_features(root: Path):
    """Features (N, F) of every push of a simulated dataset (ground-truth poses), params (N,
    5) SI, object index (N,). Images are not read (only S_0 is needed)."""
    from pushtoknow.baselines.random_forest import features_from_records
    from pushtoknow.testbed.sim_config import SimConfig

    X, Y, obj = [], [], []
    shards = list_shards(root)
    if not shards:
        raise DatasetError(root, "no shard-*.h5 files: not a simulated dataset for the forest")
    for s in shards:
        with open_shard(s) as f:
            cam = SimConfig.model_validate(json.loads(f.attrs["sim_config"])).camera.model()
        for ep in read_shard(s, images=False):
            X.append(features_from_records(ep.records, cam))
            Y.append(np.tile(ep.spec.params.as_array(), (len(ep.records), 1)))
            obj += [ep.object_index] * len(ep.records)
    return np.concatenate(X), np.concatenate(Y), np.asarray(obj)


def _push_digest(pose, tactile) -> str:
    """SHA-256 of a push's recorded pose and force (the same recording, however named)."""
    h = hashlib.sha256(np.ascontiguousarray(pose).tobytes())
    h.update(np.ascontiguousarray(tactile).tobytes())
    return h.hexdigest()


def forest_overlap(forest_data: Path, real: RealPushes) -> str | None:
    """A warning when the forest's dataset holds the object under test (`real`, from
    `load_real_object`): an object of the same name, pushes imported from the same MIT files
    (same file names) or with the same recorded pose and force; None when it holds none."""
    name = real.spec.name
    files = {Path(str(a["mit_file"])).name for a in real.attrs if "mit_file" in a}
    digests = {_push_digest(r.pose, r.tactile) for r in real.records}
    found = []  # (shard, object name, pushes in common)
    for s in list_shards(forest_data):
        with open_shard(s) as f:
            for g in f["objects"].values():
                other = str(json.loads(g.attrs["spec"]).get("name", ""))
                pushes = g["pushes"].values()
                same = sum(
                    Path(str(p.attrs.get("mit_file", ""))).name in files
                    or _push_digest(p["pose"][()], p["tactile"][()]) in digests
                    for p in pushes
                )
                if same or other == name:
                    found.append((s.name, other, same))
    if not found:
        return None
    shown = ", ".join(f"{o} in {s} ({n} of its pushes shared)" for s, o, n in found[:3])
    more = f" and {len(found) - 3} more" if len(found) > 3 else ""
    return (
        f"--forest-data {forest_data} holds the object under test ({name}): {shown}{more}; the "
        "forest and the prior mean are fitted on it, so their errors are not a test (fit them "
        "on simulated data, `pushtoknow simulate`)"
    )


def rate_note(real: RealPushes, model) -> str | None:
    """A note when the real pushes' clock (the import's rate) is not the model's."""
    rate, model_rate = real.sim_config.tactile.rate_hz, model.sim_config.tactile.rate_hz
    if math.isclose(rate, model_rate, rel_tol=1e-9):
        return None
    return (
        f"rate: the pushes were imported at {rate:g} Hz, the model runs at {model_rate:g} Hz: "
        f"the filter takes one step per sample ({rate / model_rate:.3g}x the steps per second "
        f"it was trained with) and its intervals assume {model_rate:g} Hz samples, so they are "
        f"not calibrated here; import with --rate {model_rate:g}"
    )


def real_inference_config(pushes: int, num_sigma_points: int | None = None):
    """`InferenceConfig` of the filter on recorded pushes (each starts at its motion-capture
    pose)."""
    from pushtoknow.inference.estimator import InferenceConfig

    return InferenceConfig(estimator="vt-addf", pushes=pushes, num_sigma_points=num_sigma_points)


def _run_filter(model, records, camera, seed: int, num_sigma_points: int | None):
    """Filter over the recorded pushes in order; returns (prior, estimates, pose errors)."""
    from pushtoknow.inference.learned_filter import LearnedFilterEstimator
    from pushtoknow.testbed.executor import RecordedExecutor

    cfg = real_inference_config(len(records), num_sigma_points)
    est = LearnedFilterEstimator(model, cfg, seed)
    ex = RecordedExecutor(records, camera)
    estimates, pose_err = [], []
    for k, recorded in enumerate(records):
        view = ex.observe()
        rec = ex.execute(recorded.push)  # the recording's own push; nothing to choose
        pose0 = np.asarray(rec.pose[0], dtype=float)  # motion capture (module doc)
        if k == 0:  # the prior is reported with the object seen
            est.see_object(view, pose0)
            prior = est.estimate(0)
        poses = est.update(rec, view, pose0)
        estimates.append(est.estimate(k + 1, rec.push))
        d = poses[-1] - rec.pose[-1]
        pose_err.append(
            {
                "xy_mm": float(np.hypot(d[0], d[1]) * 1e3),
                "theta_deg": float(abs(math.degrees(math.remainder(d[2], 2 * math.pi)))),
            }
        )
    return prior, estimates, pose_err


def estimate_real_object(
    data_dir: Path,
    model_path: Path,
    forest_data: Path | None = None,
    seed: int = 0,
    *,
    obj: str | None = None,
    num_sigma_points: int | None = None,
    forest_trees: int = 200,
    rescale: bool = True,
    import_dir: Path | None = None,
    identify: bool = True,
    identify_config=None,
) -> RealReport:
    """Filter, forest, physics-based identification and prior-mean estimates on the real pushes
    of one object against its reference truth (module doc), as a `RealReport`.

    data_dir: an ``import-mit`` output or a folder of raw MIT Push files (imported into
    `import_dir`, default a temporary directory, time-rescaled to the model's training speed
    unless `rescale` is False; see `prepare_real_data`); model_path: a checkpoint or run
    directory (see `pushtoknow.pretrained.resolve_model_path`); forest_data: a simulated
    dataset directory to fit the forest and the prior mean on (None: neither row); obj: see
    `load_real_object`; num_sigma_points: None = the model's; identify: also fit φ by
    replaying the pushes in MuJoCo (`identify_real`), with `identify_config` (an
    `IdentifyConfig`, None: the defaults).
    Raises `DatasetError` (bad data_dir, object or forest_data) or `CheckpointError`.
    """
    t0 = time.perf_counter()
    inputs = _load_inputs(data_dir, model_path, forest_data, obj, rescale, import_dir)
    model, real = inputs.model, inputs.real
    truth, truth_source, fric = _reference_truth(real)
    filter_row, beliefs, pose_err = _filter_rows(model, real, seed, num_sigma_points)
    forest_row = forest_means = prior_mean = None
    if inputs.training is not None:
        forest_row, forest_means, prior_mean = _forest_rows(
            inputs.training, real, forest_trees, seed
        )
    ident = identify_real(data_dir, real, seed, identify_config) if identify else None
    pushes = _push_rows(real, fric, pose_err)
    return RealReport(
        object=real.name,
        data_dir=str(data_dir),
        model=str(model_path),
        forest_data=None if forest_data is None else str(forest_data),
        seed=seed,
        conversion=inputs.conversion,
        pushes=pushes,
        truth={n: (None if np.isnan(v) else float(v)) for n, v in zip(PARAM_NAMES, truth)},
        truth_source=truth_source,
        friction_reference=fric,
        filter=filter_row,
        forest=forest_row,
        identify=ident,
        prior_mean=None if prior_mean is None else _params_dict(prior_mean),
        errors=_error_rows(truth, beliefs, forest_means, prior_mean, ident),
        mu_m=_mu_m_rows(truth, beliefs, forest_means, prior_mean, ident),
        ranges={n: list(PARAM_RANGES[n]) for n in PARAM_NAMES},
        notes=_notes(truth, pushes, model, real, inputs.cautions),
        seconds=time.perf_counter() - t0,
    )


@dataclass(frozen=True)
class _Inputs:
    """What `estimate_real_object` works on (`_load_inputs`)."""

    model: TrainedModel
    real: RealPushes
    conversion: dict  # `prepare_real_data`'s, "dir" None for a temporary import
    training: tuple[np.ndarray, np.ndarray, np.ndarray] | None  # `_training_features`
    cautions: list[str]  # warnings given, for the notes


def _load_inputs(data_dir, model_path, forest_data, obj, rescale, import_dir) -> _Inputs:
    """The model, the forest's training set and the real pushes (imported first when raw),
    checked before any work: a bad `forest_data` fails first, and the pushes must be rendered
    with the model's camera. Warns when `forest_data` is incomplete or holds the object under
    test."""
    from pushtoknow.models.checkpoint import load_checkpoint

    model = load_checkpoint(Path(model_path))
    training, cautions = None, []
    if forest_data is not None:  # first: a bad one fails before any work
        training = _training_features(Path(forest_data))
        cautions.append(warn_if_incomplete(Path(forest_data), "--forest-data"))
    as_speed = model.sim_config.push.speed if rescale else None  # its training pushes' speed
    with tempfile.TemporaryDirectory(prefix="pushtoknow-mit-") as tmp:
        target = Path(import_dir) if import_dir is not None else Path(tmp) / "import"
        ds_dir, conversion = prepare_real_data(data_dir, obj, as_speed, target)
        real = load_real_object(ds_dir, obj)
    if import_dir is None and conversion["imported_here"]:
        conversion["dir"] = None  # a temporary directory, gone
    if model.camera != real.camera:
        raise DatasetError(
            data_dir,
            f"rendered with camera {real.camera}, the model was trained with {model.camera}",
        )
    if forest_data is not None and (overlap := forest_overlap(Path(forest_data), real)):
        warnings.warn(overlap, PushToKnowWarning, stacklevel=3)
        cautions.append(overlap)
    return _Inputs(model, real, conversion, training, [c for c in cautions if c is not None])


def _reference_truth(real: RealPushes) -> tuple[np.ndarray, dict[str, str], dict]:
    """(truth (5,) in `PARAM_NAMES` order, friction NaN when no push qualifies; its source per
    parameter, in words; `friction_reference`'s dict) of the real object (module doc)."""
    ref = mit_object(real.shape)
    fric = friction_reference(real.records, ref.mass)
    mu = fric["value"]
    truth = np.array([ref.mass, np.nan if mu is None else mu, 0.0, 0.0, ref.inertia], dtype=float)
    centroid = "footprint centroid (MIT Push objects are uniform)"
    source = {
        "mass": f"MIT Push catalogue ({real.shape}, stainless steel)",
        "friction": "measured from the pushes: " + fric["rule"]
        if mu is not None
        else "none: no push is a pure translation",
        "com_x": centroid,
        "com_y": centroid,
        "inertia": f"MIT Push catalogue ({real.shape})",
    }
    return truth, source, fric


def _filter_rows(model, real: RealPushes, seed: int, num_sigma_points: int | None):
    """The learned filter over the pushes in order (`_run_filter`): (the report's filter
    entry, its beliefs [prior, after push 1, …, after push K] (`ParamEstimate`), the pose
    error at each push's end {"xy_mm", "theta_deg"})."""
    prior, estimates, pose_err = _run_filter(
        model, real.records, real.camera, seed, num_sigma_points
    )
    row = {
        "variant": model.variant,
        "sigma_points": num_sigma_points or model.inference.num_sigma_points,
        "prior": prior.as_dict(),
        "per_push": [e.as_dict() for e in estimates],
    }
    return row, [prior, *estimates], pose_err


def _forest_rows(training, real: RealPushes, trees: int, seed: int):
    """The random forest fitted on `training` (`_training_features`), predicting from the
    real pushes' features at their recorded (motion-capture) poses, and the prior mean of the
    training objects: (the report's forest entry, the forest's means after each push (K, 5),
    the prior mean (5,)), SI."""
    from pushtoknow.baselines.random_forest import (
        ForestBaseline,
        ForestConfig,
        features_from_records,
    )
    from pushtoknow.evaluation.metrics import PriorMeanPredictor

    X, Y, obj_idx = training
    forest = ForestBaseline(ForestConfig(n_estimators=trees, seed=seed)).fit(X, Y)
    f_mean, f_std = forest.predict_object(features_from_records(real.records, real.camera))
    _, first = np.unique(obj_idx, return_index=True)
    prior_mean = PriorMeanPredictor().fit(Y[first]).mean_
    row = {
        "per_push": [_params_dict(m, s) for m, s in zip(f_mean, f_std)],
        "training_pushes": len(X),
        "trees": trees,
    }
    return row, f_mean, prior_mean


def _error_rows(truth, beliefs, forest_means, prior_mean, ident) -> dict:
    """`_errors` of the filter after each push and of its prior, then (when they ran) of the
    forest after each push, the prior mean and the identification after each push."""
    errors = {
        "filter": [_errors(e.mean, truth) for e in beliefs[1:]],
        "filter_prior": _errors(beliefs[0].mean, truth),
    }
    if forest_means is not None:
        errors["forest"] = [_errors(m, truth) for m in forest_means]
        errors["prior_mean"] = _errors(prior_mean, truth)
    if ident is not None:
        errors["identify"] = [
            _errors(np.array([p[n]["mean"] for n in PARAM_NAMES]), truth) for p in ident.per_push
        ]
    return errors


def _mu_m_rows(truth, beliefs, forest_means, prior_mean, ident) -> dict:
    """E[μ·m] of the same predictors as `_error_rows` beside its truth (None without a friction
    truth), and their errors normalised by the catalogue's μ·m range."""
    mu_m_true = None if np.isnan(truth[1]) else float(truth[0] * truth[1])

    def perr(v: float):
        return None if mu_m_true is None else abs(v - mu_m_true) / _product_range()

    moments = [product_moments(e.mean_norm, e.cov_norm) for e in beliefs]
    mu_m = {
        "truth": mu_m_true,
        "filter_prior": {"mean": moments[0][0], "std": moments[0][1]},
        "filter": [{"mean": m, "std": s} for m, s in moments[1:]],
    }
    mu_m["errors"] = {"filter": [perr(p["mean"]) for p in mu_m["filter"]]}
    if forest_means is not None:
        mu_m["forest"] = [float(m[0] * m[1]) for m in forest_means]
        mu_m["prior_mean"] = float(prior_mean[0] * prior_mean[1])
        mu_m["errors"]["forest"] = [perr(v) for v in mu_m["forest"]]
        mu_m["errors"]["prior_mean"] = perr(mu_m["prior_mean"])
    if ident is not None:
        mu_m["identify"] = [p["mu_m"] for p in ident.per_push]
        mu_m["errors"]["identify"] = [perr(p["mean"]) for p in mu_m["identify"]]
    return mu_m


def _push_rows(real: RealPushes, fric: dict, pose_err: list[dict]) -> list[dict]:
    """The report's per-push summary (`RealReport.pushes`)."""
    pushes = []
    for rec, pa, fr, pe in zip(real.records, real.attrs, fric["pushes"], pose_err, strict=True):
        meta = json.loads(pa["mit_meta"]) if "mit_meta" in pa else {}
        d = rec.pose[-1, :2] - rec.pose[0, :2]
        pushes.append(
            {
                "file": str(pa.get("mit_file", "")),
                "speed_m_per_s": float(rec.push.speed),
                "file_speed_m_per_s": meta.get("speed_m_per_s"),
                "time_scale": float(pa.get(TIME_SCALE_ATTR, 1.0)),
                "samples": len(rec.time),
                "displacement_m": float(np.hypot(d[0], d[1])),
                "rotation_deg": fr["rotation_deg"],
                "pure_translation": fr["pure_translation"],
                "mu_contact_phase": fr["mu_contact_phase"],
                "filter_pose_error_end": pe,
            }
        )
    return pushes


def identify_real(data_dir: Path, real: RealPushes, seed: int, config=None) -> RealIdentification:
    """`pushtoknow.identification.identify` on the first k pushes of `real` (an object of
    `load_real_object(data_dir)`), k = 1…K.

    The pushes are replayed along their recorded pusher tracks (the pad is the probe: radius
    `PUSHER_RADIUS`, frictionless; the table is the testbed's Coulomb contact at its grid of
    supports under uniform pressure) in the import's footprint and settings, on the recorded
    clock: a push time-rescaled by s at rate r Hz is the recording sampled at r·s Hz, so it is
    replayed at that rate (the import's pushes must share one time scale). The recording has
    no noise level, so each channel's noise is its misfit (`identify`)."""
    from pushtoknow.identification.fit import identify
    from pushtoknow.identification.identify_config import IdentifyConfig
    from pushtoknow.identification.recordings import recorded_clock
    from pushtoknow.identification.replay import ReplayScene, RolloutPool

    records = real.records
    try:
        sim = recorded_clock(
            real.sim_config, [a.get(TIME_SCALE_ATTR, 1.0) for a in real.attrs], str(data_dir)
        )
    except IdentificationError as e:
        raise DatasetError(data_dir, str(e).split(": ", 1)[1]) from None
    sim = sim.model_copy(update={"render": False})
    cfg = config or IdentifyConfig()
    scene = ReplayScene(real.spec.shape, real.spec.height, sim, stop_at_rest=cfg.stop_at_rest)
    per_push, d = [], {}
    with RolloutPool(cfg.workers) as pool:  # one process pool for every fit
        for k in range(1, len(records) + 1):
            d = identify(records[:k], scene, cfg, seed, pool=pool).as_dict()
            per_push.append(
                {
                    **d["parameters"],
                    "mu_m": d["mu_m"],
                    "unidentified": d["unidentified"],
                    "reduced_chi2": d["reduced_chi2"],
                    "seconds": d["seconds"],
                    "rollouts": d["rollouts"],
                }
            )
    return RealIdentification(
        per_push=per_push,
        rate_hz=sim.tactile.rate_hz,
        noise_std=d["noise_std"],
        model=(
            f"MuJoCo replay of the recorded pusher tracks: probe radius "
            f"{sim.pad.radius * 1e3:.2f} mm, pad friction {sim.pad.friction:g}, table friction "
            "Coulomb at the testbed's support grid (uniform pressure), footprint as imported"
        ),
        notes=d["notes"],
    )


def _notes(truth, pushes, model, real: RealPushes, cautions: list[str]) -> list[str]:
    """The report's caveats (module doc), the warnings given (`cautions`) and `rate_note`."""
    notes = [
        "The real object is not one of the training catalogue's objects: its parameters are "
        "compared with the catalogue ranges below, not with grid values."
    ]
    for n, v in zip(PARAM_NAMES, truth):
        if np.isnan(v):
            continue
        lo, hi = PARAM_RANGES[n]
        where = "inside" if lo <= v <= hi else "OUTSIDE"
        notes.append(f"{n} truth {v:.4g} is {where} the catalogue range [{lo:.4g}, {hi:.4g}] (SI)")
    if np.isnan(truth[1]):
        notes.append(
            f"friction truth: no push is a pure translation (|rotation| < "
            f"{PURE_TRANSLATION_DEG} deg), so friction has no reference and no error"
        )
    train_speed = model.sim_config.push.speed
    speeds = sorted({round(p["speed_m_per_s"], 6) for p in pushes})
    if any(abs(v - train_speed) > 1e-6 for v in speeds):
        notes.append(
            f"speed mismatch: the pushes are labelled {speeds} m/s, the model was trained at "
            f"{train_speed} m/s (10 Hz): each filter step sees a larger pusher displacement "
            "than in training; import with --as-speed to time-rescale (quasi-static assumption)"
        )
    scaled = sorted({round(p["time_scale"], 6) for p in pushes})
    if scaled != [1.0]:
        notes.append(
            f"time-rescaled pushes (scale {scaled}): exact only for quasi-static pushing; the "
            "real pushes include dynamic content (impacts, stick-slip, sliding after release)"
        )
    notes.append(
        "docs/PHYSICS.md: quasi-static pushing reveals μ·m (force) and the CoM (motion), not m and "
        "μ separately, and I_z barely: compare μ·m rather than mass or friction alone"
    )
    from pushtoknow.inference.learned_filter import outside_training  # torch: the filter's

    reasons = outside_training(real.records, real.spec.footprint, real.sim_config, model.info)
    notes.append(
        "the filter: this object lies outside what it was trained on (read off its pushes and "
        f"outline): {'; '.join(reasons)}; its estimates there are extrapolations"
        if reasons
        else "the filter: nothing in the pushes or the outline lies outside what it was trained on"
    )
    rate = rate_note(real, model)
    return notes + cautions + ([] if rate is None else [rate])
