"""The pushing simulator: one object, a kinematically driven finger pad with a tactile sensor,
and an overhead RGB-D camera. Implements the `PushExecutor` interface.

Frames: everything is in the world frame (table plane z = 0). The tactile force is the planar
force exerted *by the pad on the object* in world axes, averaged over each sample window
(t_k − 1/rate, t_k]; sample k is aligned with the image taken at t_k (sample 0 is all zero).
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import ClassVar

import numpy as np

from pushtoknow.common.params import GRAVITY, ObjectParams
from pushtoknow.testbed import render as _render  # sets MUJOCO_GL before mujoco is imported
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import PAD_CLEARANCE, Push, speed_profile
from pushtoknow.testbed.scene import MassLayout, build_mjcf, mass_layout
from pushtoknow.testbed.sim_config import SimConfig, check_testbed_version

mujoco = _render.mujoco

SETTLE_TIME = 0.2  # s of physics before a push so the supports reach equilibrium
SLIDE_WINDOW = 0.5  # s after the pad stops that a release push keeps the fine physics step


@dataclass(eq=False)
class PushRecord:
    """One push: the one type of a push for the testbed, the datasets, both estimators and
    identification (which replays it, `identification.fit.tracks_from_records`). T samples at
    times `time` (s); a simulated push has T = horizon · rate + 1 at t_k = k / rate.

    What was commanded: push (the action); pusher: (T, 2) pad centre (m, world).
    What was observed: pose: (T, 3) object geometric-frame pose (x, y, θ), θ unwrapped
    (m, m, rad); tactile: (T, 3) measured (F_x, F_y, contact) in N, world frame, force by the pad
    on the object; rgb: (T, H, W, 3) uint8; depth: (T, H, W) float32 metres; s0: (H, W) bool
    object mask at t_0; outline_mask: (kH, kW) bool object mask at t_0 at the camera's outline
    resolution (k = `CameraConfig.outline_scale`); outline_mask_end: the same at the last sample,
    the object at rest after the push. Images are None where not recorded.
    What only the simulator knows: force_clean: (T, 2) noiseless force (N; None for a real
    push); trace: optional physics-rate record {"time", "pose", "velocity", "force"}.
    A real pusher's track at its recorder's own rate: pusher_fine (N, 3) [t (s, the record's
    clock), x, y] or None; replays drive the pad along it (`PushSimulator.execute`), so a
    start or stop between two samples is not smeared over the sample.
    """

    TRACKS: ClassVar[tuple[str, ...]] = ("time", "pose", "tactile", "force_clean", "pusher")

    push: Push
    time: np.ndarray
    pose: np.ndarray
    tactile: np.ndarray
    force_clean: np.ndarray | None
    pusher: np.ndarray
    rgb: np.ndarray | None
    depth: np.ndarray | None
    s0: np.ndarray | None
    trace: dict | None = field(default=None, repr=False)
    outline_mask: np.ndarray | None = None
    pusher_fine: np.ndarray | None = field(default=None, repr=False)
    outline_mask_end: np.ndarray | None = None

    def __eq__(self, other) -> bool:
        """Equal when the push and every recorded array are identical (bitwise)."""
        if not isinstance(other, PushRecord) or self.push != other.push:
            return False
        names = (
            *self.TRACKS, "rgb", "depth", "s0", "outline_mask", "pusher_fine", "outline_mask_end"
        )  # fmt: skip
        return all(
            (a is None and b is None) or (a is not None and b is not None and np.array_equal(a, b))
            for a, b in ((getattr(self, n), getattr(other, n)) for n in names)
        )

    __hash__ = None

    def tracks_only(self) -> PushRecord:
        """A copy of the push and its per-sample tracks (`TRACKS`), without images or trace."""
        tracks = {
            n: None if getattr(self, n) is None else getattr(self, n).copy() for n in self.TRACKS
        }
        return PushRecord(self.push, rgb=None, depth=None, s0=None, **tracks)


def stack_records(pushes: Sequence[Sequence[PushRecord]]) -> dict[str, np.ndarray]:
    """N objects' K pushes of T samples each by field name: "action" (N, K, 5), the pushes'
    `Push.as_array`, and each of `PushRecord.TRACKS` (N, K, T, ·); force_clean only where every
    push has one. `unstack_records` inverts it."""
    records = [r for obj in pushes for r in obj]
    names = [n for n in PushRecord.TRACKS if all(getattr(r, n) is not None for r in records)]
    out = {"action": np.array([[r.push.as_array() for r in obj] for obj in pushes])}
    return out | {n: np.array([[getattr(r, n) for r in obj] for obj in pushes]) for n in names}


def unstack_records(arrays: Mapping[str, np.ndarray]) -> list[list[PushRecord]]:
    """The pushes (without images) `stack_records` packed: N lists of K `PushRecord`s."""
    tracks = {n: arrays.get(n) for n in PushRecord.TRACKS}
    return [
        [
            PushRecord(
                Push.from_array(a),
                rgb=None,
                depth=None,
                s0=None,
                **{n: None if v is None else np.array(v[i, k]) for n, v in tracks.items()},
            )
            for k, a in enumerate(actions)
        ]
        for i, actions in enumerate(np.asarray(arrays["action"]))
    ]


class PushSimulator:
    """Simulates pushes on one object. Deterministic given the seed passed to `execute`."""

    def __init__(self, spec: ObjectSpec, config: SimConfig | None = None):
        self.spec = spec
        self.config = config or SimConfig()
        check_testbed_version(self.config, "the simulation settings (of a model or dataset)")
        self.model = mujoco.MjModel.from_xml_string(build_mjcf(spec, self.config))
        self.data = mujoco.MjData(self.model)
        m = self.model
        obj_body = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_BODY, "object")
        self._object_geoms = {
            g
            for g in range(m.ngeom)
            if m.geom_bodyid[g] == obj_body and m.geom_type[g] == mujoco.mjtGeom.mjGEOM_MESH
        }
        ox = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "object_x")
        self._obj_qpos = int(m.jnt_qposadr[ox])  # (x, y, θ) are three consecutive joints
        self._obj_qvel = int(m.jnt_dofadr[ox])
        self._support_geom_set = {
            g for g in range(m.ngeom) if m.body_parentid[m.geom_bodyid[g]] == obj_body
        }
        self._object_body = obj_body
        self._support_bodies = np.array(
            [b for b in range(m.nbody) if m.body_parentid[b] == obj_body], dtype=np.int64
        )
        self._support_geoms = np.array(
            [g for g in range(m.ngeom) if m.body_parentid[m.geom_bodyid[g]] == obj_body],
            dtype=np.int64,
        )
        self._support_joints = m.body_jntadr[self._support_bodies]
        jx = mujoco.mj_name2id(m, mujoco.mjtObj.mjOBJ_JOINT, "pusher_x")
        self._pad_qpos = m.jnt_qposadr[jx]
        self._pad_qvel = m.jnt_dofadr[jx]
        self._renderer: _render.OverheadRenderer | None = None
        self.camera = self.config.camera.model()

    def set_params(self, params: ObjectParams, layout: MassLayout | None = None) -> bool:
        """Give the compiled scene another object of the same outline and height: write the
        mass split `scene.mass_layout` gives for `params` (masses, inertia, CoM, load springs,
        friction) into the model, exactly as `build_mjcf` would compile it, without rebuilding.
        Returns False, changing nothing, where the new CoM needs another set of supports (a
        CoM near the edge lifts some off, or needs the outline's corners): build anew then.
        The data is not reset (call `reset`). `layout`: `mass_layout` of the new object when
        already computed."""
        spec = replace(self.spec, params=params)
        layout = layout or mass_layout(spec, self.config)
        m = self.model
        b = self._support_bodies
        placed = np.round(layout.points, 6)  # as written in the MJCF (`.6f`)
        if len(placed) != len(b) or not np.array_equal(placed, m.body_pos[b, :2]):
            return False
        nine = np.vectorize(lambda v: float(f"{v:.9g}"))  # as written in the MJCF (`.9g`)
        m.body_mass[b] = nine(layout.support_masses)
        m.jnt_stiffness[self._support_joints] = nine(layout.stiffness)
        m.geom_friction[self._support_geoms, 0] = params.friction
        o = self._object_body
        m.body_mass[o] = layout.body_mass
        m.body_ipos[o] = (params.com_x, params.com_y, spec.height / 2)
        m.body_inertia[o] = (layout.body_ixx, layout.body_ixx, layout.body_inertia)
        mujoco.mj_setConst(m, self.data)
        self.spec = spec
        return True

    # ----------------------------------------------------------------- state
    @property
    def renderer(self) -> _render.OverheadRenderer:
        if self._renderer is None:
            c = self.config.camera
            self._renderer = _render.OverheadRenderer(
                self.model, c.width, c.height, self._object_geoms
            )
        return self._renderer

    def object_pose(self) -> np.ndarray:
        """(3,) current (x, y, θ) of the object's geometric frame (θ unwrapped)."""
        return self.data.qpos[self._obj_qpos : self._obj_qpos + 3].copy()

    def object_velocity(self) -> np.ndarray:
        """(3,) world planar linear velocity of the geometric frame and yaw rate (m/s, rad/s)."""
        return self.data.qvel[self._obj_qvel : self._obj_qvel + 3].copy()

    def set_object_pose(self, pose) -> None:
        """Place the object at (x, y, θ) (m, m, rad) at rest; kinematics not yet updated."""
        self.data.qpos[self._obj_qpos : self._obj_qpos + 3] = np.asarray(pose, dtype=np.float64)
        self.data.qvel[self._obj_qvel : self._obj_qvel + 3] = 0.0

    def _set_pad(self, xy: np.ndarray, vel: np.ndarray) -> None:
        self.data.qpos[self._pad_qpos : self._pad_qpos + 2] = xy
        self.data.qvel[self._pad_qvel : self._pad_qvel + 2] = vel

    def reset(self, pose=(0.0, 0.0, 0.0)) -> np.ndarray:
        """Place the object at rest at `pose` (x, y, θ), pad parked away; settle. Returns pose."""
        mujoco.mj_resetData(self.model, self.data)
        x, y, th = map(float, pose)
        self.set_object_pose((x, y, th))
        park = np.array([x, y]) + 0.5  # well away from the object
        steps = int(round(SETTLE_TIME / self.model.opt.timestep))
        for _ in range(steps):
            self._set_pad(park, np.zeros(2))
            mujoco.mj_step(self.model, self.data)
        return self.object_pose()

    def observe(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Current RGB (H, W, 3) uint8, depth (H, W) float32 m, object mask S (H, W) bool, and
        the object mask at the outline resolution (kH, kW) bool."""
        rgb, depth = self.renderer.rgbd(self.data)
        return rgb, depth, self.renderer.segmentation(self.data), self.outline_mask()

    def outline_mask(self) -> np.ndarray:
        """(kH, kW) bool object mask at `CameraConfig.outline_scale` × the image resolution."""
        return self.renderer.segmentation(self.data, self.config.camera.outline_scale)

    def support_load(self) -> float:
        """Total normal force of the table on the supports over the object's weight (1 at rest;
        below 1 when supports lose contact)."""
        m, d = self.model, self.data
        total = 0.0
        f = np.zeros(6)
        for i in range(d.ncon):
            c = d.contact[i]
            if c.geom1 in self._support_geom_set or c.geom2 in self._support_geom_set:
                mujoco.mj_contactForce(m, d, i, f)
                total += f[0]
        return total / (self.spec.params.mass * GRAVITY)

    # ----------------------------------------------------------------- pushes
    def pad_start(self, push: Push) -> np.ndarray:
        """Pad start on the push line, `approach_gap` (+ clearance) before the true object.

        The contact point may come from a coarse mask, so the start is found on the true
        geometry: march back from cp until the pad is clear, then forward along pd to the
        first point at the wanted gap. A push line that misses the object starts at
        cp − pd·(radius + gap).
        """
        from shapely import affinity
        from shapely.geometry import Point

        pc, pad = self.config.push, self.config.pad
        gap = pc.approach_gap if push.profile == "constant" else PAD_CLEARANCE
        want = pad.radius + max(gap, PAD_CLEARANCE)
        u = push.unit
        x, y, th = self.object_pose()
        poly = affinity.translate(
            affinity.rotate(self.spec.footprint.polygon, th, origin=(0, 0), use_radians=True), x, y
        )
        cp = np.asarray(push.contact, dtype=np.float64)
        back = cp - u * want
        for _ in range(200):
            if poly.distance(Point(*back)) >= want:
                break
            back = back - u * 0.002
        # Forward along the line: bisection on "distance to object >= want".
        lo, hi = 0.0, float(np.linalg.norm(cp - back)) + 0.05
        if poly.distance(Point(*(back + u * hi))) >= want:
            return cp - u * want  # the line misses the object (degenerate push)
        for _ in range(30):
            mid = 0.5 * (lo + hi)
            if poly.distance(Point(*(back + u * mid))) >= want:
                lo = mid
            else:
                hi = mid
        return back + u * lo

    def execute(
        self,
        push: Push,
        rng: np.random.Generator,
        render: bool | None = None,
        trace: bool = False,
        start: np.ndarray | None = None,
        stop_at_rest: float | None = None,
        pad_track: np.ndarray | None = None,
        pad_fine: np.ndarray | None = None,
    ) -> PushRecord:
        """Run one push from the current state; returns its record.

        start (2,): the pad's start (m, world); None finds it on the true geometry
        (`pad_start`). Replaying a recorded push passes its `pusher[0]`.
        pad_track (T, 2): drive the pad along this recorded track instead of the push's speed
        profile (m, world, the pad centre at the samples' times k / rate; linear in between,
        so the pad's velocity is constant within a sample), e.g. a real robot's pusher. The
        record then has T samples, starts at pad_track[0] (`start` is ignored) and every
        sample uses the fine physics step (`dynamic_substeps`): a recorded pusher may start,
        stop and change speed anywhere.
        stop_at_rest: once the pad has stopped for good and the object's speed is below this
        (m/s, and the same in rad/s), stop simulating and hold the last pose, with zero force,
        for the remaining samples (a release push's object at rest stays there, up to
        MuJoCo's sub-micrometre creep); None simulates every sample.
        """
        cfg = self.config
        render = cfg.render if render is None else render
        dt = self.model.opt.timestep
        rate = cfg.tactile.rate_hz
        steps_per_sample = int(round(1.0 / (rate * dt)))
        u = push.unit
        if pad_track is not None:
            pad_track = np.asarray(pad_track, dtype=np.float64)
            if pad_track.ndim != 2 or pad_track.shape[1] != 2 or len(pad_track) < 2:
                raise ValueError(f"pad_track must be (T ≥ 2, 2), got {pad_track.shape}")
            if not np.isfinite(pad_track).all():
                raise ValueError("pad_track holds non-finite positions")
            T = len(pad_track)
            start = pad_track[0]
            if pad_fine is not None:
                pad_fine = np.asarray(pad_fine, dtype=np.float64)
                if pad_fine.ndim != 2 or pad_fine.shape[1] != 3 or len(pad_fine) < 2:
                    raise ValueError(f"pad_fine must be (N ≥ 2, 3), got {pad_fine.shape}")
                if not np.isfinite(pad_fine).all() or np.any(np.diff(pad_fine[:, 0]) <= 0):
                    raise ValueError("pad_fine needs finite rows at strictly increasing times")
        elif pad_fine is not None:
            raise ValueError("pad_fine needs pad_track")
        else:
            profile = speed_profile(push, self.config.push)
            T = int(round(cfg.push.horizon * rate)) + 1
            start = self.pad_start(push) if start is None else np.asarray(start, dtype=np.float64)

        pose = np.zeros((T, 3))
        force = np.zeros((T, 2))
        contact_share = np.zeros(T)
        pusher = np.zeros((T, 2))
        time = np.arange(T) / rate
        rgb = depth = s0 = outline = outline_end = None
        if render:
            H, W = cfg.camera.height, cfg.camera.width
            rgb = np.zeros((T, H, W, 3), np.uint8)
            depth = np.zeros((T, H, W), np.float32)
        tr = (
            {"time": [], "pose": [], "velocity": [], "force": [], "support_load": []}
            if trace
            else None
        )

        # Physics steps of each sample: `timestep`, split into `dynamic_substeps` while a
        # release push accelerates, releases and slides. The pad trajectory at every step is
        # computed once (the loop only copies it in).
        substeps = np.ones(T, dtype=np.int64)
        if pad_track is not None:
            substeps[1:] = cfg.physics.dynamic_substeps
        elif push.profile == "release":
            dynamic_end = profile.times[-2] + SLIDE_WINDOW
            substeps[1:] = np.where(time[:-1] < dynamic_end, cfg.physics.dynamic_substeps, 1)
        step_dt = np.repeat(dt / substeps[1:], steps_per_sample * substeps[1:])
        t_steps = np.concatenate([[0.0], np.cumsum(step_dt)[:-1]])
        if pad_fine is not None:
            t_fine = pad_fine[:, 0]
            pad_pos = np.column_stack([np.interp(t_steps, t_fine, pad_fine[:, i]) for i in (1, 2)])
            fine_vel = np.diff(pad_fine[:, 1:], axis=0) / np.diff(t_fine)[:, None]  # (N - 1, 2)
            seg = np.searchsorted(t_fine, t_steps, side="right") - 1
            inside = (seg >= 0) & (seg < len(fine_vel))
            pad_vel = np.where(inside[:, None], fine_vel[np.clip(seg, 0, len(fine_vel) - 1)], 0.0)
            moving_fine = np.flatnonzero(np.any(fine_vel != 0.0, axis=1))
            pad_stops = (
                np.inf
                if len(moving_fine) == 0 or t_fine[moving_fine[-1] + 1] >= time[-1]
                else float(t_fine[moving_fine[-1] + 1])
            )
            start, vel0 = pad_pos[0], pad_vel[0]
        elif pad_track is not None:
            pad_pos = np.column_stack([np.interp(t_steps, time, pad_track[:, i]) for i in (0, 1)])
            seg_vel = np.diff(pad_track, axis=0) * rate  # (T - 1, 2)
            pad_vel = np.repeat(seg_vel, steps_per_sample * substeps[1:], axis=0)
            moving_seg = np.flatnonzero(np.any(seg_vel != 0.0, axis=1))
            last = moving_seg[-1] if len(moving_seg) else None
            pad_stops = np.inf if last is None or last == T - 2 else time[last + 1]
            vel0 = seg_vel[0]
        else:
            pad_pos = start[None] + np.outer(profile.distance(t_steps), u)
            pad_vel = np.outer(np.interp(t_steps, profile.times, profile.speeds), u)
            moving = [i for i, v in enumerate(profile.speeds) if v != 0.0]
            pad_stops = (
                np.inf
                if not moving or moving[-1] == len(profile.speeds) - 1
                else (profile.times[moving[-1] + 1])
            )
            vel0 = u * profile.speed(0.0)

        model, data = self.model, self.data
        qa, va = self._pad_qpos, self._pad_qvel
        self._set_pad(start, vel0)
        mujoco.mj_forward(model, data)
        step = 0
        if stop_at_rest is not None and render:
            raise ValueError("stop_at_rest needs render=False (the held samples have no images)")
        try:
            for k in range(T):
                if (
                    stop_at_rest is not None
                    and k > 1
                    and time[k - 1] > pad_stops
                    and np.all(np.abs(self.object_velocity()) < stop_at_rest)
                ):
                    pose[k:] = pose[k - 1]
                    pusher[k:] = pusher[k - 1]
                    break
                if k > 0:
                    acc = np.zeros(2)
                    touching = 0
                    n = steps_per_sample * int(substeps[k])
                    model.opt.timestep = dt / int(substeps[k])
                    for _ in range(n):
                        data.qpos[qa : qa + 2] = pad_pos[step]
                        data.qvel[va : va + 2] = pad_vel[step]
                        mujoco.mj_step(model, data)
                        step += 1
                        f = -data.qfrc_constraint[va : va + 2]
                        acc += f
                        touching += bool(f[0] or f[1])
                        if tr is not None:
                            tr["time"].append(t_steps[step - 1] + step_dt[step - 1])
                            tr["pose"].append(self.object_pose())
                            tr["velocity"].append(self.object_velocity())
                            tr["force"].append(f.copy())
                            tr["support_load"].append(self.support_load())
                    force[k] = acc / n
                    contact_share[k] = touching / n
                pose[k] = self.object_pose()
                pusher[k] = data.qpos[qa : qa + 2]
                if render:
                    if k == 0:
                        s0 = self.renderer.segmentation(data)
                        outline = self.outline_mask()
                    if k == T - 1:
                        outline_end = self.outline_mask()
                    rgb[k], depth[k] = self.renderer.rgbd(data)
        finally:
            model.opt.timestep = dt

        noise = rng.normal(0.0, cfg.tactile.force_noise_std, size=(T, 2))
        contact = (contact_share >= cfg.tactile.contact_threshold).astype(np.float64)
        tactile = np.column_stack([force + noise, contact])
        tactile[0, :2] = noise[0]
        if tr is not None:
            tr = {k: np.asarray(v) for k, v in tr.items()}
        return PushRecord(
            push, time, pose, tactile, force, pusher, rgb, depth, s0, tr, outline,
            outline_mask_end=outline_end,
        )  # fmt: skip

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None
