"""`pushtoknow train`: the whole training of one variant, from a dataset to a checkpoint.

Stages (docs/DESIGN.md §8), each logged to a CSV file in the run directory:
1. VisNet, supervised (`visnet.csv`), or reused from another run (`visnet_from`);
2. VisNet poses of every frame (reference = truth perturbed as in VisNet's training);
3. supervised warm-up of the filter's networks on ground-truth transitions (`supervised.csv`);
4. end to end through the filter on truncated windows (`end_to_end.csv`), best validation kept;
5. calibration of the inference settings (R scale, update stride) on validation pushes by the
   NLL of the true parameters after a whole push (`calibration.csv`);
6. the share of each push's evidence the parameter belief keeps, per direction, on whole
   push sequences of the validation objects (`sequence_calibration.csv`,
   `training.calibrate`).
Objects are split into training and validation sets by object (`val_fraction`).
"""

from __future__ import annotations

import csv
import json
import math
import platform
import time
from pathlib import Path

import torch
from pydantic import Field

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.common.version import __version__
from pushtoknow.datasets.generate import GENERATION_FILE
from pushtoknow.datasets.shards import warn_if_incomplete
from pushtoknow.filters.base import FilterConfig
from pushtoknow.models.checkpoint import (
    InferenceSettings,
    ParamPrior,
    TrainedModel,
    Variant,
    load_checkpoint,
    new_model,
    save_checkpoint,
)
from pushtoknow.models.learned import LearnedModelsConfig
from pushtoknow.perception.visnet import visnet_measure
from pushtoknow.testbed.push import PROFILES
from pushtoknow.testbed.sim_config import SimConfig, check_testbed_version
from pushtoknow.training.calibrate import SequenceCalibrationConfig, calibrate_evidence
from pushtoknow.training.end_to_end import EndToEndConfig, evaluate_filter, train_end_to_end
from pushtoknow.training.fit_visnet import VisNetTrainConfig, perturb, train_visnet
from pushtoknow.training.push_tensors import (
    PushTensors,
    compute_vision_poses,
    dataset_camera,
    load_frames,
    load_push_tensors,
)
from pushtoknow.training.supervised import SupervisedConfig, tactile_losses, train_supervised


class CalibrationConfig(Config):
    noise_scales: tuple[float, ...] = (1.0, 4.0, 16.0, 64.0)
    update_every: tuple[int, ...] = (1, 5)
    val_pushes: int = Field(48, ge=1)
    num_sigma_points: int = Field(32, ge=MIN_SIGMA_POINTS)


class TrainConfig(Config):
    """Everything `pushtoknow train` does; YAML-loadable (`--config`)."""

    variant: Variant = "vt-addf"
    val_fraction: float = Field(0.1, gt=0, lt=1)
    max_objects: int | None = Field(None, ge=2)
    prior_coverage: float | None = Field(
        None,
        gt=0,
        lt=1,
        description="widen the parameter prior (the training objects' moments) until its "
        "central interval of this level spans each catalogue range; None: the moments as "
        "they are",
    )
    visnet: VisNetTrainConfig = VisNetTrainConfig(epochs=10, frame_every=10)
    models: LearnedModelsConfig = LearnedModelsConfig()
    filter: FilterConfig = FilterConfig()
    supervised: SupervisedConfig = SupervisedConfig(steps=1500)
    end_to_end: EndToEndConfig = EndToEndConfig()
    calibration: CalibrationConfig = CalibrationConfig()
    sequence_calibration: SequenceCalibrationConfig = SequenceCalibrationConfig()
    inference_sigma_points: int = Field(100, ge=MIN_SIGMA_POINTS)


class CsvLog:
    """Rows of dicts → CSV (columns = union of keys seen so far; file rewritten per row)."""

    def __init__(self, path: Path, echo=None):
        self.path, self.rows, self.echo = Path(path), [], echo

    def __call__(self, row: dict) -> None:
        self.rows.append({k: v for k, v in row.items() if not isinstance(v, list | dict)})
        cols: list[str] = []
        for r in self.rows:
            cols += [k for k in r if k not in cols]
        with open(self.path, "w", newline="") as f:
            w = csv.DictWriter(f, cols)
            w.writeheader()
            w.writerows(self.rows)
        if self.echo:
            self.echo(self.path.stem, row)


MIN_TRAINING_OBJECTS = 2  # one to train on and one to validate on, at the least


def split_by_object(pt: PushTensors, val_fraction: float, seed: int):
    """(train, val) PushTensors with no object in both."""
    objects = torch.unique(pt.object_index)
    gen = torch.Generator().manual_seed(seed)
    perm = objects[torch.randperm(len(objects), generator=gen)]
    n_val = max(1, int(round(val_fraction * len(objects))))
    is_val = torch.isin(pt.object_index, perm[:n_val])
    return pt.subset(torch.nonzero(~is_val).squeeze(1)), pt.subset(torch.nonzero(is_val).squeeze(1))


def _data_provenance(data: Path) -> dict:
    gen = Path(data) / GENERATION_FILE
    if not gen.exists():
        return {"data": str(data)}
    g = json.loads(gen.read_text())
    c = g.get("config", {})
    return {
        "data": str(data),
        "fingerprint": g.get("fingerprint"),
        "data_seed": c.get("seed"),
        "objects": c.get("objects"),
        "pushes_per_object": c.get("pushes"),
        "objects_from": c.get("objects_from"),
    }


def force_loss_fn(models, pt: PushTensors):
    """force_fn(push, t) → TacNet's force MSE (units of force_scale²) at the true states of
    samples t (B,) of pushes `push` (B,), used as a term of the end-to-end loss."""

    def fn(push: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
        return tactile_losses(models, pt, push, t)[1]

    return fn


def visnet_config_for(cfg: VisNetTrainConfig, sim_cfg: SimConfig) -> VisNetTrainConfig:
    """VisNet's training config for data rendered with `sim_cfg`: with the orientation marker
    the network gets the expected-marker channel."""
    if not sim_cfg.orientation_marker or cfg.net.marker_channel:
        return cfg
    net = cfg.net.model_copy(
        update={"marker_channel": True, "in_channels": cfg.net.in_channels + 1}
    )
    return cfg.model_copy(update={"net": net})


def train_model(
    data: Path,
    out: Path,
    cfg: TrainConfig = TrainConfig(),
    seed: int = 0,
    visnet_from: Path | None = None,
    progress: bool = True,
    echo=None,
) -> TrainedModel:
    """Train `cfg.variant` on the dataset in `data`; write the run to `out` (see module doc)."""
    from pushtoknow.common.progress import progress_bar

    data, out = Path(data), Path(out)
    if not data.exists():
        raise DatasetError(data, "does not exist")
    if (out / "model.pt").exists():  # never overwrite a finished run
        raise DatasetError(out, "holds a trained model (model.pt); write the run elsewhere")
    reused = load_checkpoint(visnet_from).visnet if visnet_from is not None else None
    camera, sim_cfg = dataset_camera(data)
    check_testbed_version(sim_cfg, f"the pushes of dataset {data}")
    warn_if_incomplete(data, "--data")
    t_start = time.perf_counter()
    pt = load_push_tensors(data, cfg.max_objects)
    objects = len(torch.unique(pt.object_index))
    if objects < MIN_TRAINING_OBJECTS:
        raise DatasetError(
            data,
            f"{objects} object(s); training needs at least {MIN_TRAINING_OBJECTS} (training and "
            "validation objects)",
        )
    out.mkdir(parents=True, exist_ok=True)
    cfg = cfg.model_copy(update={"visnet": visnet_config_for(cfg.visnet, sim_cfg)})
    cfg.to_yaml(out / "config.yaml")  # as run: VisNet's input channels follow the data
    torch.manual_seed(seed)
    timings: dict[str, float] = {}
    vision_only = cfg.variant == "v-ddf"

    with progress_bar(progress, remaining=False) as bar:
        # 1. VisNet
        t0 = time.perf_counter()
        if reused is not None:
            visnet = reused
            visnet_summary = {"reused_from": str(visnet_from)}
        else:
            frames = load_frames(data, cfg.visnet.frame_every, cfg.max_objects)
            res = train_visnet(
                frames,
                camera,
                cfg.visnet,
                seed,
                log=CsvLog(out / "visnet.csv", echo),
                progress=bar,
            )
            del frames
            visnet, visnet_summary = res.net, res.val_error
        visnet.eval()
        timings["visnet_s"] = time.perf_counter() - t0

        # 2. VisNet poses of every frame
        t0 = time.perf_counter()
        gen = torch.Generator().manual_seed(seed + 2)

        def measure(rgbd, mask0, pose, pose0):
            ref = perturb(pose, cfg.visnet, gen)
            return visnet_measure(visnet, rgbd, mask0, pose0, ref, camera)

        task = bar.add_task("VisNet poses", total=len(pt))
        pt.vision_pose = compute_vision_poses(
            data, measure, cfg.max_objects, progress=lambda: bar.advance(task)
        )
        train, val = split_by_object(pt, cfg.val_fraction, seed)
        prior = ParamPrior.from_params(train.params_norm, train.object_index)
        if cfg.prior_coverage is not None:
            prior = prior.covering_range(cfg.prior_coverage)
        err = (pt.vision_pose - pt.pose)[..., :2].norm(dim=-1)
        vision_error = {"vision_xy_rmse_mm": float(err.square().mean().sqrt() * 1e3)}
        timings["vision_poses_s"] = time.perf_counter() - t0

        model = new_model(
            cfg.variant,
            cfg.models,
            cfg.filter,
            visnet,
            prior,
            camera,
            info={
                "seed": seed,
                "push_speed": sim_cfg.push.speed,
                "sim_config": sim_cfg.model_dump(mode="json"),
                **_data_provenance(data),
            },
        )
        models = model.models

        # 3. supervised warm-up
        t0 = time.perf_counter()
        sup_cfg = cfg.supervised
        if vision_only:
            sup_cfg = sup_cfg.model_copy(update={"force_weight": 0.0, "contact_weight": 0.0})
        train_supervised(
            models,
            train,
            val,
            sup_cfg,
            seed,
            log=CsvLog(out / "supervised.csv", echo),
            progress=bar,
        )
        timings["supervised_s"] = time.perf_counter() - t0

        # 4. end to end
        t0 = time.perf_counter()
        filt = model.build_filter(cfg.end_to_end.num_sigma_points, noise_scale=1.0)
        force_fn = None if vision_only else force_loss_fn(models, train)
        _, best = train_end_to_end(
            filt,
            train,
            val,
            prior,
            cfg.end_to_end,
            vision_only,
            seed,
            force_fn,
            log=CsvLog(out / "end_to_end.csv", echo),
            progress=bar,
        )
        timings["end_to_end_s"] = time.perf_counter() - t0

        # 5. calibration of the inference settings
        t0 = time.perf_counter()
        model.inference = calibrate(
            model, val, cfg.calibration, seed, CsvLog(out / "calibration.csv", echo), bar
        )
        model.inference = model.inference.model_copy(
            update={"num_sigma_points": cfg.inference_sigma_points}
        )
        timings["calibration_s"] = time.perf_counter() - t0

        # 6. how much of each push's evidence to keep, on validation push sequences
        t0 = time.perf_counter()
        model.inference = calibrate_evidence(
            model,
            val,
            cfg.sequence_calibration,
            seed,
            CsvLog(out / "sequence_calibration.csv", echo),
            bar,
        )
        timings["sequence_calibration_s"] = time.perf_counter() - t0

    timings["total_s"] = time.perf_counter() - t_start
    model.info.update(
        {
            "variant": cfg.variant,
            "profiles": sorted({PROFILES[int(i)] for i in pt.action[:, 4].tolist()}),
            "train_objects": int(torch.unique(train.object_index).numel()),
            "val_objects": int(torch.unique(val.object_index).numel()),
            "train_pushes": len(train),
            "visnet_val": visnet_summary,
            **vision_error,
            "end_to_end_best": {k: v for k, v in (best or {}).items()},
            "timings": timings,
            "machine": f"{platform.processor() or platform.machine()}, "
            f"{torch.get_num_threads()} threads",
            "pushtoknow_version": __version__,
        }
    )
    save_checkpoint(model, out)
    (out / "training.json").write_text(json.dumps(model.info, indent=1, default=str))
    return model


def calibrate(
    model: TrainedModel,
    val: PushTensors,
    cfg: CalibrationConfig,
    seed: int,
    log=None,
    progress=None,
) -> InferenceSettings:
    """Pick (noise_scale, update_every) minimising the validation NLL of the true parameters
    after a whole push from the prior."""
    best, best_nll = InferenceSettings(), math.inf
    grid = [(s, k) for k in cfg.update_every for s in cfg.noise_scales]
    task = progress.add_task("calibration", total=len(grid)) if progress else None
    for scale, every in grid:
        filt = model.build_filter(cfg.num_sigma_points, noise_scale=scale)
        res = evaluate_filter(
            filt,
            val,
            model.prior,
            cfg.num_sigma_points,
            model.vision_only,
            seed,
            cfg.val_pushes,
            update_every=every,
        )
        row = {"noise_scale": scale, "update_every": every, **res}
        if log:
            log(row)
        if progress:
            progress.advance(task)
        if res["param_nll"] < best_nll:
            best_nll = res["param_nll"]
            best = InferenceSettings(update_every=every, noise_scale=scale)
    return best
