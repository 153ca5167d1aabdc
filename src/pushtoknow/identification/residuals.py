"""Residuals of replayed pushes against recorded ones, in noise units (docs/DESIGN.md §12):
what `fit.identify` and the physics filter (`recursive.iterated_update`) minimise."""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence

import numpy as np

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.params import denormalise_params
from pushtoknow.identification.prior import fit_transform
from pushtoknow.identification.replay import PushTrack, ReplayScene, RolloutPool, feasible

PENALTY_SCALE = 1e-3  # m of CoM projection (or 0.1 % of I_z excess) per unit penalty residual
BREAKAWAY_MOTION = 5e-4  # m or rad a real push's object moves by to count as not at rest
OFFSET_UNIT = 1e-3  # m per unit of a push's contact offset coordinate


def rest_weights(pose: np.ndarray, position_tol: float, angle_tol: float) -> np.ndarray:
    """(T,) weights of a pose track's (T, 3) samples that keep one sample of its final stretch
    at rest (every sample within `position_tol` (m) and `angle_tol` (rad) of the last): 0 on
    the stretch's samples after its first, 1 elsewhere. A resting object is seen in the same
    image over and over, so its perceived pose carries one error, not one per frame."""
    pose = np.asarray(pose, dtype=np.float64)
    near = (np.linalg.norm(pose[:, :2] - pose[-1, :2], axis=1) <= position_tol) & (
        np.abs(wrap_angle(pose[:, 2] - pose[-1, 2])) <= angle_tol
    )
    moving = np.flatnonzero(~near)
    first_rest = int(moving[-1]) + 1 if len(moving) else 0
    w = np.ones(len(pose))
    w[first_rest + 1 :] = 0.0
    return w


def resting_force_weights(track: PushTrack) -> np.ndarray:
    """(T, 2) weights of a track's force samples: 0 where a track replayed along a recorded
    pad (a real pusher) holds the object at rest, 1 elsewhere. At rest are the samples up to
    and including the one in which the object starts to move (its pose first leaves the start
    by more than `BREAKAWAY_MOTION` m or rad; all of them if it never does) and those after
    the one in which it comes to its final rest (`rest_weights` within `BREAKAWAY_MOTION`).
    A resting object's force is static friction's, anything up to μ_s·m·g: a probe left
    pressed on it before or after the push (up to 4.4 N on the MIT recordings), and the
    breakaway above the sliding force with the probe's own inertia (docs/DESIGN.md §11). The
    replay's Coulomb friction (one μ) and massless pad have neither. Replayed by its profile
    (a simulated push), every sample counts."""
    w = np.ones((len(track.force), 2))
    if track.pad is None:
        return w
    pose = np.asarray(track.pose, dtype=np.float64)
    moved = np.flatnonzero(
        (np.linalg.norm(pose[:, :2] - pose[0, :2], axis=1) > BREAKAWAY_MOTION)
        | (np.abs(wrap_angle(pose[:, 2] - pose[0, 2])) > BREAKAWAY_MOTION)
    )
    if not len(moved):
        return np.zeros_like(w)
    w[: moved[0] + 1] = 0.0
    return w * rest_weights(pose, BREAKAWAY_MOTION, BREAKAWAY_MOTION)[:, None]


def whiten_ar1(e: np.ndarray, rho: float, lengths: Sequence[int]) -> np.ndarray:
    """Residuals e (..., N, C) of AR(1) errors (lag-1 correlation `rho` within each track of
    `lengths` samples, unit marginal variance) as independent unit-variance ones: the first
    sample of a track kept, each later one (e_t − ρ e_{t−1}) / √(1 − ρ²). ρ = 0: unchanged."""
    if rho == 0.0:
        return e
    out = e.copy()
    start = 0
    for n in lengths:
        seg = e[..., start : start + n, :]
        out[..., start + 1 : start + n, :] = (seg[..., 1:, :] - rho * seg[..., :-1, :]) / (
            math.sqrt(1.0 - rho * rho)
        )
        start += n
    return out


class ReplayResiduals:
    """Residuals of candidate fit coordinates u (B, 5) on `tracks`, in noise units `sigmas`
    (5,): force x, y (N), x, y (m), θ (rad); the last two entries are the feasibility penalties
    (`replay.feasible`). The force's noise is white; the pose track's may be AR(1) with lag-1
    correlation `pose_correlation` (perception's error drifts from frame to frame), its
    residuals whitened (`whiten_ar1`). `rest_tolerance` (m, rad): keep one pose sample of each
    observed track's final stretch at rest (`rest_weights`); None: every sample counts. A real
    pusher's force samples with the object at rest carry no residual (`resting_force_weights`).
    `end_noise` (m, rad): the noise of each track's `end_pose` where it has one, whose misfit
    against the replay's last pose follows the tracks' samples as 3 more data residuals per
    such track (x, y, θ; None: end poses unused)."""

    def __init__(
        self,
        scene: ReplayScene,
        tracks: list[PushTrack],
        pool: RolloutPool,
        sigmas: np.ndarray,
        rest_tolerance: tuple[float, float] | None = None,
        pose_correlation: float = 0.0,
        end_noise: tuple[float, float] | None = None,
    ):
        self.scene, self.tracks, self.pool = scene, tracks, pool
        self.sigmas = np.array(sigmas, dtype=np.float64)  # a copy: a coarse stage scales it
        self.footprint = scene.footprint
        self.t_inv = np.linalg.inv(fit_transform())
        self.obs = np.concatenate([np.column_stack([t.force, t.pose])[1:] for t in tracks])
        self.push_lengths = [len(t.pose) - 1 for t in tracks]
        self.n_samples = self.obs.size  # the tracks' samples' residuals, (N, 5) flattened
        self.ended = [
            i for i, t in enumerate(tracks) if end_noise is not None and t.end_pose is not None
        ]
        self.end_obs = np.array([tracks[i].end_pose for i in self.ended]).reshape(-1, 3)
        self.end_rows = np.cumsum(self.push_lengths)[self.ended] - 1  # each one's last sample
        position, angle = end_noise or (1.0, 1.0)
        self.end_sigmas = np.array([position, position, angle])
        self.n_data = self.n_samples + self.end_obs.size
        self.pose_correlation = float(pose_correlation)
        self.weights = np.ones(self.obs.shape)  # (N, 5) per-sample weights of the residuals
        self.weights[:, :2] = np.concatenate([resting_force_weights(t)[1:] for t in tracks])
        if rest_tolerance is not None:
            self.weights[:, 2:] = np.concatenate(
                [rest_weights(t.pose, *rest_tolerance)[1:] for t in tracks]
            )[:, None]
        robust = np.zeros(self.obs.shape, dtype=bool)
        robust[:, :2] = True
        self.robust = np.concatenate([robust.reshape(-1), np.zeros(self.end_obs.size, bool)])

    def standardise(self, data: np.ndarray, weights: np.ndarray | None = None) -> np.ndarray:
        """Replayed-minus-observed samples in noise units (..., N, 5) as independent
        unit-variance residuals: the pose channels whitened, then weighted (default: the
        observed tracks' `weights`)."""
        out = data.copy()
        out[..., 2:] = whiten_ar1(data[..., 2:], self.pose_correlation, self.push_lengths)
        return out * (self.weights if weights is None else weights)

    def phi(self, u: np.ndarray) -> np.ndarray:
        """(B, 5) SI parameters of fit coordinates u (B, ≥ 5)."""
        return denormalise_params(np.atleast_2d(u)[:, :5] @ self.t_inv.T)

    def shifted(self, offsets: np.ndarray) -> list[PushTrack]:
        """The tracks with the pad moved `offsets` (K,) (m) along each push's direction: where
        the outline's true edge lies along the push line, relative to the one seen."""
        out = []
        for tr, s in zip(self.tracks, offsets, strict=True):
            d = float(s) * tr.push.unit
            start = None if tr.start is None else np.asarray(tr.start) + d
            pad = None if tr.pad is None else np.asarray(tr.pad) + d[None]
            fine = None
            if tr.pad_fine is not None:
                fine = np.array(tr.pad_fine, dtype=np.float64)
                fine[:, 1:] += d[None]
            out.append(dataclasses.replace(tr, start=start, pad=pad, pad_fine=fine))
        return out

    def simulate(self, us: np.ndarray) -> list[np.ndarray]:
        """Replays of u (B, 5), or (B, 5 + K) with each push's contact offset (mm,
        `shifted`): B arrays (N, 5) of the tracks' samples after the first; the feasibility
        penalties (B, 2) are kept for `residuals`."""
        us = np.atleast_2d(us)
        phis = self.phi(us)
        feas = [feasible(p, self.footprint) for p in phis]
        k = len(self.tracks)
        if us.shape[1] > 5:
            tracks = [self.shifted(o) for o in us[:, 5 : 5 + k] * OFFSET_UNIT]
        else:
            tracks = [self.tracks] * len(us)
        sims = self.pool.run_each(self.scene, np.stack([f[0] for f in feas]), tracks)
        self._pen = np.array([[m / PENALTY_SCALE, e / PENALTY_SCALE] for _, m, e in feas])
        return [np.concatenate([s[1:] for s in pushes]) for pushes in sims]

    def residuals(self, us: np.ndarray) -> np.ndarray:
        """(B, n_data + 2) residuals in noise units, the last two the feasibility penalties."""
        us = np.atleast_2d(us)
        sim = np.stack(self.simulate(us))
        data = self.standardise((sim - self.obs[None]) / self.sigmas)
        end = sim[:, self.end_rows, 2:] - self.end_obs[None]
        end[..., 2] = wrap_angle(end[..., 2])
        end = end / self.end_sigmas
        return np.concatenate(
            [data.reshape(len(us), -1), end.reshape(len(us), -1), self._pen], axis=1
        )


def huber_weights(r: np.ndarray, k: float, robust: np.ndarray) -> np.ndarray:
    a = np.abs(r)
    return np.where(robust & (a > k), k / np.maximum(a, 1e-300), 1.0)


def huber_cost(r: np.ndarray, k: float, robust: np.ndarray) -> float:
    a = np.abs(r)
    return float(np.sum(np.where(robust & (a > k), k * a - 0.5 * k * k, 0.5 * r * r)))
