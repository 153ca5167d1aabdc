"""Benchmark of one dual-filter step (predict + update) with the paper-sized learned models.

Inference (no autograd), CPU, 64×64 masks, C sigma points, randomly initialised networks,
steady-state steps of a run (see `_time_steps`). Two numbers:
* step_ms_median: one object (B = 1), median wall time of one step;
* object_steps_per_s: B objects batched in one step, B / median step time.
Both for each encoder variant (see `pushtoknow.models.encoding`): "mean" with a 32 px crop
(the default design) and "per_sigma" on the full 64 px image (the paper).
"""

from __future__ import annotations

import os
import platform
import statistics
import time
from collections.abc import Sequence
from dataclasses import asdict, dataclass

import torch

from pushtoknow.common.camera import CameraModel
from pushtoknow.filters.base import FilterConfig
from pushtoknow.models.context import PushContext
from pushtoknow.models.encoding import EncodingConfig
from pushtoknow.models.learned import LearnedModelsConfig, build_filter
from pushtoknow.models.networks import EncoderConfig

TARGET_STEP_MS = 10.0
TARGET_OBJECT_STEPS_PER_S = 2000.0
OBJECT_HALF_SIDE_M = 0.045  # rect1 of the catalogue
PRIOR_VARIANCES = (1e-4, 1e-4, 1e-2, 0.3, 0.3, 0.3, 0.3, 0.3)  # m², m², rad², normalised
WARMUP_STEPS = 5
DEFAULT_VARIANTS: tuple[tuple[str, str, int | None], ...] = (
    ("mean_crop32", "mean", 32),
    ("per_sigma_full64", "per_sigma", None),
)


def _context(batch: int, camera: CameraModel) -> PushContext:
    """A square object at the image centre pushed along +x from its left side."""
    h = OBJECT_HALF_SIDE_M
    uv = torch.arange(camera.width, dtype=torch.float32)
    metres = camera.metres_per_pixel()
    x = (uv - camera.principal_point[0]) * metres
    inside = (x.abs() <= h).float()
    mask = (inside.view(1, -1) * inside.view(-1, 1)).expand(batch, 1, -1, -1).contiguous()
    square = torch.tensor([[-h, -h], [h, -h], [h, h], [-h, h]])
    return PushContext(
        mask0=mask,
        pose0=torch.zeros(batch, 3),
        contact_xy=torch.tensor([[-h, 0.0]]).expand(batch, 2).contiguous(),
        direction=torch.zeros(batch),
        speed=torch.full((batch,), 0.05),
        camera=camera,
        footprint=square.expand(batch, 4, 2).contiguous(),
    )


def _time_steps(
    filt, batch: int, sigma_points: int, repeats: int, seed: int, warmup: int = WARMUP_STEPS
) -> tuple[list[float], float]:
    """Wall times of `repeats` consecutive steps after `warmup` untimed ones, along a run
    whose observation each step is the model's own prediction at the current mean (a
    consistent observation), so the timed steps are steady-state steps. Also returns the mean
    number of tempering stages of the timed steps."""
    camera = CameraModel()
    ctx = _context(batch, camera)
    gen = torch.Generator().manual_seed(seed)
    mean = torch.zeros(batch, 8)
    cov = torch.diag(torch.tensor(PRIOR_VARIANCES)).expand(batch, 8, 8)
    times, stages = [], []
    with torch.no_grad():
        for i in range(warmup + repeats):
            noise = filt.draw_noise(batch, gen, num_sigma_points=sigma_points)
            z = filt.observation(mean.unsqueeze(1), ctx).squeeze(1)
            t0 = time.perf_counter()
            mean, cov, info = filt(mean, cov, z, ctx, noise=noise)
            if i >= warmup:
                times.append(time.perf_counter() - t0)
                stages.append(float(info.stages.float().mean()))
    return times, statistics.mean(stages)


@dataclass(frozen=True)
class FilterSpeed:
    """The result of `run_filter_bench` (`pushtoknow bench filter`). Of the default variant
    (`default_variant`, the first): the median wall time of one step of one object
    (`step_ms_median`, ms) and the batched throughput (`object_steps_per_s`, object-steps per
    s). The settings: seed, batch (objects in the batched step), sigma_points (C), repeats
    (timed steps), threads ({"single": intra-op threads of the single-object run,
    "batched_tried": those the batch was timed with}); the machine and its 1-min load average
    at the start (None where unavailable); targets ({"step_ms", "object_steps_per_s"}); per
    variant name (`variants`): {"encoder_mode", "crop_size" (px or None), "step_ms_median",
    "step_ms_min", "tempering_stages_mean", "batched_step_ms_median", "batched_threads",
    "batched_step_ms_by_threads" ({threads: ms}), "object_steps_per_s", "meets_targets"}."""

    step_ms_median: float
    object_steps_per_s: float
    default_variant: str
    machine: str
    seed: int
    batch: int
    sigma_points: int
    repeats: int
    threads: dict[str, int | list[int]]
    load_average_1min_at_start: float | None
    targets: dict[str, float]
    variants: dict[str, dict]

    def to_json(self) -> dict:
        return asdict(self)


def run_filter_bench(
    seed: int = 0,
    batch: int = 32,
    sigma_points: int = 100,
    repeats: int = 20,
    variants: Sequence[tuple[str, str, int | None]] = DEFAULT_VARIANTS,
    num_threads: int | None = None,
) -> FilterSpeed:
    """Time one predict + update of the dual filter; see the module docstring.

    variants: (name, encoder mode, crop size or None); the first is the reported default.
    num_threads: torch intra-op threads for both measurements (default: 1 for the single
    object; the batch with 1 and with all cores, the faster reported); restored afterwards.
    Returns a `FilterSpeed`.
    """
    previous_threads = torch.get_num_threads()
    load_at_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    cores = os.cpu_count() or 1
    # Threads: 1 for the single object (many tiny ops: a second thread only adds
    # synchronisation). The batch is timed with 1 thread and with all cores and the faster
    # is reported: on a shared machine where another process holds a core, OpenMP workers
    # spin-wait and multi-threaded runs get 10-50x slower, on an idle one they help.
    single_threads = num_threads or 1
    batched_options = [num_threads] if num_threads else sorted({1, cores})
    try:
        results: dict[str, dict] = {}
        for name, mode, crop in variants:
            torch.manual_seed(seed)  # network initialisation
            models_cfg = LearnedModelsConfig(
                encoding=EncodingConfig(mode=mode, crop_size=crop),
                encoder=EncoderConfig(image_size=crop or CameraModel().width),
            )
            filt = build_filter(
                "dual",
                models_config=models_cfg,
                filter_config=FilterConfig(num_sigma_points=sigma_points),
            ).eval()
            torch.set_num_threads(single_threads)
            single, single_stages = _time_steps(filt, 1, sigma_points, repeats, seed)
            slow = mode == "per_sigma"  # ~0.1 s per object-step: keep the batched run short
            batched_ms: dict[int, float] = {}
            for threads in batched_options:
                torch.set_num_threads(threads)
                batched, _ = _time_steps(
                    filt,
                    batch,
                    sigma_points,
                    max(2, repeats // 10) if slow else repeats,
                    seed,
                    warmup=1 if slow else WARMUP_STEPS,
                )
                batched_ms[threads] = 1e3 * statistics.median(batched)
            best_threads = min(batched_ms, key=batched_ms.__getitem__)
            single_ms = 1e3 * statistics.median(single)
            throughput = 1e3 * batch / batched_ms[best_threads]
            results[name] = {
                "encoder_mode": mode,
                "crop_size": crop,
                "step_ms_median": single_ms,
                "step_ms_min": 1e3 * min(single),
                "tempering_stages_mean": single_stages,
                "batched_step_ms_median": batched_ms[best_threads],
                "batched_threads": best_threads,
                "batched_step_ms_by_threads": batched_ms,
                "object_steps_per_s": throughput,
                "meets_targets": single_ms <= TARGET_STEP_MS
                and throughput >= TARGET_OBJECT_STEPS_PER_S,
            }
    finally:
        torch.set_num_threads(previous_threads)
    default = results[variants[0][0]]
    return FilterSpeed(
        step_ms_median=default["step_ms_median"],
        object_steps_per_s=default["object_steps_per_s"],
        default_variant=variants[0][0],
        machine=(
            f"{platform.machine()} {platform.processor() or platform.system()}, "
            f"{cores} cores, torch {torch.__version__}"
        ),
        seed=seed,
        batch=batch,
        sigma_points=sigma_points,
        repeats=repeats,
        threads={"single": single_threads, "batched_tried": batched_options},
        load_average_1min_at_start=load_at_start,
        targets={"step_ms": TARGET_STEP_MS, "object_steps_per_s": TARGET_OBJECT_STEPS_PER_S},
        variants=results,
    )
