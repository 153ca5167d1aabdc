"""Push actions a = (cp, pd, v) and speed profiles of the pad."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Literal

import numpy as np

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

    @property
    def peak_speed(self) -> float:
        return float(max(self.speeds))


def constant_profile(speed: float, horizon: float) -> SpeedProfile:
    return SpeedProfile((0.0, horizon), (speed, speed))


def release_profile(peak: float, accel: float, decel: float, horizon: float) -> SpeedProfile:
    """Accelerate from rest to `peak`, then stop the pad at `decel` (> μ·g) so the object
    leaves the pad and slides freely: its deceleration μ·g separates μ from m (SPEC §3.8)."""
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
