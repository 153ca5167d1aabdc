"""The object's footprint as the camera sees it in S_0 (docs/DESIGN.md §5, §9)."""

from __future__ import annotations

import math

import numpy as np

from pushtoknow.common.camera import CameraModel
from pushtoknow.geometry.affordances import mask_contour

FOOTPRINT_VERTICES = 32  # footprint polygons resampled to this many vertices (batchable)


def footprint_from_mask(s0: np.ndarray, camera: CameraModel, pose0, n: int = FOOTPRINT_VERTICES):
    """Footprint polygon (n, 2) in the object frame (m) estimated from S_0 at pose0 (x, y, θ):
    the mask contour resampled evenly by arc length, translated to its centroid and rotated by
    −θ0."""
    c = mask_contour(s0, camera)
    pts = c.points
    seg = np.linalg.norm(np.diff(np.vstack([pts, pts[:1]]), axis=0), axis=1)
    s = np.concatenate([[0], np.cumsum(seg)])
    q = np.linspace(0, s[-1], n, endpoint=False)
    closed = np.vstack([pts, pts[:1]])
    res = np.stack([np.interp(q, s, closed[:, 0]), np.interp(q, s, closed[:, 1])], 1)
    res = res - c.centroid
    th = -float(pose0[2])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    return res @ R.T
