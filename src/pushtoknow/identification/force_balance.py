"""Mass from Newton's second law on a push's raw force and pose streams (docs/DESIGN.md §11).

A quasi-static push tells μ·m, not m (docs/PHYSICS.md). What separates them is the push's
dynamic content: the object's velocity changes (the start of a push, stick-slip) while the force
sensor reads f = (m + m_probe)·a + friction. Two things stand in the way, and both are measured
here rather than assumed:

- **The probe's own mass.** A force sensor behind the probe also reads the force that
  accelerates the probe: `probe_mass` regresses the force on the probe's acceleration over the
  samples where the probe is clear of the object's outline (it moves, nothing touches it):
  f = m_probe·a_probe + offset.
- **Where force and motion agree.** Friction changes with the motion at low frequencies (a
  step at the start, stick-slip) and the sensor and the motion capture lose each other above
  some tens of Hz. `inertial_mass` estimates the transfer H(f) = S_af / S_aa from the object's
  acceleration along its travel to the force along it (Welch cross-spectra summed over the
  pushes) and reads m + m_probe as Re H over the frequency bins where the two are coherent
  (γ² ≥ `ForceBalanceConfig.min_coherence`). No bin that coherent: m is not identified. The
  acceleration is the pose's second central difference, whose gain at f, (sin ωΔ / ωΔ)², is
  divided out of H.

The reading's std combines, in quadrature, the gain's random error (Bendat & Piersol:
|H|·√(1 − γ²) / (γ·√(2 n_d)) per bin, n_d the averaged segments), the spread of Re H across the
coherent bins (the band's own disagreement: a model error), and the probe mass's std.

Streams are raw rows [t, ...] at the recording's own rates (MIT Push: ~250 Hz, not
synchronised); they are interpolated onto one clock of `ForceBalanceConfig.sample_period`.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
import shapely
from pydantic import Field
from scipy.signal import csd, savgol_filter, welch

from pushtoknow.common.frozen_config import Config

__all__ = [
    "ForceBalanceConfig",
    "MassReading",
    "ProbeMass",
    "RawPush",
    "inertial_mass",
    "probe_clearance",
    "probe_mass",
]


class ForceBalanceConfig(Config):
    """Settings of `probe_mass` and `inertial_mass` (chosen on the MIT Push ABS recordings'
    free probe motion and spectra, docs/DESIGN.md §11)."""

    sample_period: float = Field(0.004, gt=0.0, description="s, the common clock")
    smoothing: float = Field(
        0.044, gt=0.0, description="s, Savitzky–Golay window of the probe's acceleration"
    )
    clearance: float = Field(
        0.003, gt=0.0, description="m, probe-to-outline gap above which the probe is free"
    )
    min_acceleration: float = Field(
        0.3, ge=0.0, description="m/s², free samples accelerating less are left out"
    )
    min_free_samples: int = Field(10, ge=3, description="free samples needed for m_probe")
    segment: int = Field(64, ge=8, description="samples per Welch segment")
    min_coherence: float = Field(0.9, gt=0.0, le=1.0, description="γ² a bin needs")
    min_segments: int = Field(
        16,
        ge=2,
        description="Welch segments needed to judge coherence (γ² of n_d segments "
        "is biased up by about 1/n_d)",
    )
    min_travel: float = Field(
        0.02, gt=0.0, description="m, pushes moving the object less are left out of m"
    )


@dataclass(frozen=True, eq=False)
class RawPush:
    """One push's raw streams. tip: (N, 3) [t s, x m, y m] of the probe's centre; pose: (M, 4)
    [t s, x m, y m, θ rad] of the object frame the outline is given in; force: (L, 3)
    [t s, f_x N, f_y N], world axes, the force the probe's sensor reads as applied *to the
    object* (sign turned accordingly, offset removed); outline: (V, 2) m, object frame;
    probe_radius: m."""

    name: str
    tip: np.ndarray
    pose: np.ndarray
    force: np.ndarray
    outline: np.ndarray
    probe_radius: float

    def __post_init__(self) -> None:
        for field, width in (("tip", 3), ("pose", 4), ("force", 3)):
            a = getattr(self, field)
            if a.ndim != 2 or a.shape[1] != width or len(a) < 2:
                raise ValueError(f"{self.name}: {field} must be (N >= 2, {width}), not {a.shape}")
        if self.outline.ndim != 2 or self.outline.shape[1] != 2 or len(self.outline) < 3:
            raise ValueError(f"{self.name}: outline must be (V >= 3, 2), not {self.outline.shape}")


@dataclass(frozen=True)
class ProbeMass:
    """The mass (kg) the force sensor carries below it, with its std (kg): the spread of the
    per-push slopes over √pushes (one push: that regression's std). None where fewer than
    `min_free_samples` free, accelerating samples exist. samples: those used; pushes: names of
    the pushes with free motion."""

    mass: float | None
    std: float | None
    samples: int
    pushes: tuple[str, ...]

    def to_json(self) -> dict:
        return {
            "mass": self.mass,
            "std": self.std,
            "samples": self.samples,
            "pushes": list(self.pushes),
        }


@dataclass(frozen=True)
class MassReading:
    """m (kg) and its std read off force and acceleration (module doc); None where not
    identified, `reason` says why. band_hz: the coherent bins' frequencies; gain: Re H there
    (kg, = m + m_probe); coherence: γ² there; segments: Welch segments averaged; pushes: the
    pushes used."""

    mass: float | None
    std: float | None
    reason: str
    band_hz: tuple[float, ...]
    gain: tuple[float, ...]
    coherence: tuple[float, ...]
    segments: int
    pushes: tuple[str, ...]

    @property
    def identified(self) -> bool:
        return self.mass is not None

    def to_json(self) -> dict:
        return {
            "mass": self.mass,
            "std": self.std,
            "identified": self.identified,
            "reason": self.reason,
            "band_hz": list(self.band_hz),
            "gain": list(self.gain),
            "coherence": list(self.coherence),
            "segments": self.segments,
            "pushes": list(self.pushes),
        }


# ============================================================================================
# Common clock and geometry
# ============================================================================================
def _common_clock(push: RawPush, dt: float):
    """(t (T,), tip (T, 2), pose (T, 3), force (T, 2)) linearly interpolated on the streams'
    common span at period dt; θ unwrapped first. T may be 0."""
    t0 = max(push.tip[0, 0], push.pose[0, 0], push.force[0, 0])
    t1 = min(push.tip[-1, 0], push.pose[-1, 0], push.force[-1, 0])
    t = t0 + dt * np.arange(max(0, int(math.floor((t1 - t0) / dt)) + 1))

    def interp(rows: np.ndarray, cols: Sequence[int]) -> np.ndarray:
        return np.stack([np.interp(t, rows[:, 0], rows[:, c]) for c in cols], axis=1)

    pose = push.pose.copy()
    pose[:, 3] = np.unwrap(pose[:, 3])
    return t, interp(push.tip, (1, 2)), interp(pose, (1, 2, 3)), interp(push.force, (1, 2))


def probe_clearance(
    tip: np.ndarray, pose: np.ndarray, outline: np.ndarray, radius: float
) -> np.ndarray:
    """(T,) m gap between a round probe of `radius` (m) centred at tip (T, 2) and the outline
    (V, 2, object frame) placed at pose (T, 3); negative where they overlap."""
    d = tip - pose[:, :2]
    c, s = np.cos(pose[:, 2]), np.sin(pose[:, 2])
    local = np.stack([c * d[:, 0] + s * d[:, 1], -s * d[:, 0] + c * d[:, 1]], axis=1)
    polygon = shapely.Polygon(outline)
    points = shapely.points(local)
    gap = shapely.distance(polygon.exterior, points)
    inside = shapely.contains(polygon, points)
    return np.where(inside, -gap, gap) - radius


def _window(config: ForceBalanceConfig) -> int:
    """Savitzky–Golay window in samples (odd, ≥ 5)."""
    n = int(round(config.smoothing / config.sample_period))
    return max(5, n | 1)


# ============================================================================================
# The probe's mass
# ============================================================================================
def probe_mass(pushes: Sequence[RawPush], config: ForceBalanceConfig = ForceBalanceConfig()):
    """The mass below the force sensor, from the pushes' free probe motion (module doc):
    per push with enough free, accelerating samples, the least-squares slope of the force on
    the probe's acceleration (both axes, through the origin); `ProbeMass` of their mean."""
    dt, w = config.sample_period, _window(config)
    slopes, variances, names, used = [], [], [], 0
    for push in pushes:
        t, tip, pose, force = _common_clock(push, dt)
        if len(t) <= w:
            continue
        acc = savgol_filter(tip, w, 2, deriv=2, delta=dt, axis=0)
        f = savgol_filter(force, w, 2, axis=0)
        free = probe_clearance(tip, pose, push.outline, push.probe_radius) > config.clearance
        free &= np.linalg.norm(acc, axis=1) > config.min_acceleration
        n = int(free.sum())
        if n < config.min_free_samples:
            continue
        a, y = acc[free], f[free]
        sxx = float((a * a).sum())
        slope = float((a * y).sum()) / sxx
        resid = y - slope * a
        dof = max(1, 2 * n - 1)
        variances.append(float((resid * resid).sum()) / dof / sxx * w)  # samples within a
        slopes.append(slope)  # window are correlated: about n / w independent ones
        names.append(push.name)
        used += n
    if not slopes:
        return ProbeMass(None, None, 0, ())
    s = np.asarray(slopes)
    std = math.sqrt(variances[0]) if len(s) == 1 else float(s.std(ddof=1) / math.sqrt(len(s)))
    return ProbeMass(float(s.mean()), std, used, tuple(names))


# ============================================================================================
# The object's mass
# ============================================================================================
def _spectra(push: RawPush, config: ForceBalanceConfig):
    """(f (F,), S_af, S_aa, S_ff, segments) of one push along its travel, or None when it
    moves the object less than `min_travel` or is shorter than a segment."""
    dt, nseg = config.sample_period, config.segment
    t, _, pose, force = _common_clock(push, dt)
    travel = pose[-1, :2] - pose[0, :2] if len(t) else np.zeros(2)
    dist = float(np.linalg.norm(travel))
    if len(t) < nseg or dist < config.min_travel:
        return None
    u = travel / dist
    x, f = pose[:, :2] @ u, force @ u
    a = np.gradient(np.gradient(x, dt), dt)
    freq, s_af = csd(a, f, fs=1.0 / dt, nperseg=nseg)
    _, s_aa = welch(a, fs=1.0 / dt, nperseg=nseg)
    _, s_ff = welch(f, fs=1.0 / dt, nperseg=nseg)
    segments = (len(t) - nseg) // (nseg // 2) + 1
    return freq, s_af, s_aa, s_ff, segments


def inertial_mass(
    pushes: Sequence[RawPush],
    probe: ProbeMass,
    config: ForceBalanceConfig = ForceBalanceConfig(),
    band_hz: Sequence[float] | None = None,
) -> MassReading:
    """m read off the pushes' force and acceleration (module doc), the probe's mass taken
    off. Each push's spectra are weighted by its segments. band_hz: read Re H at these bins
    (e.g. one push at its object's band, too short to judge coherence alone); None: at the
    coherent bins, with at least `min_segments` segments."""
    spectra, names = [], []
    for push in pushes:
        s = _spectra(push, config)
        if s is not None:
            spectra.append(s)
            names.append(push.name)

    def none(reason: str, **kw) -> MassReading:
        base = dict(band_hz=(), gain=(), coherence=(), segments=0, pushes=tuple(names))
        return MassReading(None, None, reason, **{**base, **kw})

    if not spectra:
        return none(
            f"no push moves the object ≥ {config.min_travel * 1e3:g} mm over ≥ "
            f"{config.segment} samples"
        )
    freq = spectra[0][0]
    n_d = sum(s[4] for s in spectra)
    s_af = sum(s[4] * s[1] for s in spectra) / n_d
    s_aa = sum(s[4] * s[2] for s in spectra) / n_d
    s_ff = sum(s[4] * s[3] for s in spectra) / n_d
    with np.errstate(divide="ignore", invalid="ignore"):
        # np.gradient twice reads a at frequency f as a·sinc²: (sin ωΔ / ωΔ)², ω = 2πf
        w_dt = 2.0 * np.pi * freq * config.sample_period
        gain = s_af / s_aa * np.where(w_dt > 0, np.sin(w_dt) ** 2 / np.maximum(w_dt, 1e-12) ** 2, 1)
        coh = np.abs(s_af) ** 2 / (s_aa * s_ff)
    band = np.flatnonzero((freq > 0) & np.isfinite(coh) & (coh >= config.min_coherence))
    if probe.mass is None:
        return none("the probe's mass is unknown: no free probe motion", segments=n_d)
    if band_hz is not None:
        band = np.flatnonzero(np.isin(freq, np.asarray(band_hz, dtype=float)))
        if len(band) == 0:
            return none("no band given", segments=n_d)
    elif n_d < config.min_segments:
        return none(
            f"{n_d} spectral segments < {config.min_segments}: too short to judge coherence",
            segments=n_d,
        )
    elif len(band) == 0:
        best = float(np.nanmax(coh[1:])) if len(coh) > 1 else float("nan")
        return none(
            f"force and acceleration nowhere coherent (γ² ≤ {best:.2f} < {config.min_coherence:g})",
            segments=n_d,
        )
    g, c = gain[band], coh[band]
    rel_random = np.sqrt((1.0 - c) / (2.0 * n_d * c))  # per bin, of |H|
    random_var = float(np.mean((np.abs(g) * rel_random) ** 2)) / len(band)
    total = float(g.real.mean())
    std = math.sqrt(random_var + float(g.real.var()) + (probe.std or 0.0) ** 2)
    mass = total - probe.mass
    kw = dict(
        band_hz=tuple(float(v) for v in freq[band]),
        gain=tuple(float(v) for v in g.real),
        coherence=tuple(float(v) for v in c),
        segments=n_d,
    )
    if mass <= 0.0:
        return none(f"m + m_probe = {total:.3g} kg does not exceed m_probe", **kw)
    return MassReading(mass, std, "", pushes=tuple(names), **kw)
