"""Pinhole model of the overhead camera looking straight down at the table (pure numpy/torch).

World frame: table plane z = 0, camera at (cx, cy, height) looking along -z. Image axes:
column u grows with world +x, row v grows with world -y (so the image shows the table as seen
from above with +y up). Pixel (u, v) has its centre at integer coordinates; pixel u covers
[u - 0.5, u + 0.5).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np


@dataclass(frozen=True)
class CameraModel:
    """Overhead pinhole camera.

    width, height: image size (pixels). fovy_deg: vertical field of view (degrees).
    position: camera centre (x, y, z) in metres, z above the table.
    """

    width: int = 64
    height: int = 64
    fovy_deg: float = 45.0
    position: tuple[float, float, float] = (0.0, 0.0, 0.7)
    near: float = 0.05
    far: float = 2.0

    @property
    def focal_px(self) -> float:
        """Focal length in pixels (square pixels)."""
        return 0.5 * self.height / math.tan(math.radians(self.fovy_deg) / 2)

    @property
    def principal_point(self) -> tuple[float, float]:
        return ((self.width - 1) / 2.0, (self.height - 1) / 2.0)

    def metres_per_pixel(self, z: float = 0.0) -> float:
        """Size of one pixel on the plane at height z (metres)."""
        return (self.position[2] - z) / self.focal_px

    def world_to_pixel(self, xy: np.ndarray, z: float = 0.0) -> np.ndarray:
        """(..., 2) world x, y on the plane at height z → (..., 2) pixel (u, v), float."""
        xy = np.asarray(xy, dtype=np.float64)
        f = self.focal_px / (self.position[2] - z)
        cu, cv = self.principal_point
        u = cu + f * (xy[..., 0] - self.position[0])
        v = cv - f * (xy[..., 1] - self.position[1])
        return np.stack([u, v], axis=-1)

    def pixel_to_world(self, uv: np.ndarray, z: float = 0.0) -> np.ndarray:
        """(..., 2) pixel (u, v) → (..., 2) world x, y on the plane at height z."""
        uv = np.asarray(uv, dtype=np.float64)
        f = self.focal_px / (self.position[2] - z)
        cu, cv = self.principal_point
        x = self.position[0] + (uv[..., 0] - cu) / f
        y = self.position[1] - (uv[..., 1] - cv) / f
        return np.stack([x, y], axis=-1)

    def workspace_half_extent(self, z: float = 0.0) -> float:
        """Half the side of the square of table visible in the image (metres)."""
        return 0.5 * min(self.width, self.height) * self.metres_per_pixel(z)

    def scaled(self, k: int) -> CameraModel:
        """The same camera imaging at k × the resolution (pixels k times smaller)."""
        if k < 1:
            raise ValueError(f"a camera's resolution scales by an integer k ≥ 1, not {k}")
        return replace(self, width=self.width * k, height=self.height * k)

    def resolution_of(self, mask: np.ndarray) -> CameraModel:
        """The camera that took the 2-D `mask`: this one or `scaled(k)` for an image k × this
        one's size (integer k ≥ 1). Raises ValueError for any other shape."""
        shape = np.shape(mask)
        h, w = shape[:2] if len(shape) >= 2 else (0, 0)
        k = h // self.height
        if len(shape) != 2 or k < 1 or (h, w) != (k * self.height, k * self.width):
            raise ValueError(
                f"an image of shape {shape} is not an integer multiple of the camera's "
                f"{(self.height, self.width)}"
            )
        return self if k == 1 else self.scaled(k)
