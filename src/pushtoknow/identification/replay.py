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
rollout with actuated models; `identification.sysid_baseline` fits with it as a baseline, its
pad servo-driven (a slightly different model: see there). So the batch runs the testbed's own
`PushSimulator` in a process pool, one task per (φ, push).
"""

from __future__ import annotations

import atexit
import json
from collections import OrderedDict
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Point, Polygon
from shapely.ops import nearest_points

from pushtoknow.common.errors import IdentificationError, PushToKnowError
from pushtoknow.common.parallel import LocalRunner, TaskRunner, Workers
from pushtoknow.common.params import ObjectParams
from pushtoknow.testbed.objects import (
    COM_MARGIN,
    FRICTION_LIMIT,
    MAX_MASS,
    MIN_GYRATION_RADIUS,
    ObjectSpec,
)
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.scene import mass_layout
from pushtoknow.testbed.shapes import Footprint, footprint_from_shape
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

COM_INSET = 2e-4  # m: candidates keep the CoM this far inside the valid region (rounding)
INERTIA_SHARE = 0.999  # candidates keep I_z below this share of the footprint's bound
MAX_FRICTION = 0.995 * FRICTION_LIMIT  # candidates keep μ just below what the testbed refuses


@dataclass(frozen=True)
class PushTrack:
    """One recorded push to replay and fit.

    push: the action; start (2,): pad start (m, world, the record's pusher[0]);
    pose0 (3,): object pose (x, y, θ) at the start, record frame; force (T, 2): measured
    tactile force (N, world, by the pad on the object); pose (T, 3): measured pose track;
    pad (T, 2) or None: the recorded pad track to drive the pad along (m, world), for a push
    that does not follow the testbed's speed profiles (a real pusher); None replays the
    push's profile from `start`; pad_fine (N, 3) [t, x, y] or None: the same pusher at its
    recorder's finer rate, which the pad then follows (`PushRecord.pusher_fine`); end_pose (3,)
    or None: the object's pose at rest after the push measured apart from the track (registered
    in an image taken then, θ unwrapped as the track's).
    """

    push: Push
    start: np.ndarray
    pose0: np.ndarray
    force: np.ndarray
    pose: np.ndarray
    pad: np.ndarray | None = None
    pad_fine: np.ndarray | None = None
    end_pose: np.ndarray | None = None


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


def carried_region(footprint: Footprint) -> Polygon:
    """Where the testbed's supports can carry a candidate's CoM: the footprint's convex hull
    less `COM_MARGIN`, and within the convex hull of the footprint shrunk by it (its largest
    piece), whose outline the supports line (`scene.support_points`; a sliver or spike thinner
    than twice the margin, as a traced outline can have, holds no support), less
    `COM_INSET`."""
    shrunk = footprint.polygon.buffer(-COM_MARGIN)
    if shrunk.geom_type != "Polygon":
        shrunk = max(shrunk.geoms, key=lambda g: g.area)
    region = footprint.com_region(COM_MARGIN).intersection(shrunk.convex_hull).buffer(-COM_INSET)
    return region if not region.is_empty else footprint.com_region(COM_MARGIN + COM_INSET)


def feasible(phi: np.ndarray, footprint: Footprint) -> tuple[np.ndarray, float, float]:
    """The nearest simulable φ (5,) SI: CoM inside the footprint by the testbed's margin, I_z
    between the least the testbed simulates and the most this footprint allows, μ below the
    testbed's limit. Returns (φ, CoM moved
    (m), excess: Σ (value / bound − 1) over I_z and μ where above their bound)."""
    phi = np.array(phi, dtype=np.float64)
    region = carried_region(footprint)
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


COMPILED_SCENES = 16  # compiled scenes each process keeps (`compiled_simulator`)
_compiled: OrderedDict[tuple, PushSimulator] = OrderedDict()


def compiled_simulator(scene: ReplayScene, params: ObjectParams) -> PushSimulator:
    """A simulator of the scene's outline holding `params`: a compiled scene of this process
    with the same outline, height, settings and supports carrying load, given `params` by
    `PushSimulator.set_params` (bit-identical to a fresh build), or a new one, kept for the
    next replays (the `COMPILED_SCENES` most recently used)."""
    spec = ObjectSpec(shape=scene.shape, params=params, height=scene.height)
    layout = mass_layout(spec, scene.sim_config)
    key = (
        json.dumps(scene.shape, sort_keys=True),
        scene.height,
        scene.sim_config.model_dump_json(),
        np.round(layout.points, 6).tobytes(),
    )
    sim = _compiled.get(key)
    if sim is not None and sim.set_params(params, layout):
        _compiled.move_to_end(key)
        return sim
    sim = PushSimulator(spec, scene.sim_config)
    _compiled[key] = sim
    while len(_compiled) > COMPILED_SCENES:
        _compiled.popitem(last=False)[1].close()
    return sim


def simulate_track(scene: ReplayScene, phi: np.ndarray, track: PushTrack) -> np.ndarray:
    """Replay one push for a simulable φ (5,) SI. Returns (T, 5): noiseless force (F_x, F_y) and
    pose (x, y, θ) in the record's frame."""
    sim = compiled_simulator(scene, ObjectParams.from_array(phi))
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
        pad_fine=None if track.pad is None else track.pad_fine,
    )
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


REMEMBERED_REPLAYS = 4096  # single-push replays a `RolloutPool` keeps (`replay_key`)


def scene_key(scene: ReplayScene) -> bytes:
    """What a replay of `scene` depends on, as bytes (its outline, height, settings, frame)."""
    return (
        json.dumps(
            [scene.shape, scene.height, scene.frame_offset, scene.stop_at_rest], sort_keys=True
        ).encode()
        + scene.sim_config.model_dump_json().encode()
    )


def replay_key(scene: bytes, phi: np.ndarray, track: PushTrack) -> tuple:
    """What `simulate_track` of (φ, track) in the scene of `scene_key` depends on: φ's bits
    and the push as driven (action, pad start and tracks, start pose), not what was observed."""
    push = track.push
    return (
        scene,
        np.asarray(phi, dtype=np.float64).tobytes(),
        (push.contact, push.direction, push.profile, push.speed),
        *(None if a is None else np.asarray(a, np.float64).tobytes() for a in (
            track.start, track.pose0, track.pad, track.pad_fine)),
    )  # fmt: skip


class RolloutPool:
    """Runs batches of (φ, push) replays on `workers` (local processes, 1: in this process, or a
    `TaskRunner`), remembering the last `REMEMBERED_REPLAYS` (a replay is deterministic: one
    asked for again, such as the pushes a finite-difference probe of another push's contact
    offset leaves unchanged, is not run again). `rollouts` counts candidate φ replayed over all
    pushes, `push_rollouts` single pushes run (not those remembered)."""

    def __init__(self, workers: Workers = 1):
        self._owned = not isinstance(workers, TaskRunner)
        self.runner = workers if isinstance(workers, TaskRunner) else LocalRunner(workers)
        self.workers = self.runner.workers
        self.rollouts = 0
        self.push_rollouts = 0
        self._done: OrderedDict[tuple, np.ndarray] = OrderedDict()

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
        where = scene_key(scene)
        keys = [replay_key(where, phi, tr) for _, phi, tr in tasks]
        todo = {}  # key → index of the first task asking for it, among those not remembered
        for i, key in enumerate(keys):
            if key not in self._done:
                todo.setdefault(key, i)
        ran = self.runner.map(_task, [tasks[i] for i in todo.values()])
        for key, sim in zip(todo, ran, strict=True):
            sim.setflags(write=False)  # shared by every task asking for it
            self._done[key] = sim
        out = [self._done[key] for key in keys]
        for key in keys:
            self._done.move_to_end(key)
        while len(self._done) > REMEMBERED_REPLAYS:
            self._done.popitem(last=False)
        self.rollouts += len(phis)
        self.push_rollouts += len(todo)
        k = len(tracks[0]) if tracks else 0
        return [out[b * k : (b + 1) * k] for b in range(len(phis))]


_shared: dict[int, RolloutPool] = {}


def shared_pool(workers: int) -> RolloutPool:
    """This process's `RolloutPool` of `workers` local processes, started on first use and kept
    until the process ends: estimators of one object after another (a robot's session, an
    evaluation, a benchmark) share its started workers, their compiled scenes and its
    remembered replays instead of starting processes for every object."""
    pool = _shared.get(workers)
    if pool is None:
        pool = _shared[workers] = RolloutPool(workers)
    return pool


@atexit.register
def _close_shared() -> None:
    for pool in _shared.values():
        pool.close()
    _shared.clear()
