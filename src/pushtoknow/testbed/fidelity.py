"""Physics fidelity probes of the testbed: chaos, quasi-static pushing, Coulomb release.

Each probe simulates a few noise-free pushes along +x through the left edge of an object
resting at the origin and returns a typed result in SI units (mm and degrees where named).
`pushtoknow bench physics` runs them all (docs/PHYSICS.md); tests/testbed/test_physics.py
asserts the targets on the same functions.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from pushtoknow.common.params import GRAVITY, ObjectParams
from pushtoknow.testbed.objects import ObjectSpec, resolve_shape
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.scene import support_points
from pushtoknow.testbed.shapes import footprint_from_shape
from pushtoknow.testbed.sim import PushRecord, PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

START_SHIFT = 5e-5  # m: the start-pose perturbation of the chaos probe (50 µm)
START_TURN = math.radians(0.05)  # rad: and its rotation (0.05°)


def uniform_inertia(shape: str, mass: float) -> float:
    """I_z (kg·m²) of a uniform plate of `shape` about its centroid (from a fine grid)."""
    pts = support_points(footprint_from_shape(resolve_shape(shape)), 0.002, 0.0)
    return float(mass * np.mean(np.sum(pts**2, axis=1)))


def probe_object(
    shape: str = "rect1",
    mass: float = 0.8,
    friction: float = 0.5,
    com: tuple[float, float] = (0.0, 0.0),
    inertia: float | None = None,
) -> ObjectSpec:
    """An object for the probes; I_z defaults to 0.8 × the uniform plate's (a valid value)."""
    if inertia is None:
        inertia = 0.8 * uniform_inertia(shape, mass)
    return ObjectSpec(shape=shape, params=ObjectParams(mass, friction, com[0], com[1], inertia))


def push_through(
    spec: ObjectSpec,
    offset: float = 0.0,
    profile: str = "constant",
    start_pose=(0.0, 0.0, 0.0),
    config: SimConfig | None = None,
    speed: float | None = None,
    theta: float = 0.0,
) -> PushRecord:
    """Push along +x on the line y = `offset` (m, world) with a physics-rate trace. The contact
    point is where that line enters the footprint placed at (0, 0, `theta`), so a perturbed
    start pose keeps the same commanded push."""
    cfg = config or SimConfig()
    left = _entry_x(spec, offset, theta)
    if speed is None:
        speed = cfg.push.profile_speed(profile)
    sim = PushSimulator(spec, cfg)
    try:
        sim.reset(start_pose)
        push = Push((left, offset), 0.0, profile, speed)
        return sim.execute(push, np.random.default_rng(0), render=False, trace=True)
    finally:
        sim.close()


def _entry_x(spec: ObjectSpec, y: float, theta: float) -> float:
    from shapely import affinity
    from shapely.geometry import LineString

    poly = affinity.rotate(spec.footprint.polygon, theta, origin=(0, 0), use_radians=True)
    hit = poly.intersection(LineString([(-1.0, y), (1.0, y)]))
    if hit.is_empty:
        raise ValueError(f"the line y = {y} m misses the object")
    return float(hit.bounds[0])


# ----------------------------------------------------------------------------- chaos
@dataclass(frozen=True)
class Sensitivity:
    """How much a push changes when its start pose moves by 50 µm (x or y) or 0.05°: the
    worst of the three. force_rms_n: RMS over the 10 Hz samples of the noise-free force
    difference (N); final_mm / final_deg: final pose difference."""

    shape: str
    offset_m: float
    travel_mm: float
    turn_deg: float
    force_rms_n: float
    final_mm: float
    final_deg: float


FACE_ON: dict[str, float] = {"hex": math.pi / 6}  # start θ that turns a face, not a vertex, to −x


def start_pose_sensitivity(
    shape: str = "rect1", offset: float = 0.0, config: SimConfig | None = None
) -> Sensitivity:
    """A constant push along +x at `offset` (m) from the line through the centroid, onto a face
    of `shape`, and the same push with the start pose perturbed."""
    spec = probe_object(shape)
    theta = FACE_ON.get(shape, 0.0)
    base = push_through(spec, offset, start_pose=(0.0, 0.0, theta), config=config, theta=theta)
    worst = np.zeros(3)
    for delta in ((START_SHIFT, 0, 0), (0, START_SHIFT, 0), (0, 0, START_TURN)):
        start = np.array([0.0, 0.0, theta]) + delta
        other = push_through(spec, offset, start_pose=start, config=config, theta=theta)
        df = other.force_clean - base.force_clean
        dp = other.pose[-1] - base.pose[-1] - np.asarray(delta)
        worst = np.maximum(
            worst,
            [
                math.sqrt(float(np.mean(np.sum(df**2, axis=1)))),
                1e3 * math.hypot(dp[0], dp[1]),
                math.degrees(abs(dp[2])),
            ],
        )
    d = base.pose[-1] - base.pose[0]
    return Sensitivity(
        shape,
        offset,
        1e3 * math.hypot(d[0], d[1]),
        math.degrees(d[2]),
        *map(float, worst),
    )


# -------------------------------------------------------------------- quasi-static
@dataclass(frozen=True)
class PathDependence:
    """How far a constant push's pose track moves when only m (or only μ) changes, CoM and
    I_z fixed: the largest difference over the track from the reference object (mm, deg).
    Quasi-static pushing allows none beyond the chaotic spread."""

    varied: str
    values: tuple[float, ...]
    max_mm: float
    max_deg: float
    force_shape_diff: float  # largest |F/(μmg) − reference F/(μmg)| over the 10 Hz samples


def path_dependence(
    varied: str,
    values: tuple[float, ...],
    shape: str = "rect1",
    offset: float = 0.02,
    com: tuple[float, float] = (0.01, 0.01),
    config: SimConfig | None = None,
) -> PathDependence:
    """`varied` is "mass" or "friction"; the first value is the reference."""
    inertia = 0.8 * uniform_inertia(shape, 0.2)  # valid for every mass of the catalogue

    def record(value):
        kw = {"mass": 0.8, "friction": 0.5, varied: value}
        spec = probe_object(shape, kw["mass"], kw["friction"], com, inertia)
        rec = push_through(spec, offset, config=config)
        return rec, rec.force_clean / (kw["mass"] * kw["friction"] * GRAVITY)

    ref, ref_f = record(values[0])
    mm = deg = fshape = 0.0
    for v in values[1:]:
        rec, f = record(v)
        d = rec.pose - ref.pose
        mm = max(mm, 1e3 * float(np.max(np.hypot(d[:, 0], d[:, 1]))))
        deg = max(deg, math.degrees(float(np.max(np.abs(d[:, 2])))))
        fshape = max(fshape, float(np.max(np.abs(f - ref_f))))
    return PathDependence(varied, tuple(values), mm, deg, fshape)


@dataclass(frozen=True)
class SteadyForce:
    """Centred constant push on a centred-CoM rect1: mean noise-free ‖F‖ over the second half
    of the push / (μ·m·g), and the standard deviation of the physics-rate force there (N)."""

    mass: float
    friction: float
    ratio: float
    chatter_n: float


def steady_force(mass: float, friction: float, config: SimConfig | None = None) -> SteadyForce:
    rec = push_through(probe_object("rect1", mass, friction), 0.0, config=config)
    f10 = np.linalg.norm(rec.force_clean, axis=1)
    tr = np.linalg.norm(rec.trace["force"], axis=1)
    ratio = float(f10[len(f10) // 2 :].mean()) / (mass * friction * GRAVITY)
    return SteadyForce(mass, friction, ratio, float(tr[len(tr) // 2 :].std()))


# ---------------------------------------------------------------------------- release
@dataclass(frozen=True)
class Release:
    """A centred release push on rect1 (CoM centred). Forces relative to the force needed to
    accelerate the sliding object, m·(μg + a); the slide is measured from where the object is
    when the pad starts braking, against v²/(2μg) with v the release speed.

    peak_force_ratio: largest physics-rate pad force from the start of braking on
    onset_force_ratio: largest pad force in the first 0.1 s (contact onset)
    min_support_load: least total table reaction / (m·g) during the push (0 = flight)
    flight_s: time with the table reaction below half the weight
    slide_ratio: measured slide / v²/(2μg)
    stop_time_ratio: time from braking to rest (speed < 0.1 mm/s) / (v / μg)
    creep_um: displacement after that rest (µm)
    slide_samples: 10 Hz samples the slide spans (dynamic phases seen by the sensors)
    """

    mass: float
    friction: float
    peak_force_ratio: float
    onset_force_ratio: float
    min_support_load: float | None
    flight_s: float | None
    slide_mm: float
    slide_ratio: float
    stop_time_ratio: float
    creep_um: float
    slide_samples: int


def release_record(mass: float, friction: float, config: SimConfig | None = None) -> PushRecord:
    """The release push of the probe: centred, on rect1 with the CoM at the centroid."""
    return push_through(probe_object("rect1", mass, friction), 0.0, "release", config=config)


def release_push(mass: float, friction: float, config: SimConfig | None = None) -> Release:
    return release_metrics(release_record(mass, friction, config), mass, friction, config)


def release_metrics(
    rec: PushRecord, mass: float, friction: float, config: SimConfig | None = None
) -> Release:
    """`Release` figures of a `release_record` of an object of this mass and friction."""
    cfg = config or SimConfig()
    pc, rate = cfg.push, cfg.tactile.rate_hz
    tr = rec.trace
    t, f = tr["time"], np.linalg.norm(tr["force"], axis=1)
    v = np.linalg.norm(tr["velocity"][:, :2], axis=1)
    x = tr["pose"][:, 0]
    t_brake = pc.release_peak_speed / pc.release_accel
    i_brake = int(np.searchsorted(t, t_brake))
    accel_force = mass * (friction * GRAVITY + pc.release_accel)
    rest = i_brake + int(np.argmax(v[i_brake:] < 1e-4))
    coulomb = pc.release_peak_speed**2 / (2 * friction * GRAVITY)
    slide = float(x[-1] - x[i_brake])
    load = tr.get("support_load")
    load = None if load is None or len(load) == 0 else np.asarray(load)
    dt = np.diff(np.concatenate([[0.0], t]))
    return Release(
        mass,
        friction,
        float(f[i_brake:].max()) / accel_force,
        float(f[t < 0.1].max()) / accel_force,
        None if load is None else float(load.min()),
        None if load is None else float(dt[load < 0.5].sum()),
        1e3 * slide,
        slide / coulomb,
        float(t[rest] - t_brake) / (pc.release_peak_speed / (friction * GRAVITY)),
        1e6 * abs(float(x[-1] - x[rest])),
        int(math.floor(t[rest] * rate) - math.floor(t_brake * rate)) + 1,
    )


# -------------------------------------------------- what the 10 Hz record reveals
@dataclass(frozen=True)
class ReleaseReading:
    """m and μ read in closed form off a release push's 10 Hz record (no trace, no truth):
    μ = v²/(2g·d) from the slide d between the pad's braking and the object's rest pose (the
    object follows the pad until then, so its pose at braking is the pad's braking point plus
    the contact offset seen in earlier samples), and m = F/(μg + a) from the force samples
    wholly inside the acceleration phase."""

    friction: float
    mass: float


def read_release(rec: PushRecord, config: SimConfig | None = None) -> ReleaseReading:
    pc = (config or SimConfig()).push
    rate = 1.0 / float(rec.time[1] - rec.time[0])
    t_brake = pc.release_peak_speed / pc.release_accel
    k_brake = int(math.floor(t_brake * rate))  # last sample before braking
    u = rec.push.unit
    offset = float((rec.pose[k_brake, :2] - rec.pusher[k_brake]) @ u)
    pad_at_brake = float(rec.pusher[0] @ u) + 0.5 * pc.release_accel * t_brake**2
    slide = float(rec.pose[-1, :2] @ u) - (pad_at_brake + offset)
    friction = pc.release_peak_speed**2 / (2 * GRAVITY * slide)
    inside = [k for k in range(2, k_brake + 1) if k / rate <= t_brake]  # skip the onset sample
    force = float(np.mean(np.linalg.norm(rec.tactile[inside, :2], axis=1)))
    return ReleaseReading(friction, force / (friction * GRAVITY + pc.release_accel))
