"""Accuracy on held-out objects: K inference pushes on each, NRMSE after every push, coverage of
the intervals, the prior-mean predictor beside it (docs/DESIGN.md §9).

`pushtoknow evaluate-heldout` (and docs/RESULTS.md) use `evaluate_heldout`; objects are run in
parallel processes, each seeded by (seed, object id), so results do not depend on `workers`.
"""

from __future__ import annotations

import pickle
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pushtoknow.baselines.random_forest import features_from_records
from pushtoknow.common.files import atomic_write
from pushtoknow.common.parallel import Workers, runner_for
from pushtoknow.common.params import product_moments
from pushtoknow.evaluation.metrics import coverage, nrmse, product_nrmse
from pushtoknow.inference.policies import PushDecision, PushPolicy
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord

LEARNED_ESTIMATOR = "vt-addf"  # the estimator these runs use unless told (the paper's filter)


@dataclass
class HeldoutRun:
    """Per object (N) and push (K + 1, index 0 = the prior): mean (N, K+1, 5) SI,
    std (N, K+1, 5) SI, zscore (N, K+1, 5) of the truth in the belief's normalised space
    (`PushEstimate.zscore`), product (N, K+1) E[μ·m], truth (N, 5), ids (N,); lower, upper
    (N, K+1, 5) SI: each estimate's 90% interval (`PushEstimate.interval`), None in a run
    made before they were recorded."""

    mean: np.ndarray
    std: np.ndarray
    zscore: np.ndarray
    product: np.ndarray
    truth: np.ndarray
    ids: list[str]
    seconds: list[float]
    features_truth: np.ndarray | None = None  # (N, K, F) forest features, true poses
    features_vision: np.ndarray | None = None  # (N, K, F) forest features, filtered poses
    profiles: list[list[str]] | None = None  # (N, K) speed profile of each executed push
    pushes: list[list[PushRecord]] | None = None  # (N, K) executed pushes, without images
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    @property
    def push_actions(self) -> np.ndarray | None:
        """(N, K, 5) `Push.as_array` of each executed push (None without `pushes`)."""
        if self.pushes is None:
            return None
        return np.array([[r.push.as_array() for r in obj] for obj in self.pushes])


class ReplayPolicy(PushPolicy):
    """Executes the given pushes (K, 5) (`Push.as_array` rows) in order, whatever the candidates
    and the estimate: another run's pushes on the same object."""

    name = "replay"

    def __init__(self, actions: np.ndarray):
        self.pushes = [Push.from_array(a) for a in np.asarray(actions, dtype=np.float64)]

    def choose(self, decision: PushDecision) -> Push:
        return self.pushes[decision.k]


def _run_one(args) -> dict:
    import time

    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.testbed.object_refs import load_object_spec

    model_path, object_ref, pushes, policy, seed, sigma_points, profiles, *rest = args
    estimator = rest[0] if rest else LEARNED_ESTIMATOR
    given = rest[1] if len(rest) > 1 else None  # (K, 5) pushes to replay, or None
    t0 = time.perf_counter()
    import torch

    torch.set_num_threads(1)
    model = load_checkpoint(model_path)
    spec = load_object_spec(object_ref)
    cfg = InferenceConfig(
        estimator=estimator,
        pushes=pushes,
        policy=policy,
        num_sigma_points=sigma_points,
        profiles=profiles,
    )
    est = None
    if estimator == "physics":
        # objects are the parallel unit here: each physics filter replays in its own process
        from pushtoknow.common.random import stream_seed
        from pushtoknow.identification.prior import generator_prior
        from pushtoknow.identification.recursive import PhysicsFilterConfig
        from pushtoknow.inference.physics_filter import PhysicsFilterEstimator

        physics = PhysicsFilterConfig(workers=1, prior=generator_prior(spec.name))
        seed_est = stream_seed(seed, "estimator")
        est = PhysicsFilterEstimator(model, cfg, seed_est, filter_config=physics)
    try:
        replay = None if given is None else ReplayPolicy(given)
        res = infer_simulated(
            model, spec, cfg, seed, with_truth=False, policy=replay, estimator=est
        )
    finally:
        if est is not None:
            est.close()
    rows = [res.prior, *res.estimates]
    camera = model.camera
    poses = iter(res.poses)
    return {
        "features_truth": features_from_records(res.records, camera),
        "features_vision": features_from_records(
            res.records, camera, pose_fn=lambda _: np.asarray(next(poses), float)
        ),
        "id": spec.name if object_ref.lstrip().startswith("{") else object_ref,
        "ref": object_ref,
        "mean": np.stack([e.mean for e in rows]),
        "std": np.stack([e.std for e in rows]),
        "lower": np.stack([e.interval()[0] for e in rows]),
        "upper": np.stack([e.interval()[1] for e in rows]),
        "zscore": np.stack([e.zscore(spec.params.as_array()) for e in rows]),
        "product": np.array([product_moments(e.mean_norm, e.cov_norm)[0] for e in rows]),
        "truth": spec.params.as_array(),
        "seconds": time.perf_counter() - t0,
        "profiles": [rec.push.profile for rec in res.records],
        "pushes": [rec.tracks_only() for rec in res.records],
    }


def heldout_object_ids(n: int, seed: int = 0) -> list[str]:
    """`catalogue:ID` of n held-out (test-split) catalogue objects, a seeded random order (the
    first n of the same permutation for every n)."""
    from pushtoknow.testbed.objects import catalogue_split

    test_ids = catalogue_split()[1]
    order = np.random.default_rng(seed).permutation(test_ids)
    return [f"catalogue:{i}" for i in order[: min(n, len(test_ids))]]


def evaluate_heldout(
    model_path,
    objects: list[str],
    pushes: int = 5,
    policy: str = "uniform",
    seed: int = 0,
    workers: Workers = 1,
    sigma_points: int | None = None,
    progress=None,
    profiles: tuple[str, ...] = ("constant",),
    estimator: str = LEARNED_ESTIMATOR,
    push_actions: np.ndarray | None = None,
    finished: Path | None = None,
) -> HeldoutRun:
    """Run inference on each object (`catalogue:ID` or spec strings) on `workers` (local
    processes or a `TaskRunner`); `profiles`: the speed profiles the policy may use
    (`InferenceConfig.profiles`); `estimator`: `InferenceConfig.estimator` (default: the
    learned filter, whatever `InferenceConfig`'s default). The run's seed depends on neither
    the estimator nor `workers`: the uniform and random policies make the same pushes for
    every estimator (their own random stream, `common.random`), but the uniform policy's choice
    depends on the estimator's orientation estimate (bearings in the object frame), so
    `push_actions` (N, K, 5), another run's pushes, makes the run execute exactly those pushes
    instead of the policy's (the policy's name is then a label). `finished`: a folder keeping
    each object's result as it finishes (`<index>.pkl`), read back instead of rerunning it, so
    a run stopped for any reason loses no finished object; the caller names one folder per
    run's settings and removes it once the whole run is saved. The physics estimator's prior
    is the one the testbed draws each object from (`identification.prior.generator_prior`)."""
    jobs = [
        (
            str(model_path),
            o,
            pushes,
            policy,
            seed * 100_003 + i,
            sigma_points,
            tuple(profiles),
            estimator,
            None if push_actions is None else np.asarray(push_actions[i], dtype=np.float64),
        )
        for i, o in enumerate(objects)
    ]
    done = _finished_objects(finished, [job[1] for job in jobs])
    todo = [i for i in range(len(jobs)) if i not in done]
    for _ in done if progress else ():
        progress()

    def on_done(j: int, result: dict) -> None:
        if finished is not None:
            atomic_write(finished / f"{todo[j]}.pkl", pickle.dumps(result))
        if progress:
            progress()

    if todo:
        with runner_for(workers) as runner:
            fresh = runner.map(_run_one, [jobs[i] for i in todo], on_done=on_done)
        done.update(zip(todo, fresh))
    out = [done[i] for i in range(len(jobs))]
    return HeldoutRun(
        mean=np.stack([r["mean"] for r in out]),
        std=np.stack([r["std"] for r in out]),
        zscore=np.stack([r["zscore"] for r in out]),
        product=np.stack([r["product"] for r in out]),
        truth=np.stack([r["truth"] for r in out]),
        ids=[r["id"] for r in out],
        seconds=[r["seconds"] for r in out],
        features_truth=np.stack([r["features_truth"] for r in out]),
        features_vision=np.stack([r["features_vision"] for r in out]),
        profiles=[r["profiles"] for r in out],
        pushes=[r["pushes"] for r in out],
        lower=np.stack([r["lower"] for r in out]),
        upper=np.stack([r["upper"] for r in out]),
    )


def _finished_objects(folder: Path | None, refs: list[str]) -> dict[int, dict]:
    """{index: result} of the objects of `refs` a stopped run of the same settings finished
    (`folder`'s `<index>.pkl`; a file that cannot be read, or holds another object, is run
    again)."""
    out: dict[int, dict] = {}
    if folder is None or not folder.is_dir():
        return out
    for i, ref in enumerate(refs):
        path = folder / f"{i}.pkl"
        if path.is_file():
            try:
                result = pickle.loads(path.read_bytes())
            except Exception:  # a damaged file: that object runs again
                continue
            if result.get("ref") == ref:
                out[i] = result
    return out


@dataclass(frozen=True)
class HeldoutMetrics:
    """The accuracy of a `HeldoutRun` (`heldout_metrics`): one row per push (`per_push`, K + 1,
    row 0 = the prior the filter starts from): {"push": index, NRMSE per parameter and
    "overall", "mu_m": NRMSE of μ·m, "coverage90" / "coverage68": {parameter and "overall":
    share of the truths inside the interval}}; the prior-mean predictor's NRMSE per parameter,
    "overall" and "mu_m" (`prior_mean`); the number of objects."""

    per_push: list[dict]
    prior_mean: dict[str, float]
    objects: int

    def to_json(self) -> dict:
        return asdict(self)


def heldout_metrics(run: HeldoutRun, prior_truth: np.ndarray | None = None) -> HeldoutMetrics:
    """NRMSE per parameter, overall and of μ·m, and 68%/90% coverage, after every push (index 0
    = the prior the filter starts from); `prior_mean` row: the prior-mean predictor, i.e. the
    training objects' mean (`prior_truth` (M, 5) SI; default: the filter's prior mean)."""
    k = run.mean.shape[1]
    per_push = []
    for j in range(k):
        m = run.mean[:, j]
        row = {"push": j, **nrmse(m, run.truth)}
        row["mu_m"] = product_nrmse(m, run.truth, run.product[:, j])
        row["coverage90"] = coverage(run.zscore[:, j], 0.9)
        row["coverage68"] = coverage(run.zscore[:, j], 0.68)
        per_push.append(row)
    if prior_truth is not None:
        prior_mean = np.asarray(prior_truth).mean(0)
    else:
        prior_mean = run.mean[0, 0]
    pm = np.tile(prior_mean, (len(run.truth), 1))
    prior_row = {**nrmse(pm, run.truth), "mu_m": product_nrmse(pm, run.truth)}
    return HeldoutMetrics(per_push=per_push, prior_mean=prior_row, objects=len(run.truth))
