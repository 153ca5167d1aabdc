"""Benchmark of one active push decision (docs/DESIGN.md §7) with the paper-sized learned models.

One decision = score M candidate pushes as one batch over an N-step look-ahead and pick the
best: building each step's `PushContext` (pad where `testbed.push.pad_positions` puts it),
N dual-filter predictions of M objects with C sigma points, and for "entropy" the expected
covariance update after each. Inference (no autograd), CPU, randomly initialised networks
(default `LearnedModelsConfig`: "mean" encoder on a 32 px crop), a synthetic disc mask on the
64×64 camera. Defaults: M = 16, N = 30 (50% of the 61-sample, 6 s horizon at 10 Hz),
C = 100. Also reports where the time goes (per network, from forward hooks, in a separate
untimed decision).
"""

from __future__ import annotations

import math
import os
import statistics
import time
from collections import defaultdict
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass

import numpy as np
import torch
from torch import nn

from pushtoknow.active.information_policy import ActivePolicy, look_ahead_steps
from pushtoknow.active.selection import SCORES
from pushtoknow.bench import machine_description
from pushtoknow.common.camera import CameraModel
from pushtoknow.filters.base import FilterConfig
from pushtoknow.models.context import PushContext, with_pad_track
from pushtoknow.models.learned import LearnedModelsConfig, build_filter
from pushtoknow.testbed.push import PROFILES, Push, pad_positions, release_points
from pushtoknow.testbed.sim_config import PushConfig, TactileConfig

DISC_RADIUS_M = 0.04
FOOTPRINT_VERTICES = 24
DIRECTION_JITTER_RAD = math.radians(5.0)  # paper §III-D: pd = cn + δ, δ ~ U(-5°, 5°)
PRIOR_VARIANCES = (1e-4, 1e-4, 1e-2, 0.3, 0.3, 0.3, 0.3, 0.3)  # m², m², rad², normalised
HORIZON_FRACTION = 0.5


def _disc(camera: CameraModel) -> tuple[torch.Tensor, torch.Tensor]:
    """Mask (1, 1, H, W) of a disc of DISC_RADIUS_M at the origin and its footprint polygon
    (1, V, 2) (m, object frame)."""
    metres = camera.metres_per_pixel()
    u = (torch.arange(camera.width, dtype=torch.float32) - camera.principal_point[0]) * metres
    v = (torch.arange(camera.height, dtype=torch.float32) - camera.principal_point[1]) * metres
    mask = (v.view(-1, 1).square() + u.view(1, -1).square() <= DISC_RADIUS_M**2).float()
    angles = torch.arange(FOOTPRINT_VERTICES, dtype=torch.float32) * (
        2 * math.pi / FOOTPRINT_VERTICES
    )
    poly = DISC_RADIUS_M * torch.stack([angles.cos(), angles.sin()], -1)
    return mask.view(1, 1, camera.height, camera.width), poly.unsqueeze(0)


def candidate_pushes(num: int, rng: np.random.Generator, push_cfg: PushConfig) -> list[Push]:
    """M pushes at contact points evenly around the disc, each along the inward normal plus a
    U(-5°, 5°) jitter; profiles alternate between constant (cfg speed) and release (cfg peak)."""
    pushes = []
    for i in range(num):
        alpha = 2 * math.pi * i / num
        cp = (DISC_RADIUS_M * math.cos(alpha), DISC_RADIUS_M * math.sin(alpha))
        direction = alpha + math.pi + rng.uniform(-DIRECTION_JITTER_RAD, DIRECTION_JITTER_RAD)
        profile = PROFILES[i % len(PROFILES)]
        speed = push_cfg.profile_speed(profile)
        pushes.append(Push(cp, float(direction), profile, speed))
    return pushes


def context_builder_for(
    camera: CameraModel, push_cfg: PushConfig, rate_hz: float, n_steps: int
) -> Callable[[Sequence[Push], int], PushContext]:
    """(pushes, step) ↦ `PushContext` of look-ahead step `step` (the transition to sample
    step + 1: pad at time (step + 1) / rate). The pad tracks of a candidate list are computed
    once, on its first step."""
    mask, poly = _disc(camera)
    times = np.arange(n_steps + 1) / rate_hz
    cache: dict[int, tuple] = {}

    def build(pushes: Sequence[Push], step: int) -> PushContext:
        key = id(pushes)
        if key not in cache:
            tracks = np.stack([pad_positions(p, times, push_cfg) for p in pushes])  # (M, N+1, 2)
            cache.clear()
            cache[key] = (
                pushes,  # keeps the list alive, so its id is not reused
                torch.as_tensor(tracks, dtype=torch.float32),
                torch.tensor([p.direction for p in pushes], dtype=torch.float32),
                torch.tensor([p.speed for p in pushes], dtype=torch.float32),
            )
        _, tracks, direction, speed = cache[key]
        m = len(pushes)
        ctx = PushContext(
            mask0=mask.expand(m, -1, -1, -1),
            pose0=torch.zeros(m, 3),
            contact_xy=tracks[:, 0],
            direction=direction,
            speed=speed,
            camera=camera,
            footprint=poly.expand(m, -1, -1),
            release=torch.as_tensor(release_points(pushes, push_cfg), dtype=torch.float32),
        )
        return with_pad_track(ctx, tracks, step + 1, 1.0 / rate_hz)

    return build


class _ModuleTimer:
    """Wall time spent in the forward of named modules (forward pre/post hooks)."""

    def __init__(self, modules: dict[str, nn.Module]):
        self.seconds: dict[str, float] = defaultdict(float)
        self.calls: dict[str, int] = defaultdict(int)
        self._start: dict[str, float] = {}
        self._handles = []
        for name, mod in modules.items():
            self._handles.append(mod.register_forward_pre_hook(self._pre(name)))
            self._handles.append(mod.register_forward_hook(self._post(name)))

    def _pre(self, name: str):
        def hook(module, args):
            self._start[name] = time.perf_counter()

        return hook

    def _post(self, name: str):
        def hook(module, args, output):
            self.seconds[name] += time.perf_counter() - self._start.pop(name)
            self.calls[name] += 1

        return hook

    def remove(self) -> None:
        for h in self._handles:
            h.remove()


@dataclass(frozen=True)
class ActiveDecisionSpeed:
    """The result of `run_active_bench` (`pushtoknow bench active`): the median wall time of
    one decision per score (`decision_s_median`, {score: s}); the settings (num_candidates M,
    n_steps N of look-ahead, horizon_steps of a whole push, num_sigma_points C, encoder_mode,
    threads, seed, repeats: timed decisions per score); the machine and its 1-min load average
    at the start (None where unavailable); per score (`per_score`): {"policy",
    "decision_s_median", "decision_s_min" (s), "decisions_timed", "chosen" (candidate index
    per timed decision), "breakdown_s" ({part: s}), "breakdown_total_s", "network_calls"}."""

    decision_s_median: dict[str, float]
    num_candidates: int
    n_steps: int
    horizon_steps: int
    num_sigma_points: int
    encoder_mode: str
    machine: str
    threads: int
    load_average_1min_at_start: float | None
    seed: int
    repeats: int
    per_score: dict[str, dict]

    def to_json(self) -> dict:
        return asdict(self)


def run_active_bench(
    seed: int = 0,
    num_candidates: int = 16,
    num_sigma_points: int = 100,
    repeats: int = 3,
    horizon_fraction: float = HORIZON_FRACTION,
    num_threads: int = 1,
    scores: Sequence[str] = SCORES,
) -> ActiveDecisionSpeed:
    """Time one active decision per score; see the module docstring.

    repeats: timed decisions per score after one untimed warm-up; num_threads: torch
    intra-op threads (1: many small ops; restored afterwards). Returns an
    `ActiveDecisionSpeed`.
    """
    previous_threads = torch.get_num_threads()
    load_at_start = os.getloadavg()[0] if hasattr(os, "getloadavg") else None
    push_cfg, rate = PushConfig(), TactileConfig().rate_hz
    horizon_steps = int(round(push_cfg.horizon * rate))  # T - 1 filter steps per push
    n_steps = look_ahead_steps(horizon_fraction, horizon_steps)
    camera = CameraModel()
    torch.manual_seed(seed)  # network initialisation
    filt = build_filter(
        "dual",
        models_config=LearnedModelsConfig(),
        filter_config=FilterConfig(num_sigma_points=num_sigma_points),
    ).eval()
    mean = torch.zeros(1, filt.config.state_dim)
    cov = torch.diag(torch.tensor(PRIOR_VARIANCES)).unsqueeze(0)
    networks = {
        "encoder": filt.dynamics.encoding.encoder,
        "process_net": filt.dynamics.process_net,
        "tac_net": filt.observation.tac_net,
        "obs_noise_net": filt.observation_noise.net,
    }
    per_score: dict[str, dict] = {}
    try:
        torch.set_num_threads(num_threads)
        for score in scores:
            policy = ActivePolicy(filt, horizon_steps, score, horizon_fraction)
            rng = np.random.default_rng(seed)
            gen = torch.Generator().manual_seed(seed)
            walls, chosen = [], []
            for i in range(repeats + 1):
                candidates = candidate_pushes(num_candidates, rng, push_cfg)
                t0 = time.perf_counter()
                builder = context_builder_for(camera, push_cfg, rate, n_steps)
                idx = policy.choose(candidates, mean, cov, builder, gen)
                wall = time.perf_counter() - t0
                if i > 0:  # the first decision warms up (lazy imports, allocator)
                    walls.append(wall)
                    chosen.append(idx)
            # where the time goes: one more (untimed) decision with forward hooks
            timer = _ModuleTimer(networks)
            candidates = candidate_pushes(num_candidates, rng, push_cfg)
            t0 = time.perf_counter()
            builder = context_builder_for(camera, push_cfg, rate, n_steps)
            policy.choose(candidates, mean, cov, builder, gen)
            total = time.perf_counter() - t0
            timer.remove()
            amap_cfg = filt.dynamics.encoding.config.action_map
            t_ctx = time.perf_counter()
            builder = context_builder_for(camera, push_cfg, rate, n_steps)
            for k in range(n_steps):
                builder(candidates, k).action_map(amap_cfg, mean.dtype)
            contexts = time.perf_counter() - t_ctx
            breakdown = {name: timer.seconds[name] for name in networks}
            breakdown["contexts_and_action_maps"] = contexts
            breakdown["other_filter_algebra"] = total - sum(breakdown.values())
            per_score[score] = {
                "policy": policy.name,
                "decision_s_median": statistics.median(walls),
                "decision_s_min": min(walls),
                "decisions_timed": len(walls),
                "chosen": chosen,
                "breakdown_s": breakdown,
                "breakdown_total_s": total,
                "network_calls": dict(timer.calls),
            }
    finally:
        torch.set_num_threads(previous_threads)
    return ActiveDecisionSpeed(
        decision_s_median={s: r["decision_s_median"] for s, r in per_score.items()},
        num_candidates=num_candidates,
        n_steps=n_steps,
        horizon_steps=horizon_steps,
        num_sigma_points=num_sigma_points,
        encoder_mode=filt.dynamics.encoding.config.mode,
        machine=f"{machine_description()}, torch {torch.__version__}",
        threads=num_threads,
        load_average_1min_at_start=load_at_start,
        seed=seed,
        repeats=repeats,
        per_score=per_score,
    )
