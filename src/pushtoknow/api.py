"""The Python API: the few names a user needs, re-exported by `import pushtoknow`.

    import pushtoknow as ptk

    result = ptk.estimate_simulated("random:7:0", pushes=5, seed=0)  # the testbed pushes it
    print(result.estimates[-1].mean)          # m (kg), μ, c_x, c_y (m), I_z (kg·m²)
    lo, hi = result.estimates[-1].interval()  # 90% intervals
    ptk.export_object(result, "mjcf", "object.xml")

    for result in ptk.estimate_recording("pushes.h5"):  # your own recorded pushes
        print(result.to_json())

Estimators: "physics", the dual filter whose model is the simulator, and "vt-addf", the
paper's learned dual filter (docs/DESIGN.md §9, §12).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import cast

import numpy as np

from pushtoknow.common.estimators import ESTIMATOR_NAMES
from pushtoknow.common.policy_names import POLICY_NAMES
from pushtoknow.common.random import stream_seed
from pushtoknow.identification.fit import Identification
from pushtoknow.identification.prior import CATALOGUE_PRIOR, EVERYDAY_PRIOR, PriorRanges
from pushtoknow.identification.recordings import load_recorded_objects, replay_scene
from pushtoknow.identification.recursive import PhysicsFilterConfig
from pushtoknow.identification.replay import ReplayScene
from pushtoknow.inference.estimator import InferenceConfig, InferenceResult, PushEstimate
from pushtoknow.inference.physics_filter import PhysicsFilterEstimator
from pushtoknow.inference.session import infer_recorded, infer_simulated, make_estimator
from pushtoknow.models.checkpoint import TrainedModel, load_checkpoint
from pushtoknow.pretrained import resolve_model_path
from pushtoknow.testbed.export import ExportKind, ObjectModel, write_export
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import ObjectSpec

__all__ = [
    "CATALOGUE_PRIOR",
    "ESTIMATOR_NAMES",
    "EVERYDAY_PRIOR",
    "InferenceConfig",
    "InferenceResult",
    "ObjectSpec",
    "PriorRanges",
    "PushEstimate",
    "TrainedModel",
    "estimate_recording",
    "estimate_simulated",
    "export_object",
    "load_model",
    "load_object",
]


def load_model(ref: str | Path = "pretrained") -> TrainedModel:
    """The perception (and learned filter) model: "pretrained" (shipped with the package) or
    a training run's directory."""
    if not isinstance(ref, (str, Path)):
        raise TypeError(f"ref: a run directory or 'pretrained', not {type(ref).__name__}")
    return load_checkpoint(resolve_model_path(str(ref)))


def load_object(ref: str | Path) -> ObjectSpec:
    """A testbed object: "catalogue:ID", "random:SEED:I" or a JSON/YAML spec file."""
    if not isinstance(ref, (str, Path)):
        raise TypeError(f"ref: an object reference string or file, not {type(ref).__name__}")
    return load_object_spec(str(ref))


def _config(pushes: int, estimator: str | None, policy: str) -> InferenceConfig:
    """The settings of a run, each argument checked (a one-line error naming it)."""
    if not isinstance(pushes, int) or isinstance(pushes, bool) or pushes < 1:
        raise ValueError(f"pushes: a positive integer, not {pushes!r}")
    if estimator is not None and estimator not in ESTIMATOR_NAMES:
        raise ValueError(f"estimator: one of {', '.join(ESTIMATOR_NAMES)}, not {estimator!r}")
    if policy not in POLICY_NAMES:
        raise ValueError(f"policy: one of {', '.join(POLICY_NAMES)}, not {policy!r}")
    fields: dict = {"pushes": pushes, "policy": policy}
    if estimator is not None:
        fields["estimator"] = estimator
    return InferenceConfig(**fields)


def _with_profiles(
    config: InferenceConfig, profiles: Sequence[str] | None, model: TrainedModel
) -> InferenceConfig:
    """`profiles`, or by default the learned filter's trained ones (the physics filter's:
    the config's)."""
    if profiles is not None:
        return config.model_copy(update={"profiles": tuple(profiles)})
    if config.estimator == "vt-addf":
        return config.model_copy(update={"profiles": tuple(model.profiles)})
    return config


def _seed(seed: int) -> int:
    if not isinstance(seed, int) or isinstance(seed, bool) or seed < 0:
        raise ValueError(f"seed: a non-negative integer, not {seed!r}")
    return seed


def estimate_simulated(
    obj: ObjectSpec | str,
    *,
    pushes: int = 5,
    estimator: str | None = None,
    policy: str = "uniform",
    profiles: Sequence[str] | None = None,
    seed: int = 0,
    model: TrainedModel | None = None,
) -> InferenceResult:
    """Push a testbed object `pushes` times and estimate its parameters after each push.

    obj: an `ObjectSpec` or a reference for `load_object`; estimator: "physics" or
    "vt-addf" (None: `InferenceConfig`'s default); policy: "uniform", "random",
    "active-kl" or "active-entropy"; profiles: speed profiles the policy may use (default:
    constant and release; the learned filter's: those it was trained on); model: perception
    (default: the shipped one). Same seed, same result."""
    cfg, seed = _config(pushes, estimator, policy), _seed(seed)
    if not isinstance(obj, (str, Path, ObjectSpec)):
        raise TypeError(f"obj: an ObjectSpec or object reference, not {type(obj).__name__}")
    spec = load_object(obj) if isinstance(obj, (str, Path)) else obj
    model = model or load_model()
    return infer_simulated(model, spec, _with_profiles(cfg, profiles, model), seed)


def estimate_recording(
    path: str | Path,
    *,
    estimator: str = "physics",
    object_index: int | None = None,
    max_pushes: int | None = None,
    seed: int = 0,
    model: TrainedModel | None = None,
    prior: PriorRanges | None = None,
) -> list[InferenceResult]:
    """Estimate each object in recorded pushes (a dataset or `infer` run directory, a shard
    or a recording file; docs/RECORDING.md), its pushes in their recorded order, each from its
    recorded pose. The physics estimator replays them with the outline stored with them (or,
    where none is stored, the one traced in the first image); the learned one needs images.
    object_index: only that object; max_pushes: the first K pushes of each; prior: the ranges of
    m, μ and I_z the physics estimator starts from (None: the object's, `RecordedObject.prior`:
    everyday objects' for real recordings)."""
    _config(1, estimator, "uniform")
    if prior is not None and not isinstance(prior, PriorRanges):
        raise TypeError(f"prior: a PriorRanges, not {type(prior).__name__}")
    seed = _seed(seed)
    model = model or load_model()
    objects = load_recorded_objects(Path(path), images=estimator == "vt-addf")
    if object_index is not None:
        objects = [o for o in objects if o.index == object_index]
        if not objects:
            raise ValueError(f"object_index: no object {object_index} in {path}")
    results = []
    for obj in objects:
        records = list(obj.records[:max_pushes] if max_pushes else obj.records)
        cfg = _with_profiles(_config(len(records), estimator, "uniform"), None, model)
        if estimator == "physics":
            scene = replay_scene(obj, "dataset") if obj.shape is not None else None
            est = PhysicsFilterEstimator(
                model,
                cfg,
                stream_seed(seed, "estimator"),
                obj.sim_config,
                PhysicsFilterConfig(prior=prior or obj.prior),
                scene=scene,
            )
        else:
            est = make_estimator(model, cfg, stream_seed(seed, "estimator"), obj.sim_config)
        try:
            results.append(
                infer_recorded(
                    model,
                    records,
                    cfg,
                    seed,
                    obj.truth,
                    obj.name,
                    estimator=est,
                    sim_config=obj.sim_config,
                )
            )
        finally:
            est.close()
    return results


def export_object(result: InferenceResult, kind: str, path: str | Path) -> list[Path]:
    """Write the estimated object (the last estimate's mean, the outline and height the
    estimator saw) for a simulator: kind "mjcf" (MuJoCo) or "urdf" (with an OBJ mesh beside
    it). Returns the files written."""
    if not isinstance(result, InferenceResult):
        raise TypeError(f"result: an InferenceResult, not {type(result).__name__}")
    if result.outline is None or result.height is None or not result.estimates:
        raise ValueError("result: no push was estimated, so there is no object to export")
    model = ObjectModel.from_estimate(
        result.estimates[-1].mean, result.outline, result.height, result.object_name or "object"
    )
    return write_export(model, cast(ExportKind, kind), Path(path))


def export_identification(
    identification: Identification, scene: ReplayScene, name: str, kind: str, path: str | Path
) -> list[Path]:
    """Write an `identify` result (its mean, the outline and height of the scene it replayed,
    in the record's object frame) for a simulator, as `export_object`."""
    outline = scene.footprint.vertices + np.asarray(scene.frame_offset)
    model = ObjectModel.from_estimate(identification.mean, outline, scene.height, name)
    return write_export(model, cast(ExportKind, kind), Path(path))
