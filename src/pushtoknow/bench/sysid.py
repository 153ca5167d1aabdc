"""MuJoCo's own system identification (`mujoco.sysid`) on the pushes of `bench estimator`:
`pushtoknow bench sysid`, a baseline row beside the physics estimator.

Each object is pushed exactly as `bench estimator --estimator physics --policy uniform` pushes
it (same seed, same random streams, same perception of each push's start pose, so the same
pushes: the physics estimator's perception runs, its belief update does not). The records
become `PushTrack`s (`identification.fit.tracks_from_records`: the noisy tactile force and the
simulator's pose track) and `identification.sysid_baseline.sysid_fit` fits φ from the prior
mean given the footprint, with the TRUE outline and height: the known-scene case (the physics
estimator traces its outline from the first image and tracks poses with VisNet).

Per object: |estimate − truth| / (catalogue range) per parameter, the truth's z-score under
sysid's covariance (normalised coordinates), whether sysid bounded each interval, μ·m's
relative error, the fit's wall time, evaluations (candidate φ) and rollouts (single pushes),
and the whole object's time (pushes simulated and perceived, and the fit). The summary pools
them like `bench estimator`'s (`evaluation.metrics.coverage` at 90%).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch

from pushtoknow.bench import machine_description, median_or_nan, pooled_accuracy
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.evaluation.metrics import param_ranges

SCENE_NOTE = (
    "known scene: sysid is given the true outline and height and the simulator's pose track "
    "(the physics estimator traces its outline in the first image and tracks poses with VisNet)"
)


@dataclass(frozen=True)
class SysidObjectRow:
    """One object: reference and name; fit_s: sysid's fit (s); object_s: the whole object (s,
    pushes simulated and perceived, and the fit); per parameter (PARAM_NAMES keys):
    error_norm |estimate − truth| / catalogue range, zscore of the truth (NaN without a
    covariance, 0 where the interval is unbounded), interval_bounded; mu_m_rel_error
    (estimate / truth − 1 of μ·m); estimate and truth (SI); sysid's evaluations, rollouts,
    iterations, reduced_chi2 and status; the profile of each push."""

    ref: str
    name: str
    fit_s: float
    object_s: float
    error_norm: dict[str, float]
    zscore: dict[str, float]
    interval_bounded: dict[str, bool]
    mu_m_rel_error: float
    estimate: dict[str, float]
    truth: dict[str, float]
    evaluations: int
    rollouts: int
    iterations: int
    reduced_chi2: float
    status: str
    profiles_chosen: list[str]


@dataclass(frozen=True)
class SysidSummary:
    """Pooled over the objects: fit_s_median, object_s_median (s); evaluations_median;
    error_norm_mean per parameter and error_norm_overall (the mean of the five);
    mu_m_rel_error_mean_abs; coverage90 per parameter (share of objects with |z| ≤ 1.645, an
    unbounded interval counting as covering); unbounded_intervals (object × parameter pairs)."""

    objects: int
    fit_s_median: float
    object_s_median: float
    evaluations_median: float
    error_norm_mean: dict[str, float]
    error_norm_overall: float
    mu_m_rel_error_mean_abs: float
    coverage90: dict[str, float]
    unbounded_intervals: int


@dataclass(frozen=True)
class SysidBench:
    """The report of `bench_sysid` (`to_json()` is what `--json` prints)."""

    method: str
    scene: str
    pushes: int
    profiles: tuple[str, ...]
    policy: str
    seed: int
    max_iterations: int
    fd_step: float
    threads: int
    cpu_count: int
    load_average_1min_at_start: float | None
    machine: str
    objects: list[SysidObjectRow]
    summary: SysidSummary

    def to_json(self) -> dict:
        d = asdict(self)
        d["profiles"] = list(self.profiles)
        return d


def summarise(rows: Sequence[SysidObjectRow]) -> SysidSummary:
    """Pool rows into the summary (see `SysidSummary`); NaN where there is nothing to pool."""
    error_mean, overall, covered = pooled_accuracy(rows)
    return SysidSummary(
        objects=len(rows),
        fit_s_median=median_or_nan([r.fit_s for r in rows]),
        object_s_median=median_or_nan([r.object_s for r in rows]),
        evaluations_median=median_or_nan([r.evaluations for r in rows]),
        error_norm_mean=error_mean,
        error_norm_overall=overall,
        mu_m_rel_error_mean_abs=float(np.mean([abs(r.mu_m_rel_error) for r in rows]))
        if rows
        else float("nan"),
        coverage90=covered,
        unbounded_intervals=sum(not r.interval_bounded[p] for r in rows for p in PARAM_NAMES),
    )


def object_row(ref: str, name: str, truth, fit, object_s: float, profiles) -> SysidObjectRow:
    """A row from a `SysidResult` `fit` against `truth` (5,) SI."""
    truth = np.asarray(truth, dtype=np.float64)
    error = np.abs(fit.estimate - truth) / param_ranges()
    z = fit.zscore(truth)
    bounded = np.isfinite(fit.lower) if fit.lower is not None else np.zeros(len(PARAM_NAMES), bool)

    def per(values, cast):
        return {p: cast(v) for p, v in zip(PARAM_NAMES, values, strict=True)}

    return SysidObjectRow(
        ref=ref,
        name=name,
        fit_s=float(fit.seconds),
        object_s=float(object_s),
        error_norm=per(error, float),
        zscore=per(z, float),
        interval_bounded=per(bounded, bool),
        mu_m_rel_error=float(fit.mu_m / (truth[0] * truth[1]) - 1.0),
        estimate=per(fit.estimate, float),
        truth=per(truth, float),
        evaluations=fit.evaluations,
        rollouts=fit.rollouts,
        iterations=fit.iterations,
        reduced_chi2=float(fit.reduced_chi2),
        status=fit.status,
        profiles_chosen=list(profiles),
    )


def bench_pushes(model, spec, pushes: int, profiles: tuple[str, ...], seed: int) -> list:
    """The `PushRecord`s `bench estimator --estimator physics --policy uniform` executes on
    `spec` (its `infer_simulated` run with the physics estimator's perception, without its
    belief update)."""
    from pushtoknow.common.random import stream_seed
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.inference.physics_filter import PhysicsFilterEstimator

    class PerceptionOnly(PhysicsFilterEstimator):
        """The physics estimator's start poses (VisNet), whose update only perceives."""

        def update(self, record, view, pose0):
            return self.perceive(record, view, pose0)

    config = InferenceConfig(
        pushes=pushes, estimator="physics", profiles=tuple(profiles), policy="uniform"
    )
    est = PerceptionOnly(model, config, stream_seed(seed, "estimator"))
    try:
        return infer_simulated(model, spec, config, seed, estimator=est).records
    finally:
        est.close()


def bench_sysid(
    model,
    objects: list[str],
    pushes: int,
    profiles: tuple[str, ...],
    seed: int = 0,
    max_iterations: int = 30,
    threads: int | None = None,
    fd_step: float | None = None,
    on_object: Callable[[int, SysidObjectRow], None] | None = None,
) -> SysidBench:
    """mujoco.sysid on each object reference (``random:SEED:I``, ``catalogue:ID``, …), pushed
    `pushes` times among `profiles` as `bench estimator` pushes it with the physics estimator
    and the uniform policy (seed `seed`), fitted with the true outline (module doc). `model`:
    a `models.checkpoint.TrainedModel` (testbed settings, camera, VisNet). threads: sysid's
    rollout threads and torch's intra-op threads (None: one per core), restored afterwards;
    fd_step: sysid's finite-difference step (None: `sysid_baseline.FD_STEP`).
    Every reference is resolved first (a bad one raises `ObjectSpecError` at once)."""
    from pushtoknow.identification.fit import tracks_from_records
    from pushtoknow.identification.replay import ReplayScene
    from pushtoknow.identification.sysid_baseline import (
        FD_STEP,
        start_phi,
        sysid_fit,
        sysid_module,
    )
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.testbed.objects import resolve_shape

    sysid_module()  # a missing dependency fails before any push
    specs = [load_object_spec(ref) for ref in objects]
    sim_config = model.sim_config
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    n_threads = threads or os.cpu_count() or 1
    previous = torch.get_num_threads()
    torch.set_num_threads(n_threads)
    rows: list[SysidObjectRow] = []
    try:
        for i, (ref, spec) in enumerate(zip(objects, specs, strict=True)):
            t0 = time.perf_counter()
            records = bench_pushes(model, spec, pushes, profiles, seed)
            tracks = tracks_from_records(records, sim_config)
            scene = ReplayScene(
                resolve_shape(spec.shape),
                spec.height,
                sim_config.model_copy(update={"render": False}),
            )
            fit = sysid_fit(
                scene,
                tracks,
                start_phi(scene),
                max_iterations=max_iterations,
                fd_step=fd_step or FD_STEP,
                threads=n_threads,
            )
            row = object_row(
                ref,
                spec.name or ref,
                spec.params.as_array(),
                fit,
                time.perf_counter() - t0,
                [r.push.profile for r in records],
            )
            rows.append(row)
            if on_object is not None:
                on_object(i, row)
    finally:
        torch.set_num_threads(previous)
    return SysidBench(
        method="mujoco.sysid: mujoco.minimize Levenberg-Marquardt from the prior mean given "
        "the footprint, no prior; intervals from sysid.calculate_intervals",
        scene=SCENE_NOTE,
        pushes=pushes,
        profiles=tuple(profiles),
        policy="uniform",
        seed=seed,
        max_iterations=max_iterations,
        fd_step=fd_step or FD_STEP,
        threads=n_threads,
        cpu_count=os.cpu_count() or 1,
        load_average_1min_at_start=load,
        machine=machine_description(),
        objects=rows,
        summary=summarise(rows),
    )
