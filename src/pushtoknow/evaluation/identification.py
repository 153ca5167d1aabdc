"""Accuracy of physics-based identification on simulated objects (`pushtoknow identify-bench`).

Protocol: `novel_objects(n, seed)` (unseen shapes and catalogue shapes, continuous parameters,
the evaluation suite's novel set); on each, K pushes simulated without images
(`identification.synthetic.simulate_pushes`: inward-normal pushes, random placement, the
testbed's tactile noise, and white tracking noise on the pose samples, since the testbed records
exact poses), profiles taken in turn from `profiles` (constant, release, constant, ...); then
`identify` with the true footprint and the testbed's own physics. This is an upper bound for
any estimator on this testbed (the model is exact), not a like-for-like comparison with the
learned filters, which see images.

Reported: NRMSE per parameter of the posterior mean (`metrics.nrmse`, catalogue ranges), μ·m
relative error (median and worst), coverage of the 90% (and 68%) intervals from z-scores in the
normalised space where the belief is Gaussian, the directions reported as not identified,
median seconds and rollouts per object.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np

from pushtoknow.common.parallel import Workers
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.evaluation.metrics import MethodRun, coverage, nrmse, product_nrmse
from pushtoknow.identification.fit import LEVEL, identify
from pushtoknow.identification.identify_config import IdentifyConfig
from pushtoknow.identification.replay import ReplayScene, RolloutPool
from pushtoknow.identification.synthetic import add_tracking_noise, simulate_pushes
from pushtoknow.testbed.objects import novel_objects, resolve_shape
from pushtoknow.testbed.sim_config import SimConfig


def push_profiles(profiles: Sequence[str], pushes: int) -> list[str]:
    """The profile of each of `pushes` pushes: `profiles` in turn."""
    return [profiles[k % len(profiles)] for k in range(pushes)]


@dataclass(frozen=True)
class IdentificationBenchmark:
    """The result of `run_identification_benchmark` (`pushtoknow identify-bench`): the method;
    the settings (objects, pushes per object, the profile of each push, seed, pose_noise
    [position m, angle rad], workers); NRMSE of the posterior mean per parameter and "overall"
    (`nrmse`) and of μ·m (`mu_m_nrmse`); μ·m relative error {"median", "max",
    "share_within_2pct"}; 90% / 68% coverage per parameter and "overall"; how many objects
    each direction was not identified on (`unidentified`); poor fits (objects); seconds per
    object {"median", "max"}; rollouts per object {"median", "push_rollouts_median"}; the
    parameter names (SI order of the arrays); one row per object (`per_object`: "object",
    "truth" (5,) SI and `identify`'s result as a dict)."""

    method: str
    objects: int
    pushes: int
    profiles: list[str]
    seed: int
    pose_noise: list[float]
    nrmse: dict[str, float]
    mu_m_nrmse: float
    mu_m_relative_error: dict[str, float]
    coverage90: dict[str, float]
    coverage68: dict[str, float]
    unidentified: dict[str, int]
    poor_fits: int
    seconds_per_object: dict[str, float]
    rollouts_per_object: dict[str, float]
    workers: int
    parameters: list[str]
    per_object: list[dict]

    def to_json(self) -> dict:
        return asdict(self)


def run_identification_benchmark(
    objects: int,
    pushes: int,
    profiles: Sequence[str],
    seed: int = 0,
    config: IdentifyConfig | None = None,
    progress: Callable[[str], None] | None = None,
) -> IdentificationBenchmark:
    """Identify `objects` novel objects from `pushes` simulated pushes each; returns the
    summary (see the module docstring) and per-object rows (`IdentificationBenchmark`)."""
    cfg = config or IdentifyConfig()
    sim = SimConfig(render=False)
    specs = novel_objects(objects, seed)
    plan = push_profiles(profiles, pushes)
    rows, means, truths, zs, products = [], [], [], [], []
    with RolloutPool(cfg.workers) as pool:
        for i, spec in enumerate(specs):
            records = simulate_pushes(
                spec,
                plan,
                seed=seed * 1000 + i,
                config=sim,
                pose_noise=(cfg.position_noise, cfg.angle_noise),
            )
            scene = ReplayScene(resolve_shape(spec.shape), spec.height, sim)
            res = identify(records, scene, cfg, seed=seed, pool=pool)
            truth = spec.params.as_array()
            means.append(res.mean)
            truths.append(truth)
            zs.append(res.zscore(truth))
            products.append(res.mu_m)
            rows.append(
                {
                    "object": spec.name,
                    "truth": truth.tolist(),
                    **res.as_dict(),
                }
            )
            if progress is not None:
                progress(spec.name)
    mean, truth, z = np.array(means), np.array(truths), np.array(zs)
    prod = np.array(products)
    rel = np.abs(prod / (truth[:, 0] * truth[:, 1]) - 1.0)
    unidentified: dict[str, int] = {}
    for r in rows:
        for d in r["unidentified"]:
            unidentified[d] = unidentified.get(d, 0) + 1
    return IdentificationBenchmark(
        method="physics-based identification (upper bound: exact simulator, true footprint)",
        objects=objects,
        pushes=pushes,
        profiles=plan,
        seed=seed,
        pose_noise=[cfg.position_noise, cfg.angle_noise],
        nrmse=nrmse(mean, truth),
        mu_m_nrmse=product_nrmse(mean, truth, prod),
        mu_m_relative_error={
            "median": float(np.median(rel)),
            "max": float(np.max(rel)),
            "share_within_2pct": float(np.mean(rel <= 0.02)),
        },
        coverage90=coverage(z, 0.9),
        coverage68=coverage(z, 0.68),
        unidentified=unidentified,
        poor_fits=int(sum(r["poor_fit"] for r in rows)),
        seconds_per_object={
            "median": float(np.median([r["seconds"] for r in rows])),
            "max": float(np.max([r["seconds"] for r in rows])),
        },
        rollouts_per_object={
            "median": float(np.median([r["rollouts"] for r in rows])),
            "push_rollouts_median": float(np.median([r["push_rollouts"] for r in rows])),
        },
        workers=cfg.workers,
        parameters=list(PARAM_NAMES),
        per_object=rows,
    )


ORACLE = "oracle"
ORACLE_SETTINGS = IdentifyConfig()  # its rollouts run on the caller's `workers`


def oracle_run(
    base, objects: list[str], sim_config: SimConfig, seed: int, workers: Workers, progress
):
    """The `oracle` method of the evaluation suite: `identify` on the pushes the first model
    made (`base`: its HeldoutRun, with push tracks), the true footprint and the simulator's own
    physics. Returns a `metrics.MethodRun` of two rows per object: the prior and the estimate
    after all K pushes (fitting after every push would cost K times as much), each with its 90%
    interval (the prior's from the same log-normal / Gaussian marginals as its mean)."""
    from pushtoknow.common.estimate import estimate_from_belief
    from pushtoknow.common.params import normalise_params, product_moments
    from pushtoknow.identification.prior import prior_moments
    from pushtoknow.testbed.object_refs import load_object_spec

    cfg = ORACLE_SETTINGS
    sim = sim_config.model_copy(update={"render": False})
    z0, p0 = prior_moments()
    prior = estimate_from_belief(z0, p0, None, LEVEL)
    prod0 = product_moments(z0, p0)[0]
    means, stds, lowers, uppers, zs, prods, secs = [], [], [], [], [], [], []
    with RolloutPool(workers) as pool:
        for i, ref in enumerate(objects):
            spec = load_object_spec(ref)
            records = [r.tracks_only() for r in base.pushes[i]]  # copies: noise is added
            # the recorded poses are exact: the tracking noise the fit assumes is added, as in
            # `run_identification_benchmark`, so its χ² keeps its meaning (≈ 1 at the truth)
            add_tracking_noise(
                records,
                (cfg.position_noise, cfg.angle_noise),
                np.random.default_rng([seed, i]),
            )
            scene = ReplayScene(resolve_shape(spec.shape), spec.height, sim)
            res = identify(records, scene, cfg, seed=seed, pool=pool)
            truth = base.truth[i]
            z_prior = (normalise_params(truth) - z0) / np.sqrt(np.diagonal(p0))
            means.append([prior.mean, res.mean])
            stds.append([prior.std, res.std])
            lowers.append([prior.lower, res.lower])
            uppers.append([prior.upper, res.upper])
            zs.append([z_prior, res.zscore(truth)])
            prods.append([prod0, res.mu_m])
            secs.append(res.seconds)
            if progress is not None:
                progress()
    return MethodRun(
        np.array(means),
        np.array(stds),
        base.truth,
        base.ids,
        np.array(prods),
        float(np.median(secs)),
        np.array(zs),
        lower=np.array(lowers),
        upper=np.array(uppers),
    )
