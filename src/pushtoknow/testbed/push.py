"""Push actions a = (cp, pd, v) and speed profiles of the pad."""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Literal

import numpy as np

from pushtoknow.testbed.sim_config import PadConfig, PushConfig

PAD_CLEARANCE = 1e-6  # m, clearance at the start: a release push starts touching, no impact

ProfileName = Literal["constant", "release"]
PROFILES: tuple[str, ...] = ("constant", "release")


@dataclass(frozen=True)
class SpeedProfile:
    """Piecewise-linear pad speed along the push direction: knots (t_i, v_i), constant after.

    Position is the exact integral (trapezoids), so the pad is driven smoothly, never teleported.
    """

    times: tuple[float, ...]
    speeds: tuple[float, ...]

    def speed(self, t: float) -> float:
        return float(np.interp(t, self.times, self.speeds))

    def distance(self, t):
        """Distance travelled by time t (m); t a float or an array of times."""
        ts, vs = np.asarray(self.times), np.asarray(self.speeds)
        knots = np.concatenate([[0.0], np.cumsum(0.5 * (vs[1:] + vs[:-1]) * np.diff(ts))])
        t = np.asarray(t, dtype=np.float64)
        k = np.clip(np.searchsorted(ts, t, side="right") - 1, 0, len(ts) - 1)
        d = knots[k] + 0.5 * (vs[k] + np.interp(t, ts, vs)) * (t - ts[k])
        d = np.where(t <= ts[0], 0.0, d)
        return float(d) if d.ndim == 0 else d


def constant_profile(speed: float, horizon: float) -> SpeedProfile:
    return SpeedProfile((0.0, horizon), (speed, speed))


def release_profile(peak: float, accel: float, decel: float, horizon: float) -> SpeedProfile:
    """Accelerate from rest to `peak`, then stop the pad at `decel` (> μ·g) so the object
    leaves the pad and slides freely: its deceleration μ·g separates μ from m (docs/DESIGN.md
    §10)."""
    t1 = peak / accel
    t2 = t1 + peak / decel
    if t2 >= horizon:
        raise ValueError(f"release profile needs {t2:.2f} s, longer than the horizon {horizon} s")
    return SpeedProfile((0.0, t1, t2, horizon), (0.0, peak, 0.0, 0.0))


@dataclass(frozen=True)
class Push:
    """A push: contact point cp (world, m), direction pd (world angle, rad), speed profile.

    `speed` is the profile's characteristic speed v (m/s): the constant speed, or the release
    profile's peak.
    """

    contact: tuple[float, float]
    direction: float
    profile: str = "constant"
    speed: float = 0.02

    @property
    def unit(self) -> np.ndarray:
        return np.array([math.cos(self.direction), math.sin(self.direction)])

    def as_array(self) -> np.ndarray:
        """(5,) float64: cp_x, cp_y, pd, v, profile index."""
        return np.array([*self.contact, self.direction, self.speed, PROFILES.index(self.profile)])

    @classmethod
    def from_array(cls, a) -> Push:
        a = np.asarray(a, dtype=np.float64)
        return cls((float(a[0]), float(a[1])), float(a[2]), PROFILES[int(a[4])], float(a[3]))


def speed_profile(push: Push, cfg: PushConfig) -> SpeedProfile:
    """The pad's speed profile of `push` under the testbed's push settings."""
    if push.profile == "constant":
        return constant_profile(push.speed, cfg.horizon)
    if push.profile == "release":
        return release_profile(push.speed, cfg.release_accel, cfg.release_decel, cfg.horizon)
    raise ValueError(f"unknown speed profile {push.profile!r}; use 'constant' or 'release'")


def release_point(push: Push, cfg: PushConfig) -> tuple[float, float, float]:
    """(t_r (s), v_r (m/s), D (m/s²)): when the pad starts to stop, its speed then and its
    deceleration; a pushed object with μ·g < D leaves the pad at t_r with speed v_r and slides
    freely (docs/DESIGN.md §10). A push that never stops gives (inf, 0, 0)."""
    profile = speed_profile(push, cfg)
    ts, vs = profile.times, profile.speeds
    for i in range(len(ts) - 1):
        if vs[i + 1] < vs[i]:
            return ts[i], vs[i], (vs[i] - vs[i + 1]) / (ts[i + 1] - ts[i])
    return math.inf, 0.0, 0.0


def release_points(pushes: Sequence[Push], cfg: PushConfig) -> np.ndarray:
    """(B, 3) `release_point` of each push (the learned models' `PushContext.release`)."""
    return np.array([release_point(p, cfg) for p in pushes], dtype=np.float64).reshape(-1, 3)


def pad_positions(
    push: Push,
    times: np.ndarray,
    cfg: PushConfig,
    start: np.ndarray | None = None,
    pad_radius: float | None = None,
) -> np.ndarray:
    """Commanded pad centre (T, 2) (m, world) at `times` (T,) (s since the push began).

    Exactly how `PushSimulator.execute` drives the pad: p(t) = start + d(t) · pd, d the distance
    travelled under the push's speed profile (constant at `push.speed` over `cfg.horizon`, or
    the release profile with `cfg.release_accel` / `cfg.release_decel`). A record's
    `pusher[k]` is p(k / rate) up to one physics step of integration error.

    start (2,): the pad's start. The simulator finds it on the true geometry
    (`PushSimulator.pad_start`: the first point on the push line at the wanted gap from the
    object); pass that (or a record's `pusher[0]`) to reproduce a push exactly. None gives the
    nominal start cp − pd · (pad_radius + gap), gap = max(cfg.approach_gap, clearance) for a
    constant push and the simulator's clearance for a release push: exact when cp lies on the
    object's boundary and pd is the inward normal there (or the line misses the object).
    pad_radius: m, default `PadConfig().radius`.
    """
    profile = speed_profile(push, cfg)
    u = push.unit
    if start is None:
        radius = PadConfig().radius if pad_radius is None else pad_radius
        gap = cfg.approach_gap if push.profile == "constant" else PAD_CLEARANCE
        start = np.asarray(push.contact, dtype=np.float64) - u * (radius + max(gap, PAD_CLEARANCE))
    start = np.asarray(start, dtype=np.float64).reshape(2)
    t = np.asarray(times, dtype=np.float64).reshape(-1)
    return start[None] + np.outer(np.atleast_1d(profile.distance(t)), u)
