"""Simulator throughput: simulated seconds per wall second, one process, 64×64 RGB-D + tactile."""

from __future__ import annotations

import time
from dataclasses import asdict, dataclass

import numpy as np

from pushtoknow.bench import machine_description, peak_rss_mb


@dataclass(frozen=True)
class SimulatorSpeed:
    """The result of `run_sim_bench` (`pushtoknow bench sim`): simulated seconds per wall
    second, from the median push (`realtime_factor`) and from all pushes together
    (`realtime_factor_mean`); the median wall time of one push (s, observation and push
    sampling included); the timed pushes (after one warm-up push); the push horizon (s); the
    camera image [height, width] (px); the tactile rate (Hz); the physics timestep (s); the
    process's peak resident memory (MB) and the machine."""

    realtime_factor: float
    realtime_factor_mean: float
    push_wall_s_median: float
    pushes: int
    horizon_s: float
    image: list[int]
    tactile_hz: float
    physics_timestep_s: float
    peak_rss_mb: float
    machine: str

    def to_json(self) -> dict:
        return asdict(self)


def run_sim_bench(
    pushes: int = 6, seed: int = 0, object_source: str = "catalogue:100"
) -> SimulatorSpeed:
    """Time `pushes` constant-speed pushes of one object (`object_source`) in one process."""
    from pushtoknow.common.random import stream, stream_seed
    from pushtoknow.geometry.affordances import sample_push_affordances
    from pushtoknow.testbed.executor import SimulatedExecutor
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.testbed.push import Push
    from pushtoknow.testbed.sim_config import SimConfig

    cfg = SimConfig()
    ex = SimulatedExecutor(
        load_object_spec(object_source), cfg, seed=stream_seed(seed, "simulator")
    )
    rng = stream(seed, "policy")

    def one_push():
        view = ex.observe()
        cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
        return ex.execute(Push(tuple(cp[0]), float(pd[0]), "constant", cfg.push.speed))

    one_push()  # warm-up: GL context, model compilation caches
    walls = []
    for _ in range(pushes):
        t0 = time.perf_counter()
        one_push()
        walls.append(time.perf_counter() - t0)
    ex.close()
    walls = np.array(walls)
    horizon = cfg.push.horizon
    return SimulatorSpeed(
        realtime_factor=float(horizon / np.median(walls)),
        realtime_factor_mean=float(horizon * len(walls) / walls.sum()),
        push_wall_s_median=float(np.median(walls)),
        pushes=pushes,
        horizon_s=horizon,
        image=[cfg.camera.height, cfg.camera.width],
        tactile_hz=cfg.tactile.rate_hz,
        physics_timestep_s=cfg.physics.timestep,
        peak_rss_mb=peak_rss_mb(),
        machine=machine_description(),
    )
