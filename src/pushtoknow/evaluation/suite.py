"""The evaluation suite behind `pushtoknow evaluate` (docs/DESIGN.md §9).

Protocol (what each number means):

- **Object sets.** "heldout": the catalogue's held-out objects (`catalogue_split` test IDs, never
  in any training set); "novel": `novel_objects` (unseen shapes and catalogue shapes, continuous
  parameters). Every method sees the same objects.
- **Methods.** For each trained model, inference with K pushes on every object: the first model
  with every policy in `policies`, the others with the first policy (`<variant>:<policy>`; a
  model whose structure differs from the first's is `<variant>-<structure>`). Each model's
  policies choose among the speed profiles it was trained on; the share of each profile the
  policy chose is reported (`profile_share`).
  `prior-mean`: the training objects' mean parameters. `forest`: the random-forest baseline
  (Mavrakis-style features, ground-truth poses) trained on the `--data` pushes and applied to
  the pushes the first model made under the first policy (same objects, same pushes), its
  estimate after k pushes the mean of the first k per-push predictions. `forest-visnet`: the
  same forest fed the filter's pose track (VisNet-driven) instead of ground-truth poses.
  `physics:<policy>`: the physics estimator (`inference.physics_filter`: the simulator as the
  dual filter's model, on the first model's perception) under each of `physics_policies`. Its
  runs use the seeds of the learned rows, so under the uniform (and random) policy it makes the
  same pushes as the first model's row of that policy (the policy's own random stream).
- **Sets.** "random" (when `random_objects` > 0): random-shape objects `random:<random_seed>:I`
  (`testbed.random_shapes`), continuous parameters.
- **Folds.** The objects of a set are split into `folds` disjoint groups (seeded; fewer, one
  per object, in a set of fewer objects, recorded as the set's `folds`); NRMSE is
  computed per group and reported as mean ± std over groups. The learned models are trained
  once on the catalogue's training split (retraining 3 variants × 5 folds does not fit on 2
  CPU cores), so the spread measures the variation over evaluation objects, not over training
  runs; the forest and the prior are refitted on the same training data as the models.
- **Coverage**: share of (object, parameter) pairs whose truth lies in the 68% / 90% central
  Gaussian interval of the method's final estimate (the forest's std is its tree spread).
- **Impossible / outside interval**: of the N·(K+1) estimates, how many describe no object
  (`impossible_estimates`), and how many report a mean outside their own 90% interval
  (`estimates_outside_interval`; target 0, docs/DESIGN.md §2). The filters' and the oracle's
  intervals are their reported, asymmetric ones; the forest's and the prior's are mean ±
  1.645·std, the Gaussian-in-SI interval their coverage uses, symmetric, so their count is 0
  by construction (computed all the same, so every row is counted the same way).

Inference runs are cached under OUT/cache (one .npz per set and method, keyed by the objects,
settings, the estimator and `CACHE_FORMAT`), so an interrupted evaluation resumes where it
stopped.

**Merging** (`keep`: a previous results.json): its rows are kept as they are and not
recomputed, provided the settings that define them are this run's (`KEEP_KEYS`; the random
set's two as well where it has one) and its sets hold this run's objects; only the missing sets
and rows are computed. Without training data (`data` None) a computed set has no forest rows
(its `notes` say so) and its prior-mean row is the estimators' prior
(`identification.prior.prior_moments`, its SI moments); the oracle row, where `oracle` is set,
is computed for every set that lacks one (on the first model's uniform pushes, ~40 s per
object).
"""

from __future__ import annotations

import hashlib
import json
import os
import platform
import shutil
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal

import numpy as np
from pydantic import Field
from scipy.stats import norm

from pushtoknow.active.information_policy import ACTIVE_POLICY_NAMES
from pushtoknow.baselines.random_forest import ForestBaseline, ForestConfig, features_from_dataset
from pushtoknow.common.errors import ConfigError
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.parallel import TaskRunner, Workers
from pushtoknow.common.params import MIN_SIGMA_POINTS, PARAM_NAMES
from pushtoknow.common.policy_names import POLICY_NAMES, PolicyName
from pushtoknow.evaluation.heldout import LEARNED_ESTIMATOR, HeldoutRun, evaluate_heldout
from pushtoknow.evaluation.metrics import (
    MethodRun,
    PriorMeanPredictor,
    coverage,
    estimates_outside_interval,
    impossible_estimates,
    nrmse,
    product_nrmse,
)
from pushtoknow.identification.prior import CATALOGUE_PRIOR, generator_prior
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.sim import PushRecord, stack_records, unstack_records

PRIOR = "prior-mean"
FOREST = "forest"
FOREST_VISNET = "forest-visnet"
ORACLE_KEY = "oracle"  # evaluation.identification.ORACLE
PHYSICS = "physics"  # the physics estimator (`common.estimators`), the prefix of its rows
BASELINES = (PRIOR, FOREST, FOREST_VISNET, ORACLE_KEY)  # the rows after the estimators'
RANDOM_SET = "random"
# The settings that define a set's rows: a kept row (`run_evaluation(keep=...)`) must have been
# computed under this run's; the random set's two only where the kept results have that set.
KEEP_KEYS = ("pushes", "seed", "folds", "heldout_objects", "novel_objects", "policies")
KEEP_KEYS += ("sigma_points",)
RANDOM_KEYS = ("random_objects", "random_seed")
NO_DATA = "no training data given (--data)"
ACTIVE = tuple(ACTIVE_POLICY_NAMES.values())  # they choose by the estimator's own information
INTERVAL_LEVEL = 0.9  # the interval every estimate reports (docs/DESIGN.md §2)
# What an inference-run cache holds and how its runs were drawn, part of its key: 2 holds each
# estimate's interval (lower, upper); 3 runs drew from the named random streams
# (`common.random`); 4 holds the pushes by field name (`PUSH_PREFIX`). A run cached under
# another format is recomputed, never read.
CACHE_FORMAT = 4
PUSH_PREFIX = "pushes_"  # a cached run's pushes: pushes_<stack_records name>


class EvaluationConfig(Config):
    """Settings of `run_evaluation`; loadable from YAML (`--config`)."""

    heldout_objects: int | None = Field(None, ge=1, description="None: all held-out objects")
    novel_objects: int = Field(20, ge=0)
    pushes: int = Field(5, ge=1)
    policies: tuple[str, ...] = POLICY_NAMES
    folds: int = Field(5, ge=2)
    seed: int = 0
    workers: int = Field(2, ge=1)
    sigma_points: int | None = Field(None, ge=MIN_SIGMA_POINTS)
    forest_trees: int = Field(200, ge=1)
    oracle: bool = Field(
        False,
        description="add the `oracle` row: physics-based identification on the pushes the first "
        "model made, with the true footprint and the simulator's own physics (an upper bound; "
        "about 40 s per object on 2 cores)",
    )
    physics_policies: tuple[PolicyName, ...] = Field(
        ("uniform",),
        description="policies the physics estimator (the simulator-in-the-loop filter, on the "
        "first model's perception) is evaluated under, rows `physics:<policy>`; () = none",
    )
    physics_sets: tuple[Literal["heldout", "novel", "random"], ...] | None = Field(
        None,
        description="the sets with `physics:<policy>` rows (None: every set); its replays take "
        "1–5 min per object on 2 cores",
    )
    random_objects: int = Field(
        0, ge=0, description="objects of the `random` set, random:<random_seed>:0..N-1; 0: none"
    )
    random_seed: int = Field(9001, ge=0, description="seed of the `random` set's shapes")


def product_relative_error(run: MethodRun, threshold: float = 0.02) -> dict:
    """|μ·m estimate / truth − 1| of the final estimates: median, max and the share within
    `threshold`."""
    truth = run.truth[:, 0] * run.truth[:, 1]
    final = (
        run.product[:, -1] if run.product is not None else run.mean[:, -1, 0] * run.mean[:, -1, 1]
    )
    rel = np.abs(final / truth - 1.0)
    return {
        "median": float(np.median(rel)),
        "max": float(np.max(rel)),
        f"share_within_{round(100 * threshold)}pct": float(np.mean(rel <= threshold)),
    }


def fold_indices(n: int, folds: int, seed: int) -> list[np.ndarray]:
    """`folds` disjoint index groups covering range(n), seeded."""
    if n < folds:
        raise ValueError(f"{n} objects cannot be split into {folds} folds; use fewer folds")
    perm = np.random.default_rng(seed).permutation(n)
    return [np.sort(g) for g in np.array_split(perm, folds)]


def summarise_method(
    run: MethodRun, folds: list[np.ndarray], footprints: list | None = None
) -> dict:
    """NRMSE of the final estimate (mean ± std over folds, and over all objects), μ·m NRMSE,
    68%/90% coverage, NRMSE and 90% coverage after every push k = 0..K (all objects), how many
    of the N·(K+1) estimates report a mean outside their own interval (None where the run has
    no intervals), and, given the objects' true footprints, how many were physically
    impossible."""
    k_last = run.mean.shape[1] - 1
    m, t = run.mean[:, k_last], run.truth
    prod = None if run.product is None else run.product[:, k_last]
    per_fold = [nrmse(m[g], t[g]) for g in folds]
    keys = [*PARAM_NAMES, "overall"]
    z = run.zscores(k_last)
    cov68, cov90 = coverage(z, 0.68), coverage(z, 0.9)
    per_push = []
    for k in range(k_last + 1):
        p = None if run.product is None else run.product[:, k]
        row = nrmse(run.mean[:, k], t)
        row["mu_m"] = product_nrmse(run.mean[:, k], t, p)
        row["coverage90"] = coverage(run.zscores(k), 0.9)
        per_push.append(row)
    fold_mu_m = [product_nrmse(m[g], t[g], None if prod is None else prod[g]) for g in folds]
    return {
        "nrmse": {k: float(np.mean([f[k] for f in per_fold])) for k in keys},
        "nrmse_std": {k: float(np.std([f[k] for f in per_fold])) for k in keys},
        "nrmse_all": nrmse(m, t),
        "mu_m": float(np.mean(fold_mu_m)),
        "mu_m_std": float(np.std(fold_mu_m)),
        "coverage68": cov68["overall"],
        "coverage90": cov90["overall"],
        "coverage68_per_param": cov68,
        "coverage90_per_param": cov90,
        "per_push": per_push,
        "objects": len(t),
        "seconds_per_object": run.seconds_per_object,
        "estimates": int(run.mean.shape[0] * run.mean.shape[1]),
        "impossible_estimates": None
        if footprints is None
        else impossible_estimates(run.mean, footprints),
        "outside_interval": None
        if run.lower is None or run.upper is None
        else estimates_outside_interval(run.mean, run.lower, run.upper),
        "profile_share": None if run.profiles is None else profile_share(run.profiles),
    }


def profile_share(profiles: list[list[str]]) -> dict[str, float]:
    """Share of the pushes (over objects and pushes) executed with each speed profile."""
    flat = [p for row in profiles for p in row]
    return {p: flat.count(p) / len(flat) for p in sorted(set(flat))} if flat else {}


def heldout_object_refs(n: int | None) -> list[str]:
    """The held-out catalogue objects (`catalogue_split` test IDs); n of them taken round-robin
    over the shapes, so a subset keeps every shape (None: all)."""
    from pushtoknow.testbed.objects import build_catalogue, catalogue_split

    test = catalogue_split()[1]
    objects = build_catalogue().objects
    by_shape: dict[str, list[int]] = {}
    for i in test:
        by_shape.setdefault(objects[i].shape, []).append(i)
    order = [
        ids[j]
        for j in range(max(map(len, by_shape.values())))
        for ids in by_shape.values()
        if j < len(ids)
    ]
    return [f"catalogue:{i}" for i in (order if n is None else order[:n])]


def novel_object_refs(n: int, seed: int) -> list[str]:
    from pushtoknow.testbed.objects import novel_objects

    return [o.to_json() for o in novel_objects(n, seed)]


def random_object_refs(n: int, seed: int) -> list[str]:
    """`random:SEED:I` for I < n (`testbed.random_shapes`; object I does not depend on n)."""
    return [f"random:{seed}:{i}" for i in range(n)]


def _object_id(ref: str, spec) -> str:
    """The id a run reports for `ref` (`heldout._run_one`): a spec string's name, else the ref."""
    return spec.name if ref.lstrip().startswith("{") else ref


def _cache_key(
    model: Path,
    policy: str,
    objects: list[str],
    cfg: EvaluationConfig,
    profiles: tuple[str, ...],
    estimator: str = LEARNED_ESTIMATOR,
    push_actions: np.ndarray | None = None,
) -> str:
    """The key of a cached inference run: the checkpoint's bytes, the settings, and the code
    that turns every estimator's belief into its reported numbers (`common.estimate`) and
    decides when each is reported (`inference.session`): a changed report must not reuse old
    runs. The physics estimator's adds its name, the code of the filter and of its perception,
    and the pushes it replayed."""
    h = hashlib.sha256()
    ckpt = Path(model) / "model.pt" if Path(model).is_dir() else Path(model)
    # the checkpoint's bytes, not its path: a retrained model at the same path must not reuse
    # the previous model's runs
    h.update(ckpt.read_bytes() if ckpt.is_file() else str(model).encode())
    settings = [policy, cfg.pushes, cfg.seed, cfg.sigma_points, objects, list(profiles)]
    settings.append({"format": CACHE_FORMAT})
    from pushtoknow.common import estimate
    from pushtoknow.inference import session

    for module in (estimate, session):
        h.update(Path(module.__file__).read_bytes())
    if estimator != LEARNED_ESTIMATOR:
        settings.append({"estimator": estimator})
        if estimator == PHYSICS:
            from pushtoknow.identification import (
                fit,
                optimise,
                prior,
                recursive,
                replay,
                residuals,
            )
            from pushtoknow.inference import physics_filter
            from pushtoknow.perception import footprint, registration

            filter_code = (physics_filter, recursive, optimise, residuals, replay, fit, prior)
            for module in (*filter_code, footprint, registration):
                h.update(Path(module.__file__).read_bytes())
    if push_actions is not None:
        h.update(np.ascontiguousarray(push_actions, dtype=np.float64).tobytes())
    h.update(json.dumps(settings).encode())
    return h.hexdigest()[:16]


def _save_npz(path: Path, **arrays) -> None:
    """Write `arrays` to `path` atomically: a half-written cache is never read."""
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(".tmp.npz")
    np.savez(tmp, **arrays)
    os.replace(tmp, path)


def _save_run(path: Path, key: str, run: HeldoutRun) -> None:
    _save_npz(
        path,
        key=key,
        mean=run.mean,
        std=run.std,
        zscore=run.zscore,
        product=run.product,
        truth=run.truth,
        ids=np.array(run.ids),
        seconds=np.array(run.seconds),
        features_truth=run.features_truth,
        features_vision=run.features_vision,
        profiles=np.array(run.profiles),
        **(
            {}
            if run.pushes is None
            else {f"{PUSH_PREFIX}{k}": v for k, v in stack_records(run.pushes).items()}
        ),
        **({} if run.lower is None else {"lower": run.lower, "upper": run.upper}),
    )


def _load_npz(path: Path, key: str) -> dict[str, np.ndarray] | None:
    """The arrays `_save_npz` wrote to `path`, or None when absent or written under another key."""
    if not path.exists():
        return None
    with np.load(path) as f:
        return dict(f) if str(f["key"]) == key else None


def _cached_pushes(arrays: dict[str, np.ndarray]) -> list[list[PushRecord]] | None:
    """The pushes `_save_run` stored (`PUSH_PREFIX` + `stack_records`' names), or None."""
    n = len(PUSH_PREFIX)
    stacked = {k[n:]: v for k, v in arrays.items() if k.startswith(PUSH_PREFIX)}
    return unstack_records(stacked) if stacked else None


def _load_run(path: Path, key: str) -> HeldoutRun | None:
    f = _load_npz(path, key)
    if f is None:
        return None
    return HeldoutRun(
        mean=f["mean"],
        std=f["std"],
        zscore=f["zscore"],
        product=f["product"],
        truth=f["truth"],
        ids=[str(i) for i in f["ids"]],
        seconds=f["seconds"].tolist(),
        features_truth=f["features_truth"],
        features_vision=f["features_vision"],
        profiles=f["profiles"].tolist(),
        pushes=_cached_pushes(f),
        lower=f.get("lower"),  # absent from a cache without intervals: None, never guessed
        upper=f.get("upper"),
    )


def _inference_run(
    model: Path,
    policy: str,
    objects: list[str],
    cfg: EvaluationConfig,
    profiles: tuple[str, ...],
    cache: Path,
    progress,
    need_pushes: bool = False,
    workers: Workers = 1,
    estimator: str = LEARNED_ESTIMATOR,
    push_actions: np.ndarray | None = None,
) -> HeldoutRun:
    """The model's run under `policy` on `objects`, from `cache` when it holds the same run (and
    its pushes, when `need_pushes`: the oracle replays them); `estimator`: the learned
    filter or the physics one (on the model's perception); `push_actions` (N, K, 5): another
    run's pushes, executed instead of the policy's choices."""
    key = _cache_key(model, policy, objects, cfg, profiles, estimator, push_actions)
    cached = _load_run(cache, key)
    if cached is not None and not (need_pushes and cached.pushes is None):
        return cached
    finished = cache.parent / f"{cache.stem}.{key}.finished"  # objects done so far
    run = evaluate_heldout(
        model,
        objects,
        cfg.pushes,
        policy,
        cfg.seed,
        workers,
        sigma_points=cfg.sigma_points,
        progress=progress,
        profiles=profiles,
        estimator=estimator,
        push_actions=push_actions,
        finished=finished,
    )
    _save_run(cache, key, run)
    shutil.rmtree(finished, ignore_errors=True)
    return run


def _oracle_run(
    base: HeldoutRun,
    objects: list[str],
    sim_config,
    seed: int,
    workers: Workers,
    progress,
    cache: Path,
) -> MethodRun:
    """The oracle row, from `cache` when it was computed on the same pushes (actions and
    recorded tracks), objects, seed, testbed settings and identification settings and code: it
    depends on nothing else."""
    from pushtoknow.evaluation.identification import oracle_run

    h = hashlib.sha256()
    for _, a in sorted(stack_records(base.pushes).items()):
        h.update(np.ascontiguousarray(a).tobytes())
    from pushtoknow.evaluation import identification
    from pushtoknow.identification import fit, optimise, replay, residuals

    # the code of the fit and of the row too: a changed algorithm must not reuse old rows
    for module in (fit, optimise, residuals, replay, identification):
        h.update(Path(module.__file__).read_bytes())
    identify_settings = identification.ORACLE_SETTINGS.model_dump(exclude={"workers"})
    h.update(
        json.dumps([objects, seed, sim_config.model_dump(mode="json"), identify_settings]).encode()
    )
    key = h.hexdigest()[:16]
    f = _load_npz(cache, key)
    if f is not None:
        return MethodRun(
            f["mean"],
            f["std"],
            f["truth"],
            [str(i) for i in f["ids"]],
            f["product"],
            float(f["seconds"]),
            f["zscore"],
            lower=f.get("lower"),
            upper=f.get("upper"),
        )
    run = oracle_run(base, objects, sim_config, seed, workers, progress)
    _save_npz(
        cache,
        key=key,
        mean=run.mean,
        std=run.std,
        truth=run.truth,
        ids=np.array(run.ids),
        product=run.product,
        seconds=np.array(run.seconds_per_object),
        zscore=run.zscore,
        **({} if run.lower is None else {"lower": run.lower, "upper": run.upper}),
    )
    return run


def gaussian_run(mean: np.ndarray, std: np.ndarray, truth: np.ndarray, ids: list[str]) -> MethodRun:
    """The run of a method whose estimates are Gaussian in SI (the forest, the prior mean):
    its intervals are mean ± z·std at `INTERVAL_LEVEL`, symmetric, so no mean lies outside its
    own (the count is computed all the same, as for every method)."""
    z = float(norm.ppf(0.5 + INTERVAL_LEVEL / 2))
    return MethodRun(mean, std, truth, ids, lower=mean - z * std, upper=mean + z * std)


def _forest_run(forest: ForestBaseline, features: np.ndarray, base: HeldoutRun, prior) -> MethodRun:
    """Forest estimates after k = 0..K pushes (k = 0: the prior mean) on base's pushes."""
    means, stds = [], []
    p_mean, p_std = prior.predict(1)
    for f in features:
        m, s = forest.predict_object(f)
        means.append(np.concatenate([p_mean, m]))
        stds.append(np.concatenate([p_std, s]))
    return gaussian_run(np.stack(means), np.stack(stds), base.truth, base.ids)


def _variant_names(loaded: list, paths: Sequence[str | Path] | None = None) -> list[str]:
    """Method-name prefixes of the models: the variant, suffixed by the model structure
    (`LearnedModelsConfig.label`) when it differs from the first model's ("vt-addf-black-box");
    a name already taken becomes its run folder's (`paths`, the models as given; a model.pt's
    folder) when that is free, else the name suffixed by its position ("vt-addf#1")."""
    first = loaded[0].models_config.label
    names: list[str] = []
    for i, m in enumerate(loaded):
        structure = m.models_config.label
        v = m.variant if structure == first else f"{m.variant}-{structure}"
        if v in names and paths is not None:
            path = Path(paths[i])
            folder = (path.parent if path.suffix == ".pt" else path).name
            v = folder if folder and folder not in names else v
        names.append(v if v not in names else f"{v}#{len(names)}")
    return names


@dataclass(frozen=True)
class EvaluationResults:
    """What `run_evaluation` returns; `to_json()` is results.json.

    sets: per set ("heldout", "novel", "random", and a kept results' other sets) {"objects":
    object IDs, "folds": groups, "methods": {row: `summarise_method` summary, NRMSE
    dimensionless}, "notes": {row: why it is as it is}}; primary: the primary row
    (`<variant>:<first policy>`); config: the settings; data: the training data the forest and
    prior-mean rows were fitted on ({"path", "pushes", "objects"}; None: none); models: per
    model {"name", "path", "structure", "info"}; kept: {"from": results.json, "rows": {set:
    kept rows}} when rows were kept, else None; machine: `machine_description()`; figures:
    {figure: path}."""

    sets: dict[str, dict]
    primary: str
    config: EvaluationConfig
    data: dict | None
    models: list[dict]
    kept: dict | None
    machine: dict
    figures: dict[str, str]

    @property
    def methods(self) -> dict[str, dict]:
        """The held-out set's rows: {row: summary}."""
        return self.sets["heldout"]["methods"]

    def to_json(self) -> dict:
        """The results.json dict ("kept" only when rows were kept)."""
        out = {
            "sets": self.sets,
            "methods": self.methods,
            "primary": self.primary,
            "config": self.config.model_dump(mode="json"),
            "data": self.data,
            "models": self.models,
        }
        if self.kept is not None:
            out["kept"] = self.kept
        return out | {"machine": self.machine, "figures": self.figures}


def machine_description() -> dict:
    import torch

    return {
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "cpus": os.cpu_count(),
        "python": platform.python_version(),
        "torch": torch.__version__,
    }


def _method_run(run: HeldoutRun) -> MethodRun:
    return MethodRun(
        run.mean,
        run.std,
        run.truth,
        run.ids,
        run.product,
        float(np.median(run.seconds)),
        run.zscore,
        run.profiles,
        run.lower,
        run.upper,
    )


def _kept_results(keep: Path | None, cfg: EvaluationConfig) -> dict | None:
    """The results.json `keep` names, checked: a ConfigError (one line, naming the setting)
    when a setting that defines its rows differs from this run's."""
    if keep is None:
        return None
    try:
        kept = json.loads(Path(keep).read_text())
    except (OSError, ValueError) as e:
        raise ConfigError(keep, f"cannot read the results to keep: {e}") from None
    if not isinstance(kept, dict) or not isinstance(kept.get("sets"), dict):
        raise ConfigError(keep, "not a results.json of `pushtoknow evaluate` (no sets)")
    old, new = kept.get("config") or {}, cfg.model_dump(mode="json")
    keys = KEEP_KEYS + (RANDOM_KEYS if RANDOM_SET in kept["sets"] else ())
    for k in keys:
        was = old.get(k, EvaluationConfig.model_fields[k].default)
        was = list(was) if isinstance(was, tuple) else was
        if was != new[k]:
            raise ConfigError(
                keep,
                f"its rows were computed with {k} = {json.dumps(was)}, this run has "
                f"{json.dumps(new[k])}: make them equal or evaluate without --keep",
            )
    return kept


def _row_order(kept: list[str], computed: list[str]) -> list[str]:
    """A set's rows: the estimators' (kept ones first, in their order), then the baselines."""
    rows = kept + [k for k in computed if k not in kept]
    return [k for k in rows if k not in BASELINES] + [k for k in BASELINES if k in rows]


def _estimators_prior(truth: np.ndarray, ids: list[str], k1: int) -> MethodRun:
    """The prior-mean row without training data: the SI mean and std of the prior every
    estimator starts from (`identification.prior.prior_moments`, φ uniform over the catalogue
    ranges; log-normal moments for m, μ and I_z), the same for every object and push."""
    from pushtoknow.common.params import si_moments
    from pushtoknow.identification.prior import prior_moments

    mean, std = si_moments(*prior_moments())
    shape = (len(truth), k1, len(mean))
    return gaussian_run(np.broadcast_to(mean, shape).copy(), np.broadcast_to(std, shape).copy(),
                        truth, ids)  # fmt: skip


def run_evaluation(
    data: Path | None,
    models: list[Path],
    cfg: EvaluationConfig,
    out: Path,
    progress=None,
    echo=None,
    runner: TaskRunner | None = None,
    keep: Path | None = None,
) -> EvaluationResults:
    """Evaluate `models` (checkpoint paths; the first is the primary one), the physics estimator
    and the baselines on the held-out, novel and random sets; returns the results (also written
    to OUT/results.json). data: the training dataset the forest and the prior-mean row
    are fitted on (None: no forest rows, the estimators' prior as the prior-mean row);
    keep: a results.json whose rows are kept, not recomputed (module doc; ConfigError when
    its settings differ). progress(description, total) → advance callable; echo(str) for
    status lines; runner: where the objects run (default: `cfg.workers` local processes)."""
    from pushtoknow.models.checkpoint import load_checkpoint

    if not models:
        raise ValueError("evaluate needs at least one model (--models)")
    for field, policies in (("policies", cfg.policies), ("physics_policies", cfg.physics_policies)):
        unknown = [p for p in policies if p not in POLICY_NAMES]
        if unknown or (field == "policies" and not policies):
            raise ValueError(f"unknown {field} {unknown}; choose from {list(POLICY_NAMES)}")
    kept = _kept_results(keep, cfg)  # before any work
    say = echo or (lambda _: None)
    sets = {"heldout": heldout_object_refs(cfg.heldout_objects)}
    if cfg.novel_objects:
        sets["novel"] = novel_object_refs(cfg.novel_objects, cfg.seed)
    if cfg.random_objects:
        sets[RANDOM_SET] = random_object_refs(cfg.random_objects, cfg.random_seed)
    if missing := sorted(set(cfg.physics_sets or ()) - set(sets)):
        raise ConfigError("physics_sets", f"{missing}: sets this evaluation does not make")
    specs = {name: [load_object_spec(o) for o in objects] for name, objects in sets.items()}
    kept_sets = {} if kept is None else kept["sets"]
    for set_name, objects in sets.items():
        ids = [_object_id(o, s) for o, s in zip(objects, specs[set_name])]
        if set_name in kept_sets and kept_sets[set_name].get("objects") != ids:
            raise ConfigError(keep, f"sets.{set_name}.objects are not this run's objects")
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    workers: Workers = runner if runner is not None else cfg.workers
    loaded = [load_checkpoint(m) for m in models]  # CheckpointError before any work
    names = _variant_names(loaded, models)

    forest = prior = None
    data_info = None if kept is None else kept.get("data")
    if data is not None:
        say(f"forest: features of the training pushes in {data}")
        X, Y, obj, _ = features_from_dataset(data)
        forest = ForestBaseline(ForestConfig(n_estimators=cfg.forest_trees, seed=cfg.seed))
        forest = forest.fit(X, Y)
        _, first = np.unique(obj, return_index=True)
        prior = PriorMeanPredictor().fit(Y[first])
        data_info = {"path": str(data), "pushes": int(len(X)), "objects": int(len(first))}

    results_sets: dict[str, dict] = {}
    runs_for_figures: dict[str, dict[str, MethodRun]] = {}
    kept_rows: dict[str, list[str]] = {}
    k1 = cfg.pushes + 1
    base_policy = cfg.policies[0]
    for set_name, objects in sets.items():
        old_set = kept_sets.get(set_name, {})
        old = old_set.get("methods", {})
        n = len(objects)
        n_folds = min(cfg.folds, n)
        folds = fold_indices(n, n_folds, cfg.seed)
        footprints = [s.footprint for s in specs[set_name]]
        truth = np.stack([s.params.as_array() for s in specs[set_name]])
        ids = [_object_id(o, s) for o, s in zip(objects, specs[set_name])]
        # a kept row keeps its note; a recomputed row's old note would describe another run
        notes = {k: v for k, v in old_set.get("notes", {}).items() if k in old}
        need_oracle = cfg.oracle and ORACLE_KEY not in old
        need_forest = forest is not None and not {FOREST, FOREST_VISNET} <= set(old)
        methods: dict[str, MethodRun] = {}
        base: HeldoutRun | None = None
        learned: dict[str, HeldoutRun] = {}  # the first model's runs, by policy
        # the physics estimator's priors here other than the catalogue's (`generator_prior`)
        set_priors = {generator_prior(s.name) for s in specs[set_name]} - {CATALOGUE_PRIOR}
        wanted = sets if cfg.physics_sets is None else cfg.physics_sets
        physics = cfg.physics_policies if set_name in wanted else ()
        replays = [  # physics rows on the first model's pushes: their learned run is needed
            p for p in physics if f"{PHYSICS}:{p}" not in old and p not in ACTIVE
        ]

        rows = [
            (f"{name}:{policy}", model, policy, ckpt.profiles, LEARNED_ESTIMATOR)
            for i, (model, name, ckpt) in enumerate(zip(models, names, loaded))
            for policy in (cfg.policies if i == 0 else cfg.policies[:1])
        ]
        rows += [  # a learned run the physics rows replay but no row of this run's shows
            (f"{names[0]}:{p}", models[0], p, loaded[0].profiles, LEARNED_ESTIMATOR)
            for p in replays
            if p not in cfg.policies
        ]
        rows += [
            (f"{PHYSICS}:{policy}", models[0], policy, loaded[0].profiles, PHYSICS)
            for policy in physics
        ]
        for method, model, policy, profiles, estimator in rows:
            first = estimator == LEARNED_ESTIMATOR and method == f"{names[0]}:{policy}"
            # the first model's first-policy run: the forest and the oracle use its pushes
            is_base = first and policy == base_policy
            needed = (is_base and (need_oracle or need_forest)) or (first and policy in replays)
            if (method in old or method in methods) and not needed:
                continue
            given = None
            if estimator == PHYSICS and policy not in ACTIVE:
                given = learned[policy].push_actions  # the same pushes as the learned row's
            say(f"{set_name}: {method} on {n} objects ({', '.join(profiles)})")
            adv = progress(f"{set_name} {method}", n) if progress else None
            cache = out / "cache" / set_name / f"{method.replace(':', '_')}.npz"
            need_pushes = is_base and need_oracle
            args = (model, policy, objects, cfg, profiles, cache, adv, need_pushes, workers)
            run = _inference_run(*args, estimator=estimator, push_actions=given)
            if first:
                learned[policy] = run
            if is_base:
                base = run
            if method in old:  # computed for its pushes only: the kept row stays, checked
                new = summarise_method(_method_run(run), folds, footprints)["nrmse"]["overall"]
                was = old[method].get("nrmse", {}).get("overall", np.nan)
                if not np.isclose(new, was, rtol=1e-6, atol=0.0):
                    notes[method] = (
                        f"kept row; its run, recomputed here for its pushes, gives overall "
                        f"NRMSE {new:.4f}, not {was:.4f}"
                    )
                continue
            if policy not in cfg.policies and estimator == LEARNED_ESTIMATOR:
                continue  # run for the physics row's pushes only
            methods[method] = _method_run(run)
            said = [f"the pushes of {names[0]}:{policy}, replayed"] if given is not None else []
            said += [f"prior {r.label()}" for r in set_priors] if estimator == PHYSICS else []
            if said:
                notes[method] = "; ".join(said)
        if PRIOR not in old:
            if prior is not None:
                p_mean, p_std = prior.predict(n)
                methods[PRIOR] = gaussian_run(
                    np.repeat(p_mean[:, None], k1, 1), np.repeat(p_std[:, None], k1, 1), truth, ids
                )
                notes.pop(PRIOR, None)
            else:
                methods[PRIOR] = _estimators_prior(truth, ids, k1)
                notes[PRIOR] = (
                    "the estimators' prior (identification.prior.prior_moments: every parameter "
                    "uniform over its catalogue range), its SI mean and std; " + NO_DATA
                )
        if forest is not None:
            notes.pop(FOREST, None), notes.pop(FOREST_VISNET, None)
            if FOREST not in old:
                methods[FOREST] = _forest_run(forest, base.features_truth, base, prior)
            if FOREST_VISNET not in old:
                methods[FOREST_VISNET] = _forest_run(forest, base.features_vision, base, prior)
        else:
            for k in (FOREST, FOREST_VISNET):
                if k not in old:
                    notes[k] = NO_DATA
        figure_methods = dict(methods)
        if need_oracle:
            from pushtoknow.evaluation.identification import ORACLE

            say(f"{set_name}: {ORACLE} (physics-based identification) on {n} objects")
            adv = progress(f"{set_name} {ORACLE}", n) if progress else None
            methods[ORACLE] = _oracle_run(
                base,
                objects,
                loaded[0].sim_config,
                cfg.seed,
                workers,
                adv,
                out / "cache" / set_name / f"{ORACLE}.npz",
            )
        summaries = {k: summarise_method(r, folds, footprints) for k, r in methods.items()}
        if ORACLE_KEY in methods:
            summary = summaries[ORACLE_KEY]
            summary["upper_bound"] = True
            summary["label"] = (
                "upper bound: the simulator's own physics, the true footprint, the same pushes; "
                "final estimate only (per_push: prior, after all pushes)"
            )
            summary["mu_m_relative_error"] = product_relative_error(methods[ORACLE_KEY])
        if PRIOR in summaries and prior is None:
            summaries[PRIOR]["label"] = notes[PRIOR]
        if old:
            kept_rows[set_name] = list(old)
        entry = {k: v for k, v in old_set.items() if k not in ("methods", "notes")}
        entry.update(
            {"objects": old_set.get("objects", ids), "folds": old_set.get("folds", n_folds)}
        )
        entry["methods"] = {
            k: old[k] if k in old else summaries[k] for k in _row_order(list(old), list(summaries))
        }
        if notes:
            entry["notes"] = notes
        results_sets[set_name] = entry
        runs_for_figures[set_name] = figure_methods
    for set_name, s in kept_sets.items():  # sets this run does not define: kept as they are
        if set_name not in results_sets:
            results_sets[set_name] = s
            kept_rows[set_name] = list(s.get("methods", {}))
    primary_name = f"{names[0]}:{base_policy}"
    current = [
        {"name": n, "path": str(m), "structure": c.models_config.label, "info": c.info}
        for n, m, c in zip(names, models, loaded)
    ]
    by_name = {m["name"]: m for m in current}
    old_models = [] if kept is None else kept.get("models", [])
    primary = _primary_run(
        runs_for_figures,
        primary_name,
        models[0],
        loaded[0].profiles,
        sets["heldout"],
        cfg,
        out,
    )
    held = results_sets["heldout"]["methods"]
    results = EvaluationResults(
        sets=results_sets,
        primary=primary_name,
        config=cfg,
        data=data_info,
        models=[by_name.pop(m["name"], m) for m in old_models] + list(by_name.values()),
        kept=None if kept is None else {"from": str(keep), "rows": kept_rows},
        machine=machine_description(),
        figures=write_figures(held, primary, models, names, cfg, out / "figures"),
    )
    tmp = out / "results.json.tmp"
    tmp.write_text(json.dumps(results.to_json(), indent=1, default=_json_default))
    os.replace(tmp, out / "results.json")
    return results


def _primary_run(runs, name, model, profiles, objects, cfg, out) -> MethodRun | None:
    """The primary method's held-out run, for the figures: this run's, else its cached one (a
    kept row is not recomputed for a figure), else None."""
    if name in runs.get("heldout", {}):
        return runs["heldout"][name]
    cache = out / "cache" / "heldout" / f"{name.replace(':', '_')}.npz"
    policy = name.split(":")[-1]
    run = _load_run(cache, _cache_key(model, policy, objects, cfg, profiles))
    if run is None:
        return None
    return MethodRun(run.mean, run.std, run.truth, run.ids, run.product, zscore=run.zscore)


def _json_default(o):
    if isinstance(o, np.generic):
        return o.item()
    if isinstance(o, np.ndarray):
        return o.tolist()
    if isinstance(o, Path):
        return str(o)
    raise TypeError(f"not JSON serialisable: {type(o).__name__}")


def _run_dir(model: Path) -> Path:
    model = Path(model)
    return model.parent if model.is_file() else model


def write_figures(
    held: dict[str, dict],
    primary: MethodRun | None,
    models: list[Path],
    names: list[str],
    cfg: EvaluationConfig,
    out: Path,
) -> dict[str, str]:
    """Fig. 5 (estimates vs push number, first held-out object, primary method), Fig. 4a
    (learning curves of the models' end-to-end validation), NRMSE vs pushes per method (every
    held-out row that reports each push: `held`, the set's summaries), and the calibration plot
    of the primary method; fig. 5 and the calibration only given the primary run (`primary`;
    None: a kept row whose run is not at hand). Returns {figure: path}."""
    from pushtoknow.reporting import figures as F

    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    if primary is not None:
        paths["fig5_estimates"] = str(
            F.plot_estimates_vs_push(
                primary.mean[0],
                primary.std[0],
                primary.truth[0],
                out / "fig5_estimates.png",
                title=f"{names[0]}:{cfg.policies[0]} on {primary.ids[0]}",
            )
        )
    # Fig. 4a: validation curves of each model's training stages (supervised warm-up: process
    # NLL, common to all variants; end to end: parameter RMSE after a push, where it ran)
    stages = (
        ("fig4a_supervised", "supervised.csv", "val_process_nll", "validation process NLL"),
        ("fig4a_end_to_end", "end_to_end.csv", "val_param_rmse_mean", "validation parameter RMSE"),
    )
    for fig, csv_name, column, ylabel in stages:
        curves = {}
        for m, n in zip(models, names):
            csv = _run_dir(m) / csv_name
            curve = F.read_curve(csv, "step", column) if csv.exists() else []
            if len(curve) > 1:
                curves[n] = curve
        if curves:
            paths[fig] = str(
                F.plot_learning_curves(
                    curves, out / f"{fig}.png", ylabel=ylabel, title=f"{csv_name[:-4]} stage"
                )
            )
    per_method = {}
    for method, summary in held.items():
        s = summary["per_push"]  # over all objects, whatever the folds
        if summary.get("upper_bound") or len(s) != cfg.pushes + 1:
            continue  # the oracle: final estimate only
        per_method[method] = {
            k: [(j, row[k], 0.0) for j, row in enumerate(s)] for k in [*PARAM_NAMES, "overall"]
        }
    paths["nrmse_vs_pushes"] = str(
        F.plot_nrmse_vs_pushes(per_method, out / "nrmse_vs_pushes.png", title="held-out objects")
    )
    if primary is not None:
        k_last = primary.mean.shape[1] - 1
        cal_path = out / "calibration.png"
        F.plot_calibration(primary.zscores(k_last), cal_path)
        paths["calibration"] = str(cal_path)
    return paths
