"""Simulated pushes for measuring the identifier (no rendering): pushes at the inward normal of
the true footprint (± 5°, as `geometry.affordances` samples them from S_0), the object placed at
a random pose before each push as `testbed.executor.SimulatedExecutor` does."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord, PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

MAX_DEVIATION = math.radians(5.0)


def boundary_push(
    spec: ObjectSpec, pose, rng: np.random.Generator, profile: str, speed: float
) -> Push:
    """A push onto the object at `pose` (x, y, θ): a boundary point drawn by arc length, the
    inward normal of its edge plus δ ~ U(−5°, 5°)."""
    v = spec.footprint.vertices
    edges = np.roll(v, -1, 0) - v
    lengths = np.linalg.norm(edges, axis=1)
    i = int(rng.choice(len(v), p=lengths / lengths.sum()))
    t = rng.uniform(0.1, 0.9)
    p = v[i] + t * edges[i]
    inward = np.array([-edges[i, 1], edges[i, 0]]) / lengths[i]  # CCW polygon: left is inside
    x, y, th = map(float, pose)
    c, s = math.cos(th), math.sin(th)
    cp = (x + c * p[0] - s * p[1], y + s * p[0] + c * p[1])
    direction = math.atan2(s * inward[0] + c * inward[1], c * inward[0] - s * inward[1])
    return Push(cp, direction + rng.uniform(-MAX_DEVIATION, MAX_DEVIATION), profile, speed)


def simulate_pushes(
    spec: ObjectSpec,
    profiles: Sequence[str],
    seed: int = 0,
    config: SimConfig | None = None,
    centred: bool = False,
    pose_noise: tuple[float, float] | None = None,
) -> list[PushRecord]:
    """One push per entry of `profiles` ("constant" or "release") on `spec`, noisy tactile
    force as the testbed records it, no images. centred: every push through the middle of the
    footprint's left side along +x, the object at the origin (a push through the centroid).
    pose_noise (m, rad): std of white Gaussian tracking noise added to the pose samples after
    the first (the testbed records exact poses; a tracker does not); None adds none."""
    cfg = (config or SimConfig()).model_copy(update={"render": False})
    rng = np.random.default_rng(seed)
    sim = PushSimulator(spec, cfg)
    h = cfg.workspace_half_extent
    out = []
    try:
        for profile in profiles:
            speed = cfg.push.profile_speed(profile)
            if centred:
                sim.reset((0.0, 0.0, 0.0))
                x0 = float(spec.footprint.polygon.bounds[0])
                push = Push((x0, 0.0), 0.0, profile, speed)
            else:
                pose = sim.reset(
                    (rng.uniform(-h, h), rng.uniform(-h, h), rng.uniform(-np.pi, np.pi))
                )
                push = boundary_push(spec, pose, rng, profile, speed)
            rec = sim.execute(push, rng, render=False)
            if pose_noise is not None:
                add_tracking_noise([rec], pose_noise, rng)
            out.append(rec)
    finally:
        sim.close()
    return out


def add_tracking_noise(
    records: Sequence[PushRecord], pose_noise: tuple[float, float], rng: np.random.Generator
) -> None:
    """Add white Gaussian tracking noise of std pose_noise (m, rad) to every pose sample after
    the first, in place: the testbed records exact poses, a tracker does not, and `identify`
    weighs the pose track by that noise."""
    sd = np.array([pose_noise[0], pose_noise[0], pose_noise[1]])
    for rec in records:
        rec.pose[1:] += rng.normal(0.0, 1.0, size=rec.pose[1:].shape) * sd
