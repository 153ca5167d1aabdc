"""Residuals of replayed pushes against recorded ones, in noise units (docs/DESIGN.md §12):
what `fit.identify` and the physics filter (`recursive.iterated_update`) minimise."""

from __future__ import annotations

import dataclasses

import numpy as np

from pushtoknow.common.params import denormalise_params
from pushtoknow.identification.prior import fit_transform
from pushtoknow.identification.replay import PushTrack, ReplayScene, RolloutPool, feasible

PENALTY_SCALE = 1e-3  # m of CoM projection (or 0.1 % of I_z excess) per unit penalty residual
OFFSET_UNIT = 1e-3  # m per unit of a push's contact offset coordinate


class ReplayResiduals:
    """Residuals of candidate fit coordinates u (B, 5) on `tracks`, in noise units `sigmas`
    (5,): force x, y (N), x, y (m), θ (rad); the last two entries are the feasibility penalties
    (`replay.feasible`)."""

    def __init__(
        self, scene: ReplayScene, tracks: list[PushTrack], pool: RolloutPool, sigmas: np.ndarray
    ):
        self.scene, self.tracks, self.pool = scene, tracks, pool
        self.sigmas = np.array(sigmas, dtype=np.float64)  # a copy: a coarse stage scales it
        self.footprint = scene.footprint
        self.t_inv = np.linalg.inv(fit_transform())
        self.obs = np.concatenate([np.column_stack([t.force, t.pose])[1:] for t in tracks])
        self.push_lengths = [len(t.pose) - 1 for t in tracks]
        self.n_data = self.obs.size
        robust = np.zeros(self.obs.shape, dtype=bool)
        robust[:, :2] = True
        self.robust = robust.reshape(-1)

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
            out.append(dataclasses.replace(tr, start=start, pad=pad))
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
        data = (sim - self.obs[None]) / self.sigmas
        return np.concatenate([data.reshape(len(us), -1), self._pen], axis=1)


def huber_weights(r: np.ndarray, k: float, robust: np.ndarray) -> np.ndarray:
    a = np.abs(r)
    return np.where(robust & (a > k), k / np.maximum(a, 1e-300), 1.0)


def huber_cost(r: np.ndarray, k: float, robust: np.ndarray) -> float:
    a = np.abs(r)
    return float(np.sum(np.where(robust & (a > k), k * a - 0.5 * k * k, 0.5 * r * r)))
