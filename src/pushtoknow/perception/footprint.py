"""The object's footprint as the camera sees it before a push (docs/DESIGN.md §5, §9)."""

from __future__ import annotations

import math

import numpy as np

from pushtoknow.common.camera import CameraModel
from pushtoknow.geometry.affordances import mask_contour

FOOTPRINT_VERTICES = 32  # vertices of every footprint polygon (batchable)
# Gaussian σ (m on the traced plane) the mask is smoothed by before its outline is traced. A
# frictionless pad pushes along the outline's normal, so the pixel staircase left on a face
# tilts the push: with the true CoM, on the 256 px mask smoothed by 0.7 px the limit-surface
# step alone left 0.17 of the per-step motion, turn R² 0.86; smoothed by 2 px (5 mm), 0.105
# and 0.94, as on the true outline (0.103, 0.96; κ 0.8, tests/models/test_contact_testbed.py).
# Corners round off by about σ.
OUTLINE_SMOOTHING = 0.005


def object_top(depth: np.ndarray, s0: np.ndarray, camera: CameraModel) -> float:
    """Height (m) of the object's top face above the table: the camera's height less the
    median depth (H, W) over the object's mask S_0 (H, W). Seen from above, the outline is
    nearly the top face's, so it is traced on that plane (on the table's, perspective makes it
    larger by camera height / (camera height − top): 1.8 % for a 13 mm object at 0.75 m). Off
    the optical axis the side wall facing the axis shows too, by about r·h/d: under 0.5 mm
    within the ±3 cm where objects are placed."""
    d = np.asarray(depth, dtype=np.float64)[np.asarray(s0, dtype=bool)]
    if d.size == 0:
        raise ValueError("the segmentation S_0 is empty: the object is not in view")
    return float(camera.position[2] - np.median(d))


def decimate(points: np.ndarray, n: int) -> np.ndarray:
    """The closed polygon points (N, 2) reduced to n ≤ N vertices, in order, by
    Visvalingam–Whyatt: the vertex whose triangle with its neighbours has the least area goes
    first, so straight runs thin out and corners stay."""
    pts = np.asarray(points, dtype=np.float64)
    m = len(pts)
    if n < 3 or n > m:
        raise ValueError(f"cannot decimate {m} points to {n} vertices")
    nxt, prv = np.roll(np.arange(m), -1), np.roll(np.arange(m), 1)

    def area(i):
        a, b, c = pts[prv[i]], pts[i], pts[nxt[i]]
        return 0.5 * np.abs(
            (b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
            - (c[..., 0] - a[..., 0]) * (b[..., 1] - a[..., 1])
        )

    areas = area(np.arange(m))
    keep = np.ones(m, bool)
    for _ in range(m - n):
        i = int(np.argmin(areas))
        keep[i], areas[i] = False, np.inf
        p, q = prv[i], nxt[i]
        nxt[p], prv[q] = q, p
        areas[p], areas[q] = area(p), area(q)
    return pts[keep]


def resample(points: np.ndarray, n: int) -> np.ndarray:
    """The closed polygon points (N, 2) resampled to n points evenly by arc length."""
    pts = np.asarray(points, dtype=np.float64)
    closed = np.vstack([pts, pts[:1]])
    s = np.concatenate([[0], np.cumsum(np.linalg.norm(np.diff(closed, axis=0), axis=1))])
    q = np.linspace(0, s[-1], n, endpoint=False)
    return np.stack([np.interp(q, s, closed[:, 0]), np.interp(q, s, closed[:, 1])], 1)


def footprint_from_mask(
    mask: np.ndarray, camera: CameraModel, pose0, *, z: float = 0.0, n: int = FOOTPRINT_VERTICES
) -> np.ndarray:
    """Footprint polygon (n, 2) in the object frame (m) estimated from an object mask at pose0
    (x, y, θ), traced on the plane at height z (the object's top, `object_top`), translated to
    its centroid and rotated by −θ0.

    A mask at k > 1 × the camera's resolution (kH, kW) is smoothed by `OUTLINE_SMOOTHING` and
    its contour decimated to n vertices (`decimate`: corners kept). S_0 itself (H, W) keeps its
    contour's usual smoothing, resampled evenly by arc length: at 9 mm pixels 5 mm of
    smoothing leaves the staircase, and decimating would keep its steps."""
    if camera.resolution_of(mask) is camera:
        c = mask_contour(mask, camera, z)
        pts = resample(c.points, n)
    else:
        c = mask_contour(mask, camera, z, smoothing=OUTLINE_SMOOTHING)
        pts = decimate(c.points if len(c.points) >= n else resample(c.points, n), n)
    res = pts - c.centroid
    th = -float(pose0[2])
    R = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    return res @ R.T


def footprint_seen(
    s0: np.ndarray,
    depth: np.ndarray,
    outline_mask: np.ndarray | None,
    camera: CameraModel,
    pose0,
) -> np.ndarray:
    """The footprint (FOOTPRINT_VERTICES, 2) seen before a push: traced on the outline-resolution
    mask where there is one (else on S_0 (H, W)), on the plane of the object's top found in the
    depth (H, W) m."""
    mask = s0 if outline_mask is None else outline_mask
    return footprint_from_mask(mask, camera, pose0, z=object_top(depth, s0, camera))
