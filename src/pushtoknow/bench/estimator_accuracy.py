"""Speed and accuracy of an estimator (docs/DESIGN.md §9) on simulated objects: `pushtoknow
bench estimator`. Speed targets live here, not in tests.

Each object is pushed K times by `inference.infer_simulated` (seeded by `seed`, the same for every
object), and the estimator's update after every push is timed (`InferenceResult.seconds`). Per
object: the update times, the whole run's wall time (simulation, rendering and perception
included), and the final estimate's |error| / (catalogue range of the parameter), its z-scores
and whether its mean lies inside its own 90% interval. The summary (`summarise`) pools them:
median and max seconds per update, median seconds per object, the mean normalised error per
parameter and overall (the mean of the five), the 90% coverage per parameter (|z| ≤ the
two-sided 90% quantile, 1.645) and the count of means outside their own interval (must be 0).
"""

from __future__ import annotations

import os
import time
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass, field

import numpy as np
import torch
from scipy.stats import norm

from pushtoknow.bench import machine_description, median_or_nan, pooled_accuracy
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.evaluation.metrics import param_ranges

Z90 = float(norm.ppf(0.95))  # two-sided 90% quantile of the standard normal, 1.645
DEFAULT_OBJECTS_SEED = 2026


def default_objects(n: int, seed: int = DEFAULT_OBJECTS_SEED) -> list[str]:
    """The bench's objects: ``random:SEED:0`` … ``random:SEED:N-1`` (`testbed.random_shapes`)."""
    return [f"random:{seed}:{i}" for i in range(n)]


@dataclass(frozen=True)
class ObjectRow:
    """One object's run: its reference and name, the wall time of each push's update
    (`update_s`, s) and of the whole run (`object_s`, s), and the final estimate per parameter
    (PARAM_NAMES keys): |mean − truth| / (catalogue range) (`error_norm`), the z-score of the
    truth (`zscore`), and whether the mean lies inside its own 90% interval
    (`mean_inside_interval`); the speed profile of each executed push (`profiles_chosen`: what
    an active policy picked); the single-push simulations each update ran (`replays`,
    `Estimator.replays`: the cost that does not vary with the host; zeros for the learned
    filter)."""

    ref: str
    name: str
    update_s: list[float]
    object_s: float
    error_norm: dict[str, float]
    zscore: dict[str, float]
    mean_inside_interval: dict[str, bool]
    profiles_chosen: list[str]
    replays: list[int] = field(default_factory=list)


@dataclass(frozen=True)
class EstimatorSummary:
    """Pooled over the objects (`summarise`): update_s_median and update_s_max over every
    update of every object; object_s_median over the objects' whole runs; error_norm_mean per
    parameter and error_norm_overall (the mean of the five); coverage90 per parameter (the
    share of objects with |z| ≤ 1.645); means_outside_interval (object × parameter pairs whose
    mean lies outside its own 90% interval; must be 0); updates (how many were timed);
    replays_median over every update and replays_object_median over the objects' sums (the
    work behind the seconds, the same on every host)."""

    objects: int
    updates: int
    update_s_median: float
    update_s_max: float
    object_s_median: float
    replays_median: float
    replays_object_median: float
    error_norm_mean: dict[str, float]
    error_norm_overall: float
    coverage90: dict[str, float]
    means_outside_interval: int


@dataclass(frozen=True)
class EstimatorBench:
    """The report of `bench_estimator`: the settings, the machine (description, CPU count,
    torch's intra-op threads, 1-minute load average at the start, None where unknown), one
    `ObjectRow` per object and the `EstimatorSummary`. `to_json()` is what `--json` prints."""

    estimator: str
    pushes: int
    profiles: tuple[str, ...]
    policy: str
    seed: int
    cpu_count: int
    torch_threads: int
    load_average_1min_at_start: float | None
    machine: str
    objects: list[ObjectRow]
    summary: EstimatorSummary

    def to_json(self) -> dict:
        d = asdict(self)
        d["profiles"] = list(self.profiles)
        return d


def summarise(rows: Sequence[ObjectRow]) -> EstimatorSummary:
    """Pool per-object rows into the summary (see `EstimatorSummary`); NaN where there is
    nothing to pool."""
    updates = [s for r in rows for s in r.update_s]
    error_mean, overall, covered = pooled_accuracy(rows)
    outside = sum(not r.mean_inside_interval[p] for r in rows for p in PARAM_NAMES)
    return EstimatorSummary(
        objects=len(rows),
        updates=len(updates),
        update_s_median=median_or_nan(updates),
        update_s_max=float(max(updates)) if updates else float("nan"),
        object_s_median=median_or_nan([r.object_s for r in rows]),
        replays_median=median_or_nan([n for r in rows for n in r.replays]),
        replays_object_median=median_or_nan([sum(r.replays) for r in rows]),
        error_norm_mean=error_mean,
        error_norm_overall=overall,
        coverage90=covered,
        means_outside_interval=int(outside),
    )


def object_row(ref: str, result, object_s: float) -> ObjectRow:
    """An `ObjectRow` from an `inference.InferenceResult` with its truth (the final estimate
    is judged)."""
    final = result.estimates[-1]
    truth = np.asarray(result.truth, dtype=np.float64)
    error = np.abs(np.asarray(final.mean) - truth) / param_ranges()
    z = np.asarray(final.zscore(truth))
    lo, hi = final.interval()
    inside = (np.asarray(lo) <= final.mean) & (final.mean <= np.asarray(hi))
    return ObjectRow(
        ref=ref,
        name=result.object_name,
        update_s=[float(s) for s in result.seconds],
        object_s=float(object_s),
        error_norm={p: float(v) for p, v in zip(PARAM_NAMES, error, strict=True)},
        zscore={p: float(v) for p, v in zip(PARAM_NAMES, z, strict=True)},
        mean_inside_interval={p: bool(v) for p, v in zip(PARAM_NAMES, inside, strict=True)},
        profiles_chosen=[r.push.profile for r in result.records],
        replays=[int(n) for n in result.replays],
    )


def bench_estimator(
    model,
    estimator: str,
    objects: list[str],
    pushes: int,
    profiles: tuple[str, ...],
    policy: str = "uniform",
    seed: int = 0,
    on_object: Callable[[int, ObjectRow], None] | None = None,
    on_push: Callable[[int, object], None] | None = None,
    threads: int | None = None,
) -> EstimatorBench:
    """Run `estimator` ("vt-addf" or "physics") with `model` (a `models.checkpoint`
    TrainedModel) on each object reference (``random:SEED:I``, ``catalogue:ID``, …) for `pushes`
    pushes chosen by `policy` among `profiles`, seed `seed` for every object. Every reference
    is resolved before any push (a bad one raises `ObjectSpecError` at once).
    on_object(i, row) is called after object i (0-based); on_push(i, estimate) after each of
    its pushes (progress). threads: torch's intra-op threads for the run (None: as they are),
    restored afterwards; on a machine shared with other work, more threads than free cores
    make torch's workers spin-wait and the updates many times slower."""
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.testbed.object_refs import load_object_spec

    specs = [load_object_spec(ref) for ref in objects]
    config = InferenceConfig(
        pushes=pushes, estimator=estimator, profiles=tuple(profiles), policy=policy
    )
    load = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    previous_threads = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    used_threads = torch.get_num_threads()
    rows: list[ObjectRow] = []
    try:
        for i, (ref, spec) in enumerate(zip(objects, specs, strict=True)):
            t0 = time.perf_counter()
            result = infer_simulated(
                model,
                spec,
                config,
                seed,
                on_push=None if on_push is None else (lambda e, i=i: on_push(i, e)),
            )
            row = object_row(ref, result, time.perf_counter() - t0)
            rows.append(row)
            if on_object is not None:
                on_object(i, row)
    finally:
        torch.set_num_threads(previous_threads)
    return EstimatorBench(
        estimator=estimator,
        pushes=pushes,
        profiles=tuple(profiles),
        policy=policy,
        seed=seed,
        cpu_count=os.cpu_count() or 1,
        torch_threads=used_threads,
        load_average_1min_at_start=load,
        machine=machine_description(),
        objects=rows,
        summary=summarise(rows),
    )
