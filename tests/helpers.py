"""Shared test helpers (import as `from tests.helpers import ...` is avoided; pytest rootdir
puts this folder on sys.path via conftest)."""

import numpy as np
from matplotlib.path import Path as MplPath

from pushtoknow.common.camera import CameraModel


def rasterise_footprint(
    vertices_obj: np.ndarray, pose, camera: CameraModel, z: float = 0.0
) -> np.ndarray:
    """(H, W) bool: pixels whose centre lies inside the footprint placed at pose (x, y, θ) on
    the plane at height z."""
    x, y, th = pose
    R = np.array([[np.cos(th), -np.sin(th)], [np.sin(th), np.cos(th)]])
    world = vertices_obj @ R.T + np.array([x, y])
    uv = camera.world_to_pixel(world, z)
    uu, vv = np.meshgrid(np.arange(camera.width), np.arange(camera.height))
    inside = MplPath(uv).contains_points(np.column_stack([uu.ravel(), vv.ravel()]))
    return inside.reshape(camera.height, camera.width)


def iou(a: np.ndarray, b: np.ndarray) -> float:
    return float((a & b).sum() / max((a | b).sum(), 1))
