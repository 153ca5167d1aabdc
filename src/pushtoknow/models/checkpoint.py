"""A trained model: the filter's networks, VisNet, their configs and the parameter prior, saved as
one checkpoint file (`model.pt`) that names the versions and configs it was written with.

Loading checks the file's format and format version, rebuilds the networks from the stored
configs and loads the weights strictly; any mismatch is a `CheckpointError` naming the problem.
"""

from __future__ import annotations

import hashlib
import io
import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Literal

import torch
from pydantic import Field, field_validator

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import CheckpointError, first_line
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.common.version import __version__
from pushtoknow.filters.base import BeliefFilter, FilterConfig
from pushtoknow.filters.gaussian import symmetrize
from pushtoknow.models.calibration import check_correlations, evidence_discount
from pushtoknow.models.learned import (
    FilterKind,
    LearnedModels,
    LearnedModelsConfig,
    ScaledObservationNoise,
    build_filter,
    build_learned_models,
)
from pushtoknow.models.networks import VisNet, VisNetConfig
from pushtoknow.testbed.push import PROFILES

CHECKPOINT_FORMAT = "pushtoknow-checkpoint"
CHECKPOINT_VERSION = 2  # 2: m, μ and I_z normalised through their logarithm (common.params)
CHECKPOINT_FILE = "model.pt"

Variant = Literal["vt-addf", "vt-jdf", "v-ddf"]
FILTER_KIND: dict[str, FilterKind] = {"vt-addf": "dual", "vt-jdf": "joint", "v-ddf": "vision_only"}


RANGE_MARGIN = 0.05  # normalised: 2.5% of a catalogue range (ParamPrior.covering_range)


@dataclass(frozen=True)
class ParamPrior:
    """Gaussian prior over the normalised parameters: mean (K,), cov (K, K)."""

    mean: torch.Tensor
    cov: torch.Tensor

    @classmethod
    def from_params(cls, params_norm: torch.Tensor, object_index: torch.Tensor) -> ParamPrior:
        """Moments over the objects (each counted once) of a training set; params_norm (N, K),
        object_index (N,) one row per push."""
        _, first = _first_rows(object_index)
        per_object = params_norm[first].double()
        mean = per_object.mean(0)
        dev = per_object - mean
        cov = dev.T @ dev / max(len(per_object) - 1, 1)
        return cls(mean.float(), symmetrize(cov).float())

    def covering_range(self, level: float) -> ParamPrior:
        """This prior widened, where it is narrower, until each parameter's central `level`
        interval spans the whole normalised catalogue range [-1, 1] and RANGE_MARGIN beyond
        (so values at the range's ends are inside, not on the edge; correlations kept): the
        moments of a bounded set of training objects under-cover its ends (a Gaussian fitted
        to the four catalogue values of I_z leaves the lowest and highest outside its 90%
        interval)."""
        if not 0.0 < level < 1.0:
            raise ValueError(f"prior coverage level must lie in (0, 1), got {level}")
        z = torch.distributions.Normal(0.0, 1.0).icdf(torch.tensor(0.5 + 0.5 * level)).double()
        std = self.cov.double().diagonal().sqrt()
        need = (1.0 + RANGE_MARGIN + self.mean.double().abs()) / z
        factor = torch.maximum(need / std, torch.ones_like(std))
        cov = self.cov.double() * factor[:, None] * factor[None, :]
        return ParamPrior(self.mean.clone(), symmetrize(cov).float())

    def to_dict(self) -> dict:
        return {"mean": self.mean.tolist(), "cov": self.cov.tolist()}

    @classmethod
    def from_dict(cls, d: dict) -> ParamPrior:
        return cls(torch.tensor(d["mean"]), torch.tensor(d["cov"]))


def _first_rows(index: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
    """(unique values, the first row holding each)."""
    uniq, inverse = torch.unique(index, return_inverse=True)
    first = torch.full((len(uniq),), len(index), dtype=torch.long)
    first = first.scatter_reduce(0, inverse, torch.arange(len(index)), reduce="amin")
    return uniq, first


class InferenceSettings(Config):
    """How the trained filter runs at inference (calibrated on validation pushes after
    training). update_every: apply the measurement update at every n-th 10 Hz sample only
    (prediction runs at every sample); noise_scale: factor on the learned R
    (dynamic_noise_scale: on the samples of a push's dynamic phase, None: the same);
    evidence_weights: the share of each push's evidence the parameter belief keeps, per
    direction of `models.calibration.DIRECTIONS` (1: the filter's posterior as it is);
    profile_evidence_weights: the same for pushes of a named speed profile, where its model
    errors differ (`evidence_weights_for`); evidence_correlation: r ∈ [0, 1) per direction, the
    correlation of the model errors of two pushes of one profile (the n-th push of a profile
    keeps its weight × `models.calibration.evidence_discount`; 0: independent pushes)."""

    update_every: int = Field(1, ge=1)
    noise_scale: float = Field(1.0, gt=0)
    dynamic_noise_scale: float | None = Field(
        None, gt=0, description="factor on R in a push's dynamic phase; None: noise_scale"
    )
    num_sigma_points: int = Field(100, ge=MIN_SIGMA_POINTS)
    evidence_weights: tuple[float, float, float, float, float] = (1.0, 1.0, 1.0, 1.0, 1.0)
    profile_evidence_weights: dict[str, tuple[float, float, float, float, float]] = Field(
        default_factory=dict, description="per speed profile; absent: evidence_weights"
    )
    evidence_correlation: tuple[float, float, float, float, float] = (0.0, 0.0, 0.0, 0.0, 0.0)

    @field_validator("evidence_weights")
    @classmethod
    def _in_unit_interval(cls, v):
        if not all(0.0 <= w <= 1.0 for w in v):
            raise ValueError(f"evidence weights must lie in [0, 1], got {list(v)}")
        return v

    @field_validator("profile_evidence_weights")
    @classmethod
    def _known_profiles(cls, v):
        for name, weights in v.items():
            if name not in PROFILES:
                raise ValueError(f"unknown speed profile {name!r}; choose from {list(PROFILES)}")
            cls._in_unit_interval(weights)
        return v

    @field_validator("evidence_correlation")
    @classmethod
    def _correlations(cls, v):
        check_correlations(v)
        return v

    def evidence_weights_for(self, profile: str) -> tuple[float, float, float, float, float]:
        """The evidence weights of a push with speed profile `profile`."""
        return self.profile_evidence_weights.get(profile, self.evidence_weights)

    def evidence_weight_table(self, dtype: torch.dtype = torch.float32) -> torch.Tensor:
        """(P, K) evidence weights per speed profile, rows in `testbed.push.PROFILES` order."""
        return torch.tensor([self.evidence_weights_for(p) for p in PROFILES], dtype=dtype)

    def kept_evidence(self, profile: str, nth: int) -> torch.Tensor:
        """(K,) the evidence weights of the `nth` (≥ 1) push of speed profile `profile`."""
        weights = torch.tensor(self.evidence_weights_for(profile), dtype=torch.float64)
        r = torch.tensor(self.evidence_correlation, dtype=torch.float64)
        return (weights * evidence_discount(torch.tensor(nth), r)).float()


@dataclass
class TrainedModel:
    """Everything inference needs. camera: the camera of the training images; info:
    provenance (data seed, training config, validation numbers), free-form JSON; the testbed
    settings of the training data are typed (`sim_config`, `profiles`)."""

    variant: Variant
    models_config: LearnedModelsConfig
    filter_config: FilterConfig
    models: LearnedModels
    visnet: VisNet
    prior: ParamPrior
    camera: CameraModel
    info: dict = field(default_factory=dict)
    inference: InferenceSettings = field(default_factory=InferenceSettings)

    @property
    def sim_config(self):
        """The testbed settings of the model's training data (push horizon, speed, camera):
        inference pushes the same way. Models saved without them get the defaults; settings
        saved before testbed versions existed read back as version 1 (a simulator refuses
        them: such a model must be retrained)."""
        from pushtoknow.testbed.sim_config import SimConfig, stored_sim_config

        raw = self.info.get("sim_config")
        return SimConfig() if raw is None else stored_sim_config(raw)

    @property
    def profiles(self) -> tuple[str, ...]:
        """The speed profiles the model was trained on (its policies choose among them);
        models from before profiles were recorded saw constant pushes only."""
        return tuple(self.info.get("profiles") or ("constant",))

    @property
    def vision_only(self) -> bool:
        return self.variant == "v-ddf"

    def build_filter(
        self,
        num_sigma_points: int | None = None,
        noise_scale: float | None = None,
        dynamic_noise_scale: float | None = None,
    ) -> BeliefFilter:
        """The variant's filter on these networks, R scaled by `noise_scale` and
        `dynamic_noise_scale` (defaults: the calibrated `inference` ones; a `noise_scale`
        given alone scales every sample), with `num_sigma_points` (default: inference's)."""
        c = num_sigma_points or self.inference.num_sigma_points
        cfg = self.filter_config.model_copy(update={"num_sigma_points": c})
        if noise_scale is None:
            scale = self.inference.noise_scale
            dynamic = self.inference.dynamic_noise_scale
        else:
            scale, dynamic = noise_scale, dynamic_noise_scale
        m = self.models
        noise = ScaledObservationNoise(m.observation_noise, scale, dynamic)
        models = LearnedModels(m.dynamics, m.observation, noise)
        return build_filter(FILTER_KIND[self.variant], models, filter_config=cfg)

    def eval(self) -> TrainedModel:
        self.models.modules().eval()
        self.visnet.eval()
        return self


def new_model(
    variant: Variant,
    models_config: LearnedModelsConfig,
    filter_config: FilterConfig,
    visnet: VisNet,
    prior: ParamPrior,
    camera: CameraModel,
    info: dict | None = None,
) -> TrainedModel:
    if variant not in FILTER_KIND:
        raise CheckpointError(f"unknown variant {variant!r}; expected one of {list(FILTER_KIND)}")
    models = build_learned_models(models_config, vision_only=(variant == "v-ddf"))
    return TrainedModel(
        variant, models_config, filter_config, models, visnet, prior, camera, dict(info or {})
    )


def _camera_dict(camera: CameraModel) -> dict:
    return {k: getattr(camera, k) for k in camera.__dataclass_fields__}


def weights_digest(*states: dict) -> str:
    """SHA-256 over state dicts (names, dtypes, shapes and bytes, in key order): what a
    checkpoint stores to detect corrupt weights on load."""
    h = hashlib.sha256()
    for state in states:
        for name in sorted(state):
            t = state[name].detach().cpu().contiguous()
            h.update(f"{name}|{t.dtype}|{tuple(t.shape)}|".encode())
            h.update(t.numpy().tobytes())
    return h.hexdigest()


def _check_weights(path: Path, payload: dict) -> None:
    """Raise CheckpointError when the stored digest does not match the weights (a damaged
    file) or when a weight is not finite. Checkpoints written before digests were stored get
    the finiteness check only."""
    states = (payload["models_state"], payload["visnet_state"])
    want = payload.get("weights_sha256")
    if want is not None and weights_digest(*states) != want:
        raise CheckpointError(
            f"{path}: the weights do not match their checksum (the file is damaged); "
            "restore it or retrain"
        )
    for state in states:
        for name, t in state.items():
            if t.is_floating_point() and not torch.isfinite(t).all():
                raise CheckpointError(f"{path}: weight {name} holds NaN or infinite values")


def save_checkpoint(model: TrainedModel, path: Path) -> Path:
    """Write `model` to path (a directory gets `model.pt`), atomically (temp file + rename)."""
    path = Path(path)
    if path.suffix != ".pt":  # a run directory
        path = path / CHECKPOINT_FILE
    path.parent.mkdir(parents=True, exist_ok=True)
    payload = {
        "format": CHECKPOINT_FORMAT,
        "format_version": CHECKPOINT_VERSION,
        "pushtoknow_version": __version__,
        "torch_version": str(torch.__version__),
        "variant": model.variant,
        "models_config": model.models_config.model_dump(mode="json"),
        "filter_config": model.filter_config.model_dump(mode="json"),
        "visnet_config": model.visnet.config.model_dump(mode="json"),
        "camera": _camera_dict(model.camera),
        "prior": model.prior.to_dict(),
        "info": json.loads(json.dumps(model.info)),
        "inference": model.inference.model_dump(mode="json"),
        "models_state": model.models.modules().state_dict(),
        "visnet_state": model.visnet.state_dict(),
    }
    payload["weights_sha256"] = weights_digest(payload["models_state"], payload["visnet_state"])
    buf = io.BytesIO()
    torch.save(payload, buf)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_bytes(buf.getvalue())
    tmp.replace(path)
    return path


def checkpoint_file(path: Path) -> Path:
    """The checkpoint file `path` names: itself, or a run directory's `model.pt`."""
    path = Path(path)
    return path / CHECKPOINT_FILE if path.is_dir() else path


def load_checkpoint(path: Path) -> TrainedModel:
    """Read a checkpoint written by `save_checkpoint` (a file, or a run directory holding
    `model.pt`)."""
    path = checkpoint_file(path)
    if not path.exists():
        raise CheckpointError(f"no checkpoint at {path}")
    try:
        payload = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as e:
        raise CheckpointError(
            f"{path} is not a readable pushtoknow checkpoint ({first_line(e)})"
        ) from e
    if not isinstance(payload, dict) or payload.get("format") != CHECKPOINT_FORMAT:
        raise CheckpointError(f"{path} is not a pushtoknow checkpoint")
    version = payload.get("format_version")
    if version != CHECKPOINT_VERSION:
        raise CheckpointError(
            f"{path} has checkpoint format version {version}, this pushtoknow "
            f"{__version__} reads version {CHECKPOINT_VERSION}; retrain the model "
            "or use the pushtoknow version that wrote it "
            f"({payload.get('pushtoknow_version', 'unknown')})"
        )
    _check_weights(path, payload)
    try:
        models_config = LearnedModelsConfig.model_validate(payload["models_config"])
        filter_config = FilterConfig.model_validate(payload["filter_config"])
        visnet = VisNet(VisNetConfig.model_validate(payload["visnet_config"]))
        camera = CameraModel(**payload["camera"])
        model = new_model(
            payload["variant"],
            models_config,
            filter_config,
            visnet,
            ParamPrior.from_dict(payload["prior"]),
            camera,
            payload.get("info", {}),
        )
        model.inference = InferenceSettings.model_validate(payload.get("inference", {}))
    except CheckpointError:
        raise
    except Exception as e:
        raise CheckpointError(f"{path}: its config does not fit this version ({e})") from e
    for name, module, state in (
        ("filter networks", model.models.modules(), payload["models_state"]),
        ("VisNet", model.visnet, payload["visnet_state"]),
    ):
        try:
            module.load_state_dict(state, strict=True)
        except RuntimeError as e:
            first = str(e).splitlines()[0:3]
            raise CheckpointError(
                f"{path}: the weights of the {name} do not match their config: {' '.join(first)}"
            ) from e
    return model.eval()
