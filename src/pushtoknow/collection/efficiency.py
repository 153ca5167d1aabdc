"""Learning efficiency of the data-collection policies (`pushtoknow ablate-efficiency`; the
paper's Fig. 4b, docs/DESIGN.md §8): validation loss versus the number of training pushes when the
training data grow by pushes chosen uniformly, at random or actively.

Per replicate seed s (the run's `--seed` plus each of `seeds`):

1. initial data: `initial.objects` training-catalogue objects × `initial.pushes` pushes with
   random affordances (`pushtoknow simulate`, data seed s), shared by every policy;
2. M0 = `train_model` on the initial data (training seed s), shared by every policy;
3. for each policy and round r = 1 … R: collect `round.objects` new objects × `round.pushes`
   pushes with the policy and M_{r-1} (`collect_dataset`, seed s; the objects of round r are
   the next block of the same seeded order, identical for every policy, so the policies differ
   only in which pushes they choose), and train M_r from scratch on the union of the initial
   data and rounds 1 … r (training seed s).

Validation loss: every model M runs its filter (the calibrated inference settings: R scale and
update stride; `validation.num_sigma_points` sigma points) over each push of a fixed
validation set (`validation.objects` held-out catalogue objects, `catalogue-test`, simulated
once with random affordances and seed `--seed`), one whole push from M's parameter prior
(`training.end_to_end.evaluate_filter`); VisNet measures the poses with the reference perturbed
from the truth as in training. The loss is the mean NLL of the true normalised parameters under
the belief after the push (`val_nll`, the y axis of the figure); the parameter RMSE in
normalised units (`val_rmse`, mean over the five) and the median NLL go beside it.

VisNet: with `visnet_from` every model, M0 included, reuses that run's VisNet (e.g. the shipped
model's, trained on other training-catalogue objects with the same camera); otherwise, with
`share_visnet` (default), M0 trains VisNet on the initial data and every later model of the
replicate reuses it (`train_model(visnet_from=M0)`). Either way the comparison is fair in that
every policy's models see poses from the same VisNet, but it then measures what the collected
pushes do for the filter's networks (process model, TacNet, observation noise), not for VisNet.

The initial pushes are simulated like `pushtoknow simulate` (the object placed afresh before
each push); collected pushes re-centre the object between pushes as inference does (so the
filter's belief carries over); both are plain pushes with the model's testbed settings.

Outputs in `out`: `efficiency.json` = {policy: [{"round", "pushes", "seeds", "val_nll": [per
seed], "val_rmse": [per seed], "val_nll_median": [per seed], "mean", "std", "rmse_mean",
"rmse_std"}, …]} (rows by round, round 0 being M0; "pushes" = all pushes of the model's
dataset, of which `train_model` holds out `train.val_fraction` of the objects for its own model
selection and calibration; mean/std over seeds of val_nll, std with ddof = 1, 0 for one seed),
`efficiency.csv` (one row per policy, round and seed), `efficiency-run.json` (config, seeds,
per-model details, timings); the CLI adds `efficiency.png`. Resumable: finished datasets,
models and validation results are kept (`ablation.json` holds the fingerprint of the config
and seed; another config is an error).
"""

from __future__ import annotations

import csv
import hashlib
import json
import math
import os
import time
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import torch
from pydantic import Field, field_validator

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.common.policy_names import POLICY_NAMES, PolicyName
from pushtoknow.testbed.sim_config import SimConfig
from pushtoknow.training.pipeline import TrainConfig

ABLATION_FILE = "ablation.json"
RESULTS_FILE = "efficiency.json"


class DataBlock(Config):
    objects: int = Field(..., ge=1)
    pushes: int = Field(..., ge=1, description="pushes per object")


class ValidationSet(Config):
    objects: int = Field(24, ge=1)
    pushes: int = Field(2, ge=1)
    objects_from: str = "catalogue-test"
    num_sigma_points: int = Field(32, ge=MIN_SIGMA_POINTS)


class EfficiencyConfig(Config):
    """`pushtoknow ablate-efficiency --config FILE` (see the module docstring)."""

    objects_from: str = Field("catalogue-train", description="source of training objects")
    initial: DataBlock = DataBlock(objects=40, pushes=2)
    rounds: int = Field(3, ge=1)
    round: DataBlock = DataBlock(objects=40, pushes=2)
    policies: tuple[PolicyName, ...] = ("uniform", "random", "active-entropy")
    seeds: tuple[int, ...] = (0, 1)
    validation: ValidationSet = ValidationSet()
    sim: SimConfig = SimConfig()
    train: TrainConfig = TrainConfig()
    share_visnet: bool = True
    visnet_from: str | None = Field(
        None,
        description="reuse this run's VisNet ('pretrained' or a RUN directory) in every model, "
        "M0 included; None: M0 trains one (shared by the seed's models if share_visnet)",
    )
    candidates: int = Field(16, ge=1, description="affordances per push decision (collection)")
    collect_sigma_points: int | None = Field(
        32,
        ge=MIN_SIGMA_POINTS,
        description="sigma points of the filter while collecting (None: the model's)",
    )
    objects_per_shard: int = Field(4, ge=1)
    workers: int = Field(2, ge=1, description="processes for simulation and collection")
    torch_threads: int | None = Field(
        1,
        ge=1,
        description="torch threads of the training process (1 is fastest on a few shared "
        "cores; None: torch's default)",
    )

    @field_validator("policies", mode="before")
    @classmethod
    def _known_policies(cls, v):
        for p in [v] if isinstance(v, str) else v:
            if p not in POLICY_NAMES:
                raise ValueError(f"policy must be one of {', '.join(POLICY_NAMES)}, got {p!r}")
        return v

    @field_validator("policies", "seeds")
    @classmethod
    def _distinct(cls, v):
        if not v or len(set(v)) != len(v):
            raise ValueError("must be a non-empty list without repeats")
        return v

    def fingerprint(self, seed: int) -> str:
        data = {
            "config": self.model_dump(mode="json", exclude={"workers", "torch_threads"}),
            "seed": seed,
        }
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def _std(xs: list[float]) -> float:
    return float(np.std(xs, ddof=1)) if len(xs) > 1 else 0.0


def _write_json(path: Path, data) -> None:
    tmp = path.with_name(path.name + ".tmp")
    tmp.write_text(json.dumps(data, indent=1))
    os.replace(tmp, path)


def _model_done(run: Path) -> bool:
    return (run / "model.pt").exists() and (run / "training.json").exists()


@dataclass(frozen=True)
class ValidationMetrics:
    """One model's validation metrics (`validation_loss`; the module docstring): mean NLL of
    the true normalised parameters after one push from the prior (`val_nll`, nats), its median
    over pushes (`val_nll_median`), the normalised parameter RMSE after the push and before it
    (`val_rmse`, `val_prior_rmse`; mean over the five), the share of true parameters inside
    the 90% interval (`val_coverage90`), the validation pushes (`val_pushes`) and the model's
    inference settings (`inference`, `InferenceSettings` as JSON). `to_json()` is the content
    of the model's validation.json."""

    val_nll: float
    val_rmse: float
    val_nll_median: float
    val_coverage90: float
    val_prior_rmse: float
    val_pushes: int
    inference: dict

    def to_json(self) -> dict:
        return asdict(self)


@dataclass(frozen=True)
class EfficiencyRound:
    """One policy's models after one round (round 0: M0, shared by every policy), over the
    replicate seeds: the pushes of their training data (`pushes`), the seeds, per seed (in
    `seeds` order) val_nll, val_rmse and val_nll_median (`ValidationMetrics`), and over the
    seeds the mean and std of val_nll (`mean`, `std`) and of val_rmse (`rmse_mean`,
    `rmse_std`); std with ddof = 1, 0 for one seed."""

    round: int
    pushes: int
    seeds: list[int]
    val_nll: list[float]
    val_rmse: list[float]
    val_nll_median: list[float]
    mean: float
    std: float
    rmse_mean: float
    rmse_std: float


@dataclass(frozen=True)
class EfficiencyResults:
    """The ablation's result (`summarise`, `run_efficiency`): per policy, in the config's
    order, its `EfficiencyRound`s by round. `to_json()` is efficiency.json ({policy: [round
    rows]}), what `--json` prints."""

    policies: dict[str, list[EfficiencyRound]]

    def to_json(self) -> dict:
        return {p: [asdict(r) for r in rounds] for p, rounds in self.policies.items()}


def validation_loss(
    model_dir: Path, val_data: Path, cfg: EfficiencyConfig, seed: int
) -> ValidationMetrics:
    """The validation metrics of the model in `model_dir` on the dataset `val_data` (see the
    module docstring), cached in `model_dir/validation.json`."""
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.perception.visnet import visnet_measure
    from pushtoknow.training.end_to_end import evaluate_filter
    from pushtoknow.training.fit_visnet import perturb
    from pushtoknow.training.push_tensors import compute_vision_poses, load_push_tensors

    cache = Path(model_dir) / "validation.json"
    if cache.exists():
        return ValidationMetrics(**json.loads(cache.read_text()))
    model = load_checkpoint(model_dir)
    pt = load_push_tensors(val_data)
    gen = torch.Generator().manual_seed(seed + 2)
    vis_cfg = cfg.train.visnet

    @torch.no_grad()
    def measure(rgbd, mask0, pose, pose0):
        ref = perturb(pose, vis_cfg, gen)
        return visnet_measure(model.visnet, rgbd, mask0, pose0, ref, model.camera)

    pt.vision_pose = compute_vision_poses(val_data, measure)
    c = cfg.validation.num_sigma_points
    filt = model.build_filter(c)  # the calibrated R scale
    filt.eval()
    res = evaluate_filter(
        filt,
        pt,
        model.prior,
        c,
        model.vision_only,
        seed,
        update_every=model.inference.update_every,
    )
    out = ValidationMetrics(
        val_nll=res["param_nll"],
        val_rmse=res["param_rmse_mean"],
        val_nll_median=res["param_nll_median"],
        val_coverage90=res["coverage90"],
        val_prior_rmse=res["prior_param_rmse_mean"],
        val_pushes=len(pt),
        inference=model.inference.model_dump(mode="json"),
    )
    _write_json(cache, out.to_json())
    return out


def summarise(rows: list[dict], policies, seeds) -> EfficiencyResults:
    """rows (policy, round, seed, pushes, val_*) → per policy, per round: the per-seed lists
    (in `seeds` order), mean and std (`EfficiencyResults`)."""
    out: dict[str, list[EfficiencyRound]] = {}
    for p in policies:
        mine = [r for r in rows if r["policy"] == p]
        series = []
        for rnd in sorted({r["round"] for r in mine}):
            at = sorted(
                (r for r in mine if r["round"] == rnd), key=lambda r: seeds.index(r["seed"])
            )
            nll = [r["val_nll"] for r in at]
            rmse = [r["val_rmse"] for r in at]
            series.append(
                EfficiencyRound(
                    round=rnd,
                    pushes=at[0]["pushes"],
                    seeds=[r["seed"] for r in at],
                    val_nll=nll,
                    val_rmse=rmse,
                    val_nll_median=[r["val_nll_median"] for r in at],
                    mean=float(np.mean(nll)),
                    std=_std(nll),
                    rmse_mean=float(np.mean(rmse)),
                    rmse_std=_std(rmse),
                )
            )
        out[p] = series
    return EfficiencyResults(out)


def run_efficiency(
    cfg: EfficiencyConfig,
    out: Path,
    seed: int = 0,
    workers: int | None = None,
    log: Callable[[str], None] | None = None,
) -> EfficiencyResults:
    """The whole ablation (module docstring); returns what efficiency.json holds."""
    threads = torch.get_num_threads()
    if cfg.torch_threads is not None:
        torch.set_num_threads(cfg.torch_threads)
    try:
        return _run(cfg, Path(out), seed, workers, log)
    finally:
        torch.set_num_threads(threads)


def _run(cfg: EfficiencyConfig, out: Path, seed: int, workers, log) -> EfficiencyResults:
    from pushtoknow.collection.collect import collect_dataset, combine_datasets
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
    from pushtoknow.datasets.shards import dataset_info
    from pushtoknow.training.pipeline import train_model

    say = log or (lambda _: None)
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    workers = workers or cfg.workers
    fp = cfg.fingerprint(seed)
    marker = out / ABLATION_FILE
    if marker.exists() and json.loads(marker.read_text()).get("fingerprint") != fp:
        raise DatasetError(
            out, f"holds an ablation run with another config or seed (see {ABLATION_FILE})"
        )
    _write_json(marker, {"fingerprint": fp, "seed": seed, "config": cfg.model_dump(mode="json")})
    cfg.to_yaml(out / "config.yaml")
    t_start = time.perf_counter()
    timings: dict[str, float] = {}

    def timed(key: str, fn, *args, **kwargs):
        t0 = time.perf_counter()
        res = fn(*args, **kwargs)
        timings[key] = timings.get(key, 0.0) + time.perf_counter() - t0
        return res

    def simulate(path: Path, block, objects_from: str, data_seed: int) -> None:
        gen = GenerationConfig(
            objects=block.objects,
            pushes=block.pushes,
            seed=data_seed,
            objects_from=objects_from,
            objects_per_shard=cfg.objects_per_shard,
            sim=cfg.sim,
        )
        timed("simulate_s", generate_dataset, path, gen, workers=workers, progress=False)

    def train(data: Path, run: Path, train_seed: int, visnet_from: Path | None) -> None:
        if _model_done(run):
            return
        say(f"training {run.relative_to(out)}")
        timed(
            "train_s",
            train_model,
            data,
            run,
            cfg.train,
            train_seed,
            visnet_from=visnet_from,
            progress=False,
        )

    def validate(run: Path) -> ValidationMetrics:
        return timed("validate_s", validation_loss, run, val_dir, cfg, seed)

    shared_visnet = None
    if cfg.visnet_from is not None:
        from pushtoknow.models.checkpoint import load_checkpoint
        from pushtoknow.pretrained import resolve_model_path

        shared_visnet = resolve_model_path(cfg.visnet_from)
        camera = load_checkpoint(shared_visnet).camera
        if camera != cfg.sim.camera.model():
            raise DatasetError(
                shared_visnet, "its VisNet was trained with another camera than the config's"
            )

    val_dir = out / "validation"
    say(f"validation set: {cfg.validation.objects} × {cfg.validation.pushes} pushes")
    simulate(val_dir, cfg.validation, cfg.validation.objects_from, seed)

    seeds = [seed + s for s in cfg.seeds]
    rows: list[dict] = []
    models: list[dict] = []
    for s in seeds:
        base = out / f"seed-{s}"
        initial = base / "initial"
        say(f"seed {s}: initial data {cfg.initial.objects} × {cfg.initial.pushes} pushes")
        simulate(initial, cfg.initial, cfg.objects_from, s)
        m0 = base / "m0"
        train(initial, m0, s, shared_visnet)
        v0 = validate(m0).to_json()  # rows: for summarise and efficiency.csv
        n0 = cfg.initial.objects * cfg.initial.pushes
        visnet_from = shared_visnet or (m0 if cfg.share_visnet else None)
        for p in cfg.policies:
            rows.append({"policy": p, "round": 0, "seed": s, "pushes": n0, **v0})
        models.append({"seed": s, "policy": None, "round": 0, "run": str(m0), **v0})
        for p in cfg.policies:
            prev, parts = m0, [initial]
            for r in range(1, cfg.rounds + 1):
                rdir = base / p / f"round-{r}"
                first = cfg.initial.objects + (r - 1) * cfg.round.objects
                say(f"seed {s}, {p}, round {r}: collecting with {prev.relative_to(out)}")
                timed(
                    "collect_s",
                    collect_dataset,
                    rdir / "collected",
                    prev,
                    p,
                    cfg.objects_from,
                    cfg.round.objects,
                    cfg.round.pushes,
                    s,
                    workers,
                    first,
                    objects_per_shard=cfg.objects_per_shard,
                    candidates=cfg.candidates,
                    num_sigma_points=cfg.collect_sigma_points,
                    progress=False,
                )
                parts.append(rdir / "collected")
                combine_datasets(parts, rdir / "data")
                n = dataset_info(rdir / "data").pushes
                run = rdir / "model"
                train(rdir / "data", run, s, visnet_from)
                v = validate(run)
                say(
                    f"seed {s}, {p}, round {r}: {n} pushes, val NLL {v.val_nll:.4g}, "
                    f"RMSE {v.val_rmse:.4g}"
                )
                rows.append({"policy": p, "round": r, "seed": s, "pushes": n, **v.to_json()})
                models.append({"seed": s, "policy": p, "round": r, "run": str(run), **v.to_json()})
                prev = run
    results = summarise(rows, list(cfg.policies), seeds)
    _write_json(out / RESULTS_FILE, results.to_json())
    cols = [
        "policy",
        "round",
        "seed",
        "pushes",
        "val_nll",
        "val_rmse",
        "val_nll_median",
        "val_coverage90",
        "val_prior_rmse",
    ]
    with open(out / "efficiency.csv", "w", newline="") as f:
        w = csv.DictWriter(f, cols, extrasaction="ignore")
        w.writeheader()
        w.writerows(rows)
    timings["total_s"] = time.perf_counter() - t_start
    _write_json(
        out / "efficiency-run.json",
        {
            "seed": seed,
            "seeds": seeds,
            "config": cfg.model_dump(mode="json"),
            "metric": "val_nll: mean NLL of the true normalised parameters after one push from "
            "the prior on the validation set (evaluate_filter); val_rmse: normalised RMSE",
            "models": models,
            "timings_this_call": timings,
        },
    )
    return results


def figure_series(
    results: EfficiencyResults, key: str = "nll"
) -> dict[str, list[tuple[float, float, float]]]:
    """{policy: [(pushes, mean, std)]} for `reporting.figures.plot_learning_efficiency`;
    key "nll" (val_nll) or "rmse" (val_rmse); policies with a non-finite mean are left out."""

    def point(r: EfficiencyRound) -> tuple[float, float, float]:
        m, s = (r.mean, r.std) if key == "nll" else (r.rmse_mean, r.rmse_std)
        return float(r.pushes), float(m), float(s)

    return {
        p: [point(r) for r in rounds]
        for p, rounds in results.policies.items()
        if all(math.isfinite(point(r)[1]) for r in rounds)
    }
