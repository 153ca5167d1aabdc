"""Push affordances from the initial segmentation S_0 (docs/DESIGN.md §4).

The mask is smoothed and its 0.5 iso-contour traced with sub-pixel accuracy (contourpy, as used
by matplotlib); contour points go to the world through the camera model. Outward normals come
from the contour tangents (counter-clockwise in the world). Candidates: a contact point drawn
uniformly by arc length, pd = inward normal + δ, δ ~ U(−5°, 5°).
"""

from __future__ import annotations

from dataclasses import dataclass

import contourpy
import numpy as np
from scipy.ndimage import gaussian_filter

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import ShapeError

MASK_SMOOTHING_PX = 0.7  # Gaussian σ applied to S_0 before contouring (pixels)
NORMAL_WINDOW = 2  # contour points on each side used for the tangent


@dataclass(frozen=True)
class Contour:
    """Object boundary in the world: points (N, 2) m, outward unit normals (N, 2), arc
    lengths (N,) m of the segment each point stands for."""

    points: np.ndarray
    normals: np.ndarray
    lengths: np.ndarray

    @property
    def centroid(self) -> np.ndarray:
        """Area centroid of the contour polygon (m)."""
        x, y = self.points[:, 0], self.points[:, 1]
        xn, yn = np.roll(x, -1), np.roll(y, -1)
        cross = x * yn - xn * y
        a = cross.sum() / 2
        return np.array([((x + xn) * cross).sum(), ((y + yn) * cross).sum()]) / (6 * a)


def largest_level_line(
    z: np.ndarray, x: np.ndarray | None = None, y: np.ndarray | None = None
) -> np.ndarray:
    """The longest line (N, 2) where the image z (H, W) crosses 0.5, as (x, y) on the grid of
    x (W,) and y (H,) (None: column and row indices), its closing repeat of the first point
    dropped."""
    line = max(contourpy.contour_generator(x=x, y=y, z=z).lines(0.5), key=len)
    return line[:-1] if np.allclose(line[0], line[-1]) else line


def mask_contour(
    s0: np.ndarray, camera: CameraModel, z: float = 0.0, smoothing: float | None = None
) -> Contour:
    """Largest outer contour of a (H, W) mask, or of a (kH, kW) one taken by the same camera at
    k × its resolution, in world coordinates on the plane at height z. The mask is smoothed
    first by a Gaussian of σ = smoothing (m on that plane), or MASK_SMOOTHING_PX of its own
    pixels (None)."""
    s0 = np.asarray(s0)
    try:
        camera = camera.resolution_of(s0)
    except ValueError:
        raise ShapeError(
            f"expected a mask of shape {(camera.height, camera.width)} or an integer multiple, "
            f"got {s0.shape}"
        ) from None
    if not s0.any():
        raise ValueError("the segmentation S_0 is empty: the object is not in view")
    sigma_px = MASK_SMOOTHING_PX if smoothing is None else smoothing / camera.metres_per_pixel(z)
    img = np.pad(gaussian_filter(s0.astype(np.float64), sigma_px), 1)
    uv = largest_level_line(img) - 1.0  # (x=column, y=row) = (u, v); undo the padding
    pts = camera.pixel_to_world(uv, z)
    x, y = pts[:, 0], pts[:, 1]
    if 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:
        pts = pts[::-1]
    tangent = np.roll(pts, -NORMAL_WINDOW, 0) - np.roll(pts, NORMAL_WINDOW, 0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    normals = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)  # CCW polygon → outward
    seg = np.linalg.norm(np.roll(pts, -1, 0) - pts, axis=1)
    lengths = 0.5 * (seg + np.roll(seg, 1))
    return Contour(pts, normals, lengths)


def sample_push_affordances(
    s0: np.ndarray,
    camera: CameraModel,
    n: int,
    rng: np.random.Generator,
    max_deviation_deg: float = 5.0,
    z: float = 0.0,
) -> tuple[np.ndarray, np.ndarray]:
    """M = n candidate pushes from S_0.

    Returns contact points (n, 2) in the world (m) and push directions (n,) (rad): the inward
    normal at the contact point plus δ ~ U(−max_deviation, max_deviation).
    """
    c = mask_contour(s0, camera, z)
    idx = rng.choice(len(c.points), size=n, p=c.lengths / c.lengths.sum())
    inward = -c.normals[idx]
    delta = np.radians(rng.uniform(-max_deviation_deg, max_deviation_deg, size=n))
    directions = np.arctan2(inward[:, 1], inward[:, 0]) + delta
    return c.points[idx].copy(), directions
