"""Rotational symmetry of a footprint: what vision can and cannot tell about orientation."""

from __future__ import annotations

import math

import numpy as np
from shapely import affinity
from shapely.geometry import Polygon

SYMMETRY_ORDERS = (6, 4, 3, 2)  # tested from the highest
CONTINUOUS = 0  # order returned for (near-)discs: any rotation looks the same
IOU_THRESHOLD = 0.97  # rotated footprint overlaps itself this much → symmetric


def _self_iou(poly: Polygon, angle: float) -> float:
    r = affinity.rotate(poly, angle, origin=(0, 0), use_radians=True)
    return poly.intersection(r).area / poly.union(r).area


def symmetry_order(vertices: np.ndarray) -> int:
    """k such that the footprint (V, 2), centred on its centroid, looks the same after a 2π/k
    turn: 1 for no symmetry, `CONTINUOUS` (0) for discs. Tolerant to pixel-level noise."""
    poly = Polygon(vertices)
    if min(_self_iou(poly, a) for a in (0.37, 1.1, 2.3)) > IOU_THRESHOLD:
        return CONTINUOUS
    for k in SYMMETRY_ORDERS:
        if _self_iou(poly, 2 * math.pi / k) > IOU_THRESHOLD:
            return k
    return 1
