"""`mujoco.sysid` as a baseline identifier: φ = (m, μ, c_x, c_y, I_z) fitted to recorded pushes
in the testbed's scene by MuJoCo's own system identification (shipped with mujoco 4.0.0; needs
absl-py, colorama and tabulate, and plotly only for its HTML report, which is not used).

sysid's pieces as used here: a `ParameterDict` of `Parameter`s with box bounds; one
`ModelSequences` (an `MjSpec`, an initial state, a control and a sensor `TimeSeries` per push)
per physics step; `build_residual_fn` → `optimize(optimizer="mujoco")`, MuJoCo's
box-constrained Levenberg–Marquardt (`mujoco.minimize.least_squares` with
`OPTIMISER_OPTIONS`, forward-difference Jacobian, every candidate rolled out by
`mujoco.rollout`); `calculate_intervals` at the optimum: covariance
s²(JᵀJ)⁻¹, s² the residual variance (reduced χ²), Student-t half-widths, infinite along a
direction the data do not reveal. There is no prior: plain least squares from the start φ.

How sysid's model differs from the testbed's replay (`identification.replay.simulate_track`):

- Pad: sysid rolls out *controls*, so the pad (the testbed's 50 kg body on its x/y slide
  joints) is driven by actuators tracking its reference, the push's speed profile from
  `PushTrack.start` (or `PushTrack.pad`) as `PushSimulator.execute` computes it: a velocity
  servo on the reference velocity (kv = `PAD_DAMPING_STEP` · mass / step), a critically damped
  position servo and a motor feeding forward mass × reference acceleration; it tracks within
  ~0.1 mm (contact force / kp). The testbed writes the pad's qpos/qvel every step instead (a
  velocity jump per step, no acceleration within one). The model steps with semi-implicit
  Euler, not the testbed's implicitfast, whose implicit servo damping enters the contact
  solve (a release push turned 14% more); the object has no velocity-dependent force, so
  both integrators treat it alike. At the true φ what remains is ≤ 0.01 noise units on a
  constant push; a release push (1 m/s² from rest, starting in contact) is where the two pad
  models part: 0.4 mm / 0.3° after the slide on a 0.23 kg L-shape, but 2.4 cm / 18° on a
  1.06 kg octagon pushed at a corner (`sysid_residuals` measures it; the same model with the
  pad's qpos/qvel written as the testbed does matches to 1 µm).
- Support loads: the testbed builds its supports for each φ (a CoM outside the grid's hull
  adds the outline's vertices, and unloaded supports are dropped), which changes the model's
  state size, and sysid's initial states are fixed per sequence. So every candidate has the
  same superset of supports (grid, ring and vertices); a custom `BuildModelFn` recomputes the
  loads with the testbed's own `scene.support_loads` on the testbed's point set for that CoM
  and writes each support's mass and spring load, and the body's mass, CoM and I_z as
  `build_mjcf` does; a support the testbed would not have loses its contact, spring and
  weight (gravity compensated) and keeps a negligible mass (`UNLOADED_MASS`). So the
  CoM-dependent load distribution is the testbed's, exactly.
- Physics step: one per sequence. Release pushes and pushes along a recorded pad track are
  simulated at the testbed's fine step (timestep / dynamic_substeps) throughout, constant
  pushes at its timestep; the testbed refines only a release's dynamic phase. As the testbed
  settles the object before each push, each rollout first holds the pad at its start for
  `SETTLE_TIME`, so the candidate's supports settle under its own loads (from the start φ's
  settled state); every sample is simulated (no stop at rest).
- Residual (sysid's `modify_residual` hook): the contact force of pad on object (a MuJoCo
  `contact` sensor) averaged over each tactile sample window as the testbed averages it,
  and the object pose at the sample times, in noise units (force: the recording's tactile
  noise; pose: `IdentifyConfig.position_noise` / `angle_noise`); sample 0 is left out.
- Parameters: sysid's finite-difference step is absolute below |x| = 1 (one scalar eps), so
  φ is searched in the project's normalised coordinates (`common.params.normalise_params`:
  log m, log μ, log I_z, CoM scaled by the catalogue ranges), all O(1). sysid's bounds are a
  box, so a candidate outside the simulable set (CoM beyond the footprint's hull less the
  testbed's margin, I_z above the footprint's bound) is projected onto it
  (`replay.feasible`) before it is simulated: its misfit is flat beyond.
"""

from __future__ import annotations

import io
import math
import os
import re
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from scipy.special import stdtrit
from shapely.geometry import MultiPoint, Point

from pushtoknow.common.errors import IdentificationError
from pushtoknow.common.params import (
    GRAVITY,
    PARAM_NAMES,
    ObjectParams,
    denormalise_params,
    normalise_params,
)
from pushtoknow.identification.fit import UNKNOWN_FORCE_NOISE
from pushtoknow.identification.identify_config import IdentifyConfig
from pushtoknow.identification.prior import footprint_prior, polygon_moments
from pushtoknow.identification.replay import (
    COM_INSET,
    MAX_FRICTION,
    PushTrack,
    ReplayScene,
    feasible,
)
from pushtoknow.testbed import render as _render  # sets MUJOCO_GL before mujoco is imported
from pushtoknow.testbed.objects import COM_MARGIN, MAX_MASS, MIN_GYRATION_RADIUS, ObjectSpec
from pushtoknow.testbed.push import speed_profile
from pushtoknow.testbed.scene import (
    LOAD_SPRING_REST,
    SUPPORT_MASS_SHARE,
    TABLE_BITS,
    build_mjcf,
    support_loads,
    support_points,
)
from pushtoknow.testbed.shapes import Footprint
from pushtoknow.testbed.sim import SETTLE_TIME
from pushtoknow.testbed.sim_config import SimConfig

mujoco: Any = _render.mujoco  # the compiled module: mypy sees none of its names

LEVEL = 0.9
PAD_DAMPING_STEP = 0.5  # pad velocity servo: kv · timestep / pad mass (explicit, stable below 2)
UNLOADED_MASS = 1e-9  # share of m a support the testbed drops keeps (a moving body needs one)
FORCE_SENSOR = "pad_force"
MIN_MASS, MIN_FRICTION = 0.02, 0.05  # kg, -: lower bounds of the search box
MAX_INERTIA = 1.0  # kg·m²: upper bound of the box (each candidate is clamped to its footprint's)
# Settings of sysid's optimiser (`mujoco.minimize.least_squares`) besides its defaults: the
# columns scaled by the Jacobian, the Levenberg-Marquardt regulariser started at 1e-3 and raised
# ×√10 per rejected step (its defaults, from 1e-6 by ×10^0.1, spend ~100 rollouts of every push
# on one rejected step). On noiseless pushes: as accurate, with 2.5 times fewer evaluations.
OPTIMISER_OPTIONS: dict[str, Any] = {"x_scale": "jac", "mu_min": 1e-3, "mu_factor": 10**0.5}
# sysid's finite-difference step (normalised units; 0.2 mm of CoM, 1% of m, μ, I_z): 1e-3 stalled
# from the prior mean on one of three bench objects (the simulator's step-to-step jitter), 1e-4
# on a single push; `identify` steps 0.01–0.15 in its coordinates
FD_STEP = 1e-2
FAR = 1e3  # m: a CoM this far away makes `support_points` add the outline's vertices
_SUPPORT_BODY = re.compile(r'<body name="support\d+".*?</body>', re.S)


def sysid_module():
    """`mujoco.sysid`, or IdentificationError when its optional dependencies are missing (its
    package then imports empty)."""
    from mujoco import sysid

    if not hasattr(sysid, "optimize"):
        raise IdentificationError(
            "mujoco.sysid is unavailable: install its dependencies (pip install absl-py "
            "colorama tabulate)"
        )
    return sysid


@dataclass(frozen=True)
class SupportLayout:
    """The fixed supports of every candidate: points (N, 2) (m, object frame), the first
    `n_base` the testbed's grid and ring, the rest the shrunk outline's vertices."""

    points: np.ndarray
    n_base: int

    @classmethod
    def of(cls, footprint: Footprint, config: SimConfig) -> SupportLayout:
        sup = config.support
        base = support_points(footprint, sup.spacing, sup.edge_margin)
        full = support_points(footprint, sup.spacing, sup.edge_margin, (FAR, FAR))
        return cls(full, len(base))

    def loads(self, com) -> np.ndarray:
        """(N,) shares of the weight for a CoM (2,): the testbed's (`support_loads` on the
        points `support_points` gives for that CoM), 0 on the supports the testbed would not
        have or drops."""
        base = self.points[: self.n_base]
        hull = MultiPoint([tuple(p) for p in base]).convex_hull.buffer(1e-9)
        pts = base if hull.contains(Point(*com)) else self.points
        w = np.zeros(len(self.points))
        w[: len(pts)] = support_loads(pts, com)
        w[w <= 1e-9] = 0.0  # the testbed drops these
        return w


def _scene_xml(scene: ReplayScene, layout: SupportLayout, timestep: float) -> str:
    """MJCF of the sysid model: `build_mjcf`'s scene (no marker decal) with the fixed
    supports (their loads written later by `apply_phi`), the pad's servos and the sensors."""
    cfg = scene.sim_config.model_copy(update={"render": False, "orientation_marker": False})
    spec = ObjectSpec(
        shape=scene.shape, params=ObjectParams(0.5, 0.5, 0.0, 0.0, 1e-3), height=scene.height
    )
    xml = build_mjcf(spec, cfg)
    sup = cfg.support
    bodies = "".join(
        f'<body name="support{i}" pos="{x:.6f} {y:.6f} 0">'
        f'<joint name="support{i}_z" type="slide" axis="0 0 1" stiffness="1" '
        f'springref="{LOAD_SPRING_REST}"/>'
        f'<inertial pos="0 0 {sup.radius}" mass="1e-3" diaginertia="1e-9 1e-9 1e-9"/>'
        f'<geom name="support{i}" type="sphere" size="{sup.radius}" pos="0 0 {sup.radius}" '
        f'contype="1" conaffinity="1" condim="3" friction="0.5 0 0" mass="0" '
        f'rgba="0 0 0 0" group="3"/></body>'
        for i, (x, y) in enumerate(layout.points)
    )
    first = _SUPPORT_BODY.search(xml)
    if first is None:
        raise IdentificationError("the testbed's scene has no supports to replace")
    xml = xml[: first.start()] + bodies + _SUPPORT_BODY.sub("", xml[first.start() :])
    xml = re.sub(r'timestep="[^"]*"', f'timestep="{timestep!r}"', xml, count=1)
    xml = xml.replace('integrator="implicitfast"', 'integrator="Euler"')
    kv = PAD_DAMPING_STEP * cfg.pad.mass / timestep
    kp = kv * kv / (4.0 * cfg.pad.mass)  # critically damped
    extra = f"""
  <actuator>
    <position name="pad_x" joint="pusher_x" kp="{kp!r}"/>
    <position name="pad_y" joint="pusher_y" kp="{kp!r}"/>
    <velocity name="pad_vx" joint="pusher_x" kv="{kv!r}"/>
    <velocity name="pad_vy" joint="pusher_y" kv="{kv!r}"/>
    <motor name="pad_fx" joint="pusher_x"/>
    <motor name="pad_fy" joint="pusher_y"/>
  </actuator>
  <sensor>
    <contact name="{FORCE_SENSOR}" geom1="pad" body2="object" data="force" reduce="netforce"/>
    <jointpos name="object_x" joint="object_x"/>
    <jointpos name="object_y" joint="object_y"/>
    <jointpos name="object_yaw" joint="object_yaw"/>
  </sensor>
</mujoco>"""
    return xml.replace("</mujoco>", extra)


def apply_phi(spec, phi: np.ndarray, layout: SupportLayout, scene: ReplayScene) -> None:
    """Write a simulable φ (5,) SI into the sysid model's spec as `build_mjcf` builds it: the
    body's mass, CoM and I_z, each support's mass, spring load and friction."""
    m, mu, cx, cy, iz = map(float, phi)
    w = layout.loads((cx, cy))
    kept = w > 0
    com = np.array([cx, cy])
    spread = float(w[kept] @ np.sum((layout.points[kept] - com) ** 2, axis=1))
    share = min(SUPPORT_MASS_SHARE, 0.5 * iz / max(m * spread, 1e-12))
    h = scene.height
    body_mass = (1.0 - share) * m
    body_inertia = iz - share * m * spread
    ixx = body_inertia / 2 + body_mass * h * h / 12
    body = spec.body("object")
    body.mass = body_mass
    body.ipos = [cx, cy, h / 2]
    body.inertia = [ixx, ixx, body_inertia]
    for i, wi in enumerate(w):
        support, geom = spec.body(f"support{i}"), spec.geom(f"support{i}")
        if wi > 0:
            m_i = share * wi * m
            stiffness = (wi * m * GRAVITY - m_i * GRAVITY) / -LOAD_SPRING_REST
            contact, gravcomp = TABLE_BITS, 0.0
        else:  # a support the testbed does not have: no contact, no force, no weight
            m_i, stiffness, contact, gravcomp = UNLOADED_MASS * m, 0.0, 0, 1.0
        support.mass = m_i
        support.gravcomp = gravcomp
        spec.joint(f"support{i}_z").stiffness = [stiffness, 0.0, 0.0]
        geom.contype = geom.conaffinity = contact
        geom.friction = [mu, 0.0, 0.0]


def settle_steps(timestep: float) -> int:
    """Physics steps each rollout holds the pad at its start before the push: the testbed's
    `SETTLE_TIME`, so every candidate's supports settle under its own loads."""
    return int(round(SETTLE_TIME / timestep))


def pad_controls(
    track: PushTrack, config: SimConfig, timestep: float
) -> tuple[np.ndarray, np.ndarray, int]:
    """The pad's reference at every physics step: times (S + N + 1,) s and controls
    (S + N + 1, 6) (position (m), velocity (m/s), pad mass × acceleration (N), x then y), and
    the steps per tactile sample n (N = n (T − 1)). First S = `settle_steps` steps at rest at
    the start, then the push as `PushSimulator.execute` drives the pad: the speed profile from
    `track.start`, or `track.pad` linearly between samples."""
    rate = config.tactile.rate_hz
    n = int(round(1.0 / (rate * timestep)))
    T = len(track.force)
    t = np.arange(n * (T - 1) + 1) * timestep
    if track.pad is not None:
        pad = np.asarray(track.pad, dtype=np.float64)
        times = np.arange(T) / rate
        pos = np.column_stack([np.interp(t, times, pad[:, i]) for i in (0, 1)])
        seg = np.diff(pad, axis=0) * rate
        vel = seg[np.minimum(np.arange(len(t)) // n, T - 2)]
    else:
        profile = speed_profile(track.push, config.push)
        u = track.push.unit
        pos = np.asarray(track.start, dtype=np.float64)[None] + np.outer(profile.distance(t), u)
        vel = np.outer(np.interp(t, profile.times, profile.speeds), u)
    S = settle_steps(timestep)
    pos = np.vstack([np.repeat(pos[:1], S, axis=0), pos])
    vel = np.vstack([np.zeros((S, 2)), vel])
    acc = np.zeros_like(vel)
    if track.pad is None:
        acc[:-1] = np.diff(vel, axis=0) / timestep
    else:  # the pad's first speed, reached in the last settling step
        acc[S - 1] = vel[S] / timestep
    t = np.arange(len(pos)) * timestep
    return t, np.hstack([pos, vel, config.pad.mass * acc]), n


def _check_inputs(scene: ReplayScene, tracks: Sequence[PushTrack], phi0) -> np.ndarray:
    if not isinstance(scene, ReplayScene):
        raise IdentificationError(f"scene must be a ReplayScene, got {type(scene).__name__}")
    if not tracks:
        raise IdentificationError("no pushes to identify from")
    for i, tr in enumerate(tracks):
        if not isinstance(tr, PushTrack):
            raise IdentificationError(f"push {i}: a PushTrack is needed, got {type(tr).__name__}")
        f, p = np.asarray(tr.force), np.asarray(tr.pose)
        if f.ndim != 2 or f.shape[1] != 2 or p.ndim != 2 or p.shape[1] != 3:
            raise IdentificationError(
                f"push {i}: force must be (T, 2) and pose (T, 3), got {f.shape} and {p.shape}"
            )
        if len(f) != len(p) or len(f) < 2:
            raise IdentificationError(
                f"push {i}: force and pose need the same T ≥ 2 samples, got {len(f)} and {len(p)}"
            )
        if not (np.isfinite(f).all() and np.isfinite(p).all()):
            raise IdentificationError(f"push {i}: non-finite values in its force or pose track")
        if tr.pad is not None and np.shape(tr.pad) != (len(f), 2):
            raise IdentificationError(
                f"push {i}: pad track must be (T, 2) = ({len(f)}, 2), got {np.shape(tr.pad)}"
            )
        if tr.pad is None and tr.start is None:
            raise IdentificationError(f"push {i}: no pad start and no pad track to drive the pad")
    phi = np.asarray(phi0, dtype=np.float64)
    if phi.shape != (5,) or not np.isfinite(phi).all() or min(phi[0], phi[1], phi[4]) <= 0:
        raise IdentificationError(
            f"start φ must be 5 finite values {PARAM_NAMES} with m, μ, I_z > 0, got "
            f"{np.asarray(phi0).tolist()}"
        )
    return phi


def start_phi(scene: ReplayScene) -> np.ndarray:
    """(5,) SI: the prior mean given the footprint (`prior.footprint_prior`: m and μ at the
    catalogue prior's, the CoM at the centroid of where it can lie, I_z the uniform plate's)."""
    fp = scene.footprint
    region = fp.com_region(COM_MARGIN)
    _, plate = polygon_moments(fp.vertices)
    z, _ = footprint_prior(np.asarray(region.exterior.coords)[:-1], float(np.sqrt(np.trace(plate))))
    return denormalise_params(z)


@dataclass(frozen=True)
class SysidResult:
    """What `sysid_fit` found, SI unless stated, PARAM_NAMES order.

    estimate (5,): sysid's optimum (projected onto the simulable set, as simulated); start (5,);
    lower, upper (5,): the 90% interval from `calculate_intervals` (symmetric in the normalised
    coordinates, so asymmetric in SI for m, μ, I_z), NaN for a parameter the data leave
    unbounded; None when sysid gave no covariance (an empty or singular Jacobian);
    std_norm (5,), cov_norm (5, 5): its standard deviations and covariance in the normalised
    coordinates (inf / huge where unbounded), None likewise; reduced_chi2: sysid's s², the
    residual variance it scales the covariance by (≈ 1 when model and noise are right);
    objective_start, objective: ½‖r‖² at the start and at the optimum; iterations; status:
    the optimiser's termination line; evaluations: candidate φ evaluated (each a rollout of
    every push), rollouts: single push rollouts; pushes; seconds: wall time.
    """

    estimate: np.ndarray
    start: np.ndarray
    lower: np.ndarray | None
    upper: np.ndarray | None
    std_norm: np.ndarray | None
    cov_norm: np.ndarray | None
    reduced_chi2: float
    objective_start: float
    objective: float
    iterations: int
    status: str
    evaluations: int
    rollouts: int
    pushes: int
    residuals: int
    seconds: float
    level: float = LEVEL

    @property
    def mu_m(self) -> float:
        return float(self.estimate[0] * self.estimate[1])

    def zscore(self, truth) -> np.ndarray:
        """(5,) (truth − estimate) / std in the normalised coordinates; 0 where the interval is
        unbounded (it holds every value), NaN without a covariance."""
        if self.std_norm is None:
            return np.full(5, np.nan)
        d = normalise_params(np.asarray(truth, dtype=np.float64)) - normalise_params(self.estimate)
        with np.errstate(divide="ignore", invalid="ignore"):
            z = d / self.std_norm
        return np.where(np.isfinite(self.std_norm), z, 0.0)

    def to_json(self) -> dict:
        def interval(i):
            if self.lower is None or not np.isfinite(self.lower[i]):
                return None
            return [float(self.lower[i]), float(self.upper[i])]

        return {
            "method": "mujoco.sysid (mujoco.minimize Levenberg-Marquardt, no prior)",
            "parameters": {
                k: {
                    "estimate": float(self.estimate[i]),
                    "start": float(self.start[i]),
                    "interval90": interval(i),
                }
                for i, k in enumerate(PARAM_NAMES)
            },
            "intervals": None
            if self.lower is None
            else "sysid calculate_intervals: s²(JᵀJ)⁻¹ in normalised coordinates, Student t; "
            "null where unbounded",
            "mu_m": self.mu_m,
            "std_norm": None
            if self.std_norm is None
            else [float(s) if np.isfinite(s) else None for s in self.std_norm],
            "reduced_chi2": self.reduced_chi2,
            "objective_start": self.objective_start,
            "objective": self.objective,
            "iterations": self.iterations,
            "status": self.status,
            "evaluations": self.evaluations,
            "rollouts": self.rollouts,
            "pushes": self.pushes,
            "residuals": self.residuals,
            "seconds": self.seconds,
            "level": self.level,
        }


def _bounds(scene: ReplayScene) -> tuple[np.ndarray, np.ndarray]:
    """The search box (5,) SI: m, μ within the replay's limits, the CoM within the bounding box
    of where it can lie, I_z between the least any candidate gets and `MAX_INERTIA`."""
    region = scene.footprint.com_region(COM_MARGIN + COM_INSET)
    x0, y0, x1, y1 = region.bounds
    lo = np.array([MIN_MASS, MIN_FRICTION, x0, y0, 1.001 * MIN_MASS * MIN_GYRATION_RADIUS**2])
    hi = np.array([MAX_MASS, MAX_FRICTION, x1, y1, MAX_INERTIA])
    return lo, hi


class _Problem:
    """The sysid model of one scene and its pushes (module doc)."""

    def __init__(
        self,
        scene: ReplayScene,
        tracks: Sequence[PushTrack],
        phi0: np.ndarray,
        sigmas: np.ndarray,
    ):
        sysid = sysid_module()
        self.scene = scene
        self.footprint = scene.footprint
        self.layout = SupportLayout.of(self.footprint, scene.sim_config)
        self.sigmas = sigmas
        cfg = scene.sim_config
        dt = cfg.physics.timestep
        fine = dt / cfg.physics.dynamic_substeps
        self.sequences = []
        self.pushes = len(tracks)
        groups: dict[bool, list[PushTrack]] = {False: [], True: []}
        for tr in tracks:
            groups[self.is_fine(tr)].append(tr)
        for is_fine, group in groups.items():
            if not group:
                continue
            h = fine if is_fine else dt
            spec = mujoco.MjSpec.from_string(_scene_xml(scene, self.layout, h))
            apply_phi(spec, feasible(phi0, self.footprint)[0], self.layout, scene)
            model = spec.compile()
            names, states, controls, sensors = [], [], [], []
            for j, tr in enumerate(group):
                t, ctrl, _ = pad_controls(tr, cfg, h)
                names.append(f"push{j}")
                states.append(self._initial_state(model, tr, ctrl[0]))
                controls.append(sysid.TimeSeries(t, ctrl))
                T = len(tr.force)
                data = np.zeros((T, model.nsensordata))
                data[:, :2] = tr.force
                data[:, 3:6] = tr.pose
                times = settle_steps(h) * h + np.arange(T) / cfg.tactile.rate_hz
                sensors.append(sysid.TimeSeries(times, data))
            self.sequences.append(
                sysid.ModelSequences(
                    "fine" if is_fine else "coarse",
                    spec,
                    names,
                    states,
                    controls,
                    sensors,
                )
            )

    def is_fine(self, track: PushTrack) -> bool:
        """Whether a push is simulated at the testbed's fine step (a release push, a recorded
        pad track), in the second sequence."""
        return track.pad is not None or track.push.profile == "release"

    def residual_fn(self, threads: int | None):
        """sysid's residual function of this problem (`build_residual_fn`)."""
        return sysid_module().build_residual_fn(
            models_sequences=self.sequences,
            build_model=self.build_model,
            modify_residual=self.modify_residual,
            n_threads=threads or os.cpu_count() or 1,
            resample_true=False,
        )

    def _object_pose_world(self, pose) -> np.ndarray:
        dx, dy = self.scene.frame_offset
        x, y, th = map(float, pose)
        c, s = math.cos(th), math.sin(th)
        return np.array([x + c * dx - s * dy, y + s * dx + c * dy, th])

    def _initial_state(self, model, track: PushTrack, ctrl0: np.ndarray) -> np.ndarray:
        """The testbed's start of a push (`PushSimulator.reset`) for the start φ: the object at
        rest at the record's pose0, its supports settled, the pad at rest at its start (each
        rollout settles again, `settle_steps`, under the candidate's loads)."""
        data = mujoco.MjData(model)
        ox = model.joint("object_x")
        qa, va = int(ox.qposadr[0]), int(ox.dofadr[0])
        px = model.joint("pusher_x")
        pa, pv = int(px.qposadr[0]), int(px.dofadr[0])
        pose = self._object_pose_world(track.pose0)
        data.qpos[qa : qa + 3] = pose
        park = pose[:2] + 0.5
        data.ctrl[:] = [*park, 0.0, 0.0, 0.0, 0.0]
        for _ in range(settle_steps(model.opt.timestep)):
            data.qpos[pa : pa + 2] = park
            data.qvel[pv : pv + 2] = 0.0
            mujoco.mj_step(model, data)
        data.time = 0.0
        data.qpos[pa : pa + 2] = ctrl0[:2]
        data.qvel[pv : pv + 2] = 0.0
        data.qvel[va : va + 3] = 0.0
        mujoco.mj_forward(model, data)
        spec = mujoco.mjtState.mjSTATE_FULLPHYSICS
        state = np.empty(mujoco.mj_stateSize(model, spec))
        mujoco.mj_getState(model, data, state, spec)
        return state

    def build_model(self, params, spec):
        """sysid's BuildModelFn: the candidate (projected onto the simulable set) written into
        the spec, compiled."""
        phi = self.phi(params.as_vector())
        apply_phi(spec, phi, self.layout, self.scene)
        return spec.compile()

    def phi(self, z: np.ndarray) -> np.ndarray:
        """Normalised coordinates (5,) → the simulable φ (5,) SI that is simulated."""
        return feasible(denormalise_params(np.asarray(z, dtype=np.float64)), self.footprint)[0]

    def modify_residual(self, params, pred, measured, model, return_pred_all, state=None, **_):
        """sysid's ModifyResidualFn: force averaged over each tactile window and pose at the
        sample times, minus the measured, in noise units; samples 1 … T − 1."""
        sysid = sysid_module()
        T = len(measured.times)
        S = settle_steps(model.opt.timestep)  # the rollout settles first
        n = (pred.data.shape[0] - S) // (T - 1)
        force = pred.data[S : S + n * (T - 1), :2].reshape(T - 1, n, 2).mean(axis=1)
        qa = 1 + int(model.joint("object_x").qposadr[0])  # the state's column 0 is the time
        pose = state[S + n - 1 :: n][: T - 1, qa : qa + 3].copy()
        dx, dy = self.scene.frame_offset
        if dx or dy:
            c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
            pose[:, 0] -= c * dx - s * dy
            pose[:, 1] -= s * dx + c * dy
        predicted = np.hstack([force, pose])
        meas = np.hstack([measured.data[1:, :2], measured.data[1:, 3:6]])
        res = (predicted - meas) / self.sigmas
        times = measured.times[1:]
        return (
            res.ravel(),
            sysid.TimeSeries(times, predicted),
            sysid.TimeSeries(times, meas),
        )


def _sigmas(scene: ReplayScene, config: IdentifyConfig | None) -> np.ndarray:
    """(5,) noise units of a sample's residual: F_x, F_y (N), x, y (m), θ (rad)."""
    cfg = config or IdentifyConfig()
    force = cfg.force_noise or scene.sim_config.tactile.force_noise_std or UNKNOWN_FORCE_NOISE
    return np.array([force, force, cfg.position_noise, cfg.position_noise, cfg.angle_noise])


def sysid_residuals(
    scene: ReplayScene,
    tracks: Sequence[PushTrack],
    phi,
    config: IdentifyConfig | None = None,
) -> list[np.ndarray]:
    """sysid's residuals of φ (5,) SI: per push (T − 1, 5), (predicted − measured) force
    (F_x, F_y) and pose (x, y, θ) at samples 1 … T − 1 in noise units (see `sysid_fit`): how
    far sysid's model of the scene is from the pushes (e.g. from the testbed's own replay at
    the true φ)."""
    phi = _check_inputs(scene, tracks, phi)
    prob = _Problem(scene, tracks, phi, _sigmas(scene, config))
    z = normalise_params(prob.phi(normalise_params(phi)))
    params = sysid_module().ParameterDict()
    for i, name in enumerate(PARAM_NAMES):
        params.add(sysid_module().Parameter(name, z[i], z[i] - 1.0, z[i] + 1.0))
    residuals, _, _ = prob.residual_fn(1)(z, params)
    order = [i for fine in (False, True) for i, t in enumerate(tracks) if prob.is_fine(t) == fine]
    out: list[np.ndarray] = [np.empty(0)] * len(tracks)
    for i, r in zip(order, residuals, strict=True):
        out[i] = np.asarray(r).reshape(-1, 5)
    return out


def sysid_fit(
    scene: ReplayScene,
    tracks: Sequence[PushTrack],
    phi0=None,
    config: IdentifyConfig | None = None,
    max_iterations: int = 30,
    fd_step: float = FD_STEP,
    threads: int | None = None,
    **options,
) -> SysidResult:
    """Fit φ to `tracks` (K pushes: measured force (T, 2) N and pose (T, 3) m, m, rad, record
    frame) in `scene` with mujoco.sysid (module doc), from `phi0` (5,) SI (None: `start_phi`,
    the prior mean given the footprint). config: the noise model (`position_noise`,
    `angle_noise`, `force_noise`; default `IdentifyConfig()`, whose force noise is the scene's
    tactile noise); max_iterations: Levenberg–Marquardt iterations; fd_step: sysid's
    finite-difference step (normalised units); threads: rollout threads (None: the CPU count);
    options: more settings of `mujoco.minimize.least_squares` (over `OPTIMISER_OPTIONS`).
    Raises IdentificationError for bad input or a missing sysid."""
    if phi0 is None and isinstance(scene, ReplayScene):
        phi0 = start_phi(scene)
    phi0 = _check_inputs(scene, tracks, phi0)
    sysid = sysid_module()
    t0 = time.perf_counter()
    prob = _Problem(scene, tracks, phi0, _sigmas(scene, config))
    lo, hi = (normalise_params(b) for b in _bounds(scene))
    z0 = np.clip(normalise_params(feasible(phi0, prob.footprint)[0]), lo, hi)
    params = sysid.ParameterDict()
    for i, name in enumerate(PARAM_NAMES):
        params.add(sysid.Parameter(name, z0[i], lo[i], hi[i]))
    counted = {"columns": 0}
    inner = prob.residual_fn(threads)

    def residual_fn(x, p, **kw):
        counted["columns"] += 1 if np.ndim(x) == 1 else np.shape(x)[1]
        return inner(x, p, **kw)

    log = io.StringIO()
    opt_params, result = sysid.optimize(
        params,
        residual_fn,
        optimizer="mujoco",
        verbose=False,
        max_iters=max_iterations,
        eps=fd_step,
        output=log,
        **{**OPTIMISER_OPTIONS, **options},
    )
    z = np.asarray(result.x, dtype=np.float64)
    residuals, _, _ = residual_fn(z, opt_params)
    r = np.concatenate(residuals)
    jac = result.jac
    estimate = prob.phi(z)  # what was simulated: the optimum projected onto the simulable set
    centre = normalise_params(estimate)
    lower = upper = std = cov = None
    dof = r.size - z.size
    s2 = float(r @ r / max(dof, 1))
    if jac is not None and np.size(jac) and np.all(np.isfinite(jac)) and np.any(jac):
        cov, half = sysid.calculate_intervals(residuals, np.asarray(jac), alpha=1.0 - LEVEL)
        t = float(stdtrit(max(dof, 1), 0.5 + LEVEL / 2))
        std = np.asarray(half, dtype=np.float64) / t
        bounded = np.isfinite(half)
        lo_z = np.where(bounded, centre - np.where(bounded, half, 0.0), np.nan)
        hi_z = np.where(bounded, centre + np.where(bounded, half, 0.0), np.nan)
        lower = np.where(bounded, denormalise_params(np.nan_to_num(lo_z)), np.nan)
        upper = np.where(bounded, denormalise_params(np.nan_to_num(hi_z)), np.nan)
    objectives = result.extras.get("objective") or [np.nan]
    lines = [ln for ln in log.getvalue().splitlines() if ln.startswith("Terminated")]
    return SysidResult(
        estimate=estimate,
        start=phi0,
        lower=lower,
        upper=upper,
        std_norm=std,
        cov_norm=None if cov is None else np.asarray(cov),
        reduced_chi2=s2,
        objective_start=float(objectives[0]),
        objective=float(0.5 * r @ r),
        iterations=max(len(objectives) - 1, 0),
        status=lines[-1] if lines else "",
        evaluations=counted["columns"],
        rollouts=counted["columns"] * prob.pushes,
        pushes=prob.pushes,
        residuals=int(r.size),
        seconds=time.perf_counter() - t0,
    )
