"""Replaying recorded pushes in the testbed's own scene for a candidate φ, batched over cores.

A candidate object is the recorded footprint with φ = (m, μ, c_x, c_y, I_z); its scene is built
by `testbed.scene.build_mjcf` exactly as the testbed builds it (support loads from
`scene.support_loads`), and the pad replays the recorded push: the same action and speed
profile from the recorded pad start `pusher[0]`, so the fit sees exactly the executed pushes.

`mujoco.rollout` (present in the pinned MuJoCo 4.0.0) rolls out open-loop *controls*
(ctrl, applied forces, mocap poses); the testbed drives its pad kinematically by writing the
pad joints' qpos and qvel at every physics step and refines the step during a release push's
dynamic phase, which rollout's control vector cannot express without changing the physics
(a mocap pad has no velocity in the contact Jacobian). `mujoco.sysid` (also shipped) builds on
rollout with actuated models, and does not import here (its optional dependency absl is
missing). So the batch runs the testbed's own `PushSimulator` in a process pool, one task per
(φ, push).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from shapely.geometry import Point
from shapely.ops import nearest_points

from pushtoknow.common.errors import IdentificationError, PushToKnowError
from pushtoknow.common.parallel import LocalRunner, TaskRunner, Workers
from pushtoknow.common.params import ObjectParams
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.objects import COM_MARGIN, MAX_MASS, MIN_GYRATION_RADIUS, ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.shapes import Footprint, footprint_from_shape

COM_INSET = 2e-4  # m: candidates keep the CoM this far inside the valid region (rounding)
INERTIA_SHARE = 0.999  # candidates keep I_z below this share of the footprint's bound
MAX_FRICTION = 1.99  # the testbed refuses Coulomb coefficients above 2


@dataclass(frozen=True)
class PushTrack:
    """One recorded push to replay and fit.

    push: the action; start (2,): pad start (m, world, the record's pusher[0]);
    pose0 (3,): object pose (x, y, θ) at the start, record frame; force (T, 2): measured
    tactile force (N, world, by the pad on the object); pose (T, 3): measured pose track;
    pad (T, 2) or None: the recorded pad track to drive the pad along (m, world), for a push
    that does not follow the testbed's speed profiles (a real pusher); None replays the
    push's profile from `start`.
    """

    push: Push
    start: np.ndarray
    pose0: np.ndarray
    force: np.ndarray
    pose: np.ndarray
    pad: np.ndarray | None = None


@dataclass(frozen=True)
class ReplayScene:
    """What stays fixed during a fit: the footprint's shape description (object frame),
    extrusion height (m), the simulation settings and `frame_offset` (2,), the position of
    the fit footprint's centroid in the record's object frame (m; zero unless the footprint was
    estimated from a mask, whose centroid differs from the recorded frame's origin)."""

    shape: dict
    height: float
    sim_config: SimConfig
    frame_offset: tuple[float, float] = (0.0, 0.0)
    stop_at_rest: float | None = 1e-4

    @property
    def footprint(self) -> Footprint:
        return footprint_from_shape(self.shape)


def feasible(phi: np.ndarray, footprint: Footprint) -> tuple[np.ndarray, float, float]:
    """The nearest simulable φ (5,) SI: CoM inside the footprint by the testbed's margin, I_z
    between the least the testbed simulates and the most this footprint allows, μ below the
    testbed's limit. Returns (φ, CoM moved
    (m), excess: Σ (value / bound − 1) over I_z and μ where above their bound)."""
    phi = np.array(phi, dtype=np.float64)
    region = footprint.com_region(COM_MARGIN + COM_INSET)
    c = Point(phi[2], phi[3])
    moved = 0.0
    if not region.contains(c):
        q = nearest_points(region, c)[0]
        moved = float(c.distance(q))
        phi[2], phi[3] = q.x, q.y
    bound = INERTIA_SHARE * phi[0] * footprint.max_radius_from(phi[2:4]) ** 2
    excess = max(0.0, float(phi[4] / bound - 1.0)) + max(0.0, float(phi[1] / MAX_FRICTION - 1.0))
    phi[4] = min(phi[4], bound)
    phi[1] = min(phi[1], MAX_FRICTION)
    if phi[0] > MAX_MASS:  # the replay's limit; I_z keeps its share of the bound
        phi[4] *= MAX_MASS / phi[0]
        phi[0] = MAX_MASS
    # the testbed's least radius of gyration (a rounding margin above it)
    phi[4] = max(phi[4], 1.001 * phi[0] * MIN_GYRATION_RADIUS**2)
    return phi, moved, excess


def simulate_track(scene: ReplayScene, phi: np.ndarray, track: PushTrack) -> np.ndarray:
    """Replay one push for a simulable φ (5,) SI. Returns (T, 5): noiseless force (F_x, F_y) and
    pose (x, y, θ) in the record's frame."""
    from pushtoknow.testbed.sim import PushSimulator

    spec = ObjectSpec(shape=scene.shape, params=ObjectParams.from_array(phi), height=scene.height)
    sim = PushSimulator(spec, scene.sim_config)
    try:
        dx, dy = scene.frame_offset
        x, y, th = map(float, track.pose0)
        c, s = np.cos(th), np.sin(th)
        sim.reset((x + c * dx - s * dy, y + s * dx + c * dy, th))
        rec = sim.execute(
            track.push,
            np.random.default_rng(0),
            render=False,
            start=track.start,
            stop_at_rest=scene.stop_at_rest,
            pad_track=track.pad,
        )
    finally:
        sim.close()
    pose = rec.pose.copy()
    if dx or dy:
        c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
        pose[:, 0] -= c * dx - s * dy
        pose[:, 1] -= s * dx + c * dy
    return np.column_stack([rec.force_clean, pose])


def _task(args) -> np.ndarray:
    scene, phi, track = args
    try:
        return simulate_track(scene, phi, track)
    except (PushToKnowError, ValueError) as e:  # re-raised as one picklable, one-line error
        raise IdentificationError(f"replaying a push with φ = {phi.tolist()} failed: {e}") from None


class RolloutPool:
    """Runs batches of (φ, push) replays on `workers` (local processes, 1: in this process, or a
    `TaskRunner`). `rollouts` counts candidate φ replayed over all pushes, `push_rollouts`
    single pushes."""

    def __init__(self, workers: Workers = 1):
        self._owned = not isinstance(workers, TaskRunner)
        self.runner = workers if isinstance(workers, TaskRunner) else LocalRunner(workers)
        self.workers = self.runner.workers
        self.rollouts = 0
        self.push_rollouts = 0

    def __enter__(self) -> RolloutPool:
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def close(self) -> None:
        if self._owned:
            self.runner.close()

    def run(
        self, scene: ReplayScene, phis: np.ndarray, tracks: list[PushTrack]
    ) -> list[list[np.ndarray]]:
        """phis (B, 5) simulable SI → B lists of K arrays (T_k, 5): force and pose of each
        push (see `simulate_track`)."""
        phis = np.atleast_2d(np.asarray(phis, dtype=np.float64))
        return self.run_each(scene, phis, [tracks] * len(phis))

    def run_each(
        self, scene: ReplayScene, phis: np.ndarray, tracks: list[list[PushTrack]]
    ) -> list[list[np.ndarray]]:
        """As `run`, each φ (B, 5) with its own pushes tracks[b] (K each)."""
        tasks = [(scene, phi, tr) for phi, trs in zip(phis, tracks, strict=True) for tr in trs]
        out = self.runner.map(_task, tasks)
        self.rollouts += len(phis)
        self.push_rollouts += len(tasks)
        k = len(tracks[0]) if tracks else 0
        return [out[b * k : (b + 1) * k] for b in range(len(phis))]
