"""Random-forest baseline (Mavrakis et al., as used by the paper; docs/DESIGN.md §9).

Hand-crafted features of each push, all in the object's initial frame (so they do not depend on
where the object lies): the contact point and push direction relative to the object; the
object's displacement and rotation over the push (from the ground-truth pose, or from any other
pose source such as VisNet); the contact-force statistics (mean, std, max of ‖F‖, mean force
along and across the push, share of samples in contact); the speed and profile; and simple shape
descriptors of S_0's footprint. A multi-output random forest (scikit-learn) regresses φ from one
push; an object's estimate after K pushes is the mean of its first K per-push predictions, and
the spread of the trees gives a (rough) standard deviation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from sklearn.ensemble import RandomForestRegressor

from pushtoknow.common.angles import wrap_angle

FEATURE_NAMES = (
    "contact_x",
    "contact_y",
    "push_cos",
    "push_sin",
    "speed",
    "release",
    "disp_along",
    "disp_across",
    "rotation",
    "path_length",
    "force_mean",
    "force_std",
    "force_max",
    "force_along",
    "force_across",
    "contact_share",
    "force_early",
    "force_late",
    "slide_after_contact",
    "shape_area",
    "shape_major",
    "shape_minor",
)


def _rot(th: float) -> np.ndarray:
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def push_features(
    pose: np.ndarray,
    tactile: np.ndarray,
    action: np.ndarray,
    footprint_px_area: float,
    footprint_axes: tuple[float, float],
) -> np.ndarray:
    """Features of one push.

    pose: (T, 3) object poses (x, y, θ) — ground truth or estimated; tactile: (T, 3) (F_x, F_y,
    contact); action: (5,) [cp_x, cp_y, pd, v, profile index]; footprint_px_area: S_0 area (m²);
    footprint_axes: principal semi-axes of S_0 (m). Returns (len(FEATURE_NAMES),).
    """
    x0, y0, th0 = pose[0]
    R0 = _rot(-th0)
    cp = R0 @ (action[:2] - np.array([x0, y0]))
    pd_obj = float(wrap_angle(action[2] - th0))
    u = np.array([math.cos(action[2]), math.sin(action[2])])
    n = np.array([-u[1], u[0]])
    d = pose[-1, :2] - pose[0, :2]
    rotation = float(pose[-1, 2] - pose[0, 2])
    path = float(np.sum(np.linalg.norm(np.diff(pose[:, :2], axis=0), axis=1)))
    F = tactile[:, :2]
    fmag = np.linalg.norm(F, axis=1)
    c = tactile[:, 2] > 0.5
    fc = fmag[c] if c.any() else np.zeros(1)
    idx = np.nonzero(c)[0]
    if len(idx) >= 2:
        half = len(idx) // 2
        early, late = fmag[idx[:half]].mean(), fmag[idx[half:]].mean()
        # Displacement after the last contact sample: free sliding (release pushes).
        after = pose[-1, :2] - pose[idx[-1], :2]
        slide = float(np.linalg.norm(after))
    else:
        early = late = slide = 0.0
    return np.array(
        [
            cp[0],
            cp[1],
            math.cos(pd_obj),
            math.sin(pd_obj),
            action[3],
            float(action[4] == 1),
            d @ u,
            d @ n,
            rotation,
            path,
            fc.mean(),
            fc.std(),
            fmag.max(),
            (F[c] @ u).mean() if c.any() else 0.0,
            (F[c] @ n).mean() if c.any() else 0.0,
            c.mean(),
            early,
            late,
            slide,
            footprint_px_area,
            footprint_axes[0],
            footprint_axes[1],
        ]
    )


def mask_shape_descriptors(s0: np.ndarray, metres_per_pixel: float) -> tuple[float, tuple]:
    """Area (m²) and principal semi-axes (m) of a mask (second moments of the pixels)."""
    v, u = np.nonzero(s0)
    area = len(u) * metres_per_pixel**2
    if len(u) < 3:
        return area, (0.0, 0.0)
    cov = np.cov(np.stack([u, v])) * metres_per_pixel**2
    ev = np.sort(np.linalg.eigvalsh(cov))[::-1]
    return area, (float(2 * np.sqrt(ev[0])), float(2 * np.sqrt(ev[1])))


@dataclass
class ForestConfig:
    n_estimators: int = 200
    min_samples_leaf: int = 2
    max_features: float = 0.5
    seed: int = 0
    n_jobs: int = 1


class ForestBaseline:
    """Multi-output random forest on push features; targets are normalised per parameter."""

    def __init__(self, config: ForestConfig | None = None):
        self.config = config or ForestConfig()

    def fit(self, features: np.ndarray, params: np.ndarray) -> ForestBaseline:
        c = self.config
        self.mu_, self.sd_ = params.mean(0), params.std(0) + 1e-12
        self.model_ = RandomForestRegressor(
            n_estimators=c.n_estimators,
            min_samples_leaf=c.min_samples_leaf,
            max_features=c.max_features,
            random_state=c.seed,
            n_jobs=c.n_jobs,
        ).fit(features, (params - self.mu_) / self.sd_)
        return self

    def predict_pushes(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-push mean (N, 5) and tree spread std (N, 5), SI."""
        per_tree = np.stack([t.predict(features) for t in self.model_.estimators_])
        mean = per_tree.mean(0) * self.sd_ + self.mu_
        std = per_tree.std(0) * self.sd_
        return mean, std

    def predict_object(self, features: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Aggregate an object's K pushes (K, F) → estimate after k = 1..K pushes: (K, 5) mean
        of the first k per-push predictions, and their std combined with the tree spread."""
        m, s = self.predict_pushes(features)
        k = np.arange(1, len(m) + 1)[:, None]
        mean = np.cumsum(m, 0) / k
        # Averaging k correlated predictions: keep the mean per-push tree spread (no 1/√k).
        std = np.sqrt(np.cumsum(s**2, 0) / k)
        return mean, std


def features_from_records(records, camera, pose_fn=None) -> np.ndarray:
    """(K, F) features of an object's pushes. pose_fn(record) → (T, 3) poses; default: truth."""
    rows = []
    mpp = camera.metres_per_pixel()
    for r in records:
        pose = r.pose if pose_fn is None else pose_fn(r)
        area, axes = mask_shape_descriptors(r.s0, mpp)
        rows.append(push_features(pose, r.tactile, r.push.as_array(), area, axes))
    return np.asarray(rows)


def features_from_dataset(root, pose_fn=None):
    """All pushes of a dataset: features (N, F), params (N, 5) SI, object index (N,),
    push number within its object (N,)."""
    import json

    from pushtoknow.common.errors import DatasetError
    from pushtoknow.datasets.shards import list_shards, open_shard, read_shard
    from pushtoknow.testbed.sim_config import SimConfig

    shards = list_shards(root)
    if not shards:
        raise DatasetError(root, "no shard-*.h5 files: the forest has no training pushes")
    X, Y, obj, k = [], [], [], []
    for s in shards:
        with open_shard(s) as f:
            cam = SimConfig.model_validate(json.loads(f.attrs["sim_config"])).camera.model()
        for ep in read_shard(s):
            X.append(features_from_records(ep.records, cam, pose_fn))
            Y.append(np.tile(ep.spec.params.as_array(), (len(ep.records), 1)))
            obj += [ep.object_index] * len(ep.records)
            k += list(range(len(ep.records)))
    return np.concatenate(X), np.concatenate(Y), np.array(obj), np.array(k)
