"""The push a = (cp, pd, v) that a recorded pad track performed: shared by the MIT Push import
(`datasets.mit_import.push_action`) and the recording format (`datasets.recording`).

Rules (docs/DESIGN.md §11): contact samples are first..last (the first and last sample with
contact; sample k's contact refers to the window ending at t_k). Sample `onset` = max(first − 1,
0) is the last one before contact, where the pad reaches the object (0 without contact).
direction = angle of the pad's displacement from sample onset to sample last; if that is
shorter than `MIN_DIRECTION_DISPLACEMENT`, the displacement over the whole push; if that is
short too, from the pad towards the object at sample onset. contact point = the point of the
footprint's boundary nearest the pad at sample onset, found in the object frame at that sample
and placed on the *initial* pose (as simulated actions are); without a footprint, the pad's
front at onset (its centre + radius along the direction).
"""

from __future__ import annotations

import math

import numpy as np

from pushtoknow.testbed.push import Push

MIN_DIRECTION_DISPLACEMENT = 1e-3  # m of pad travel needed to define a push direction


def rotation(th: float) -> np.ndarray:
    """(2, 2) rotation by th (rad)."""
    c, s = math.cos(th), math.sin(th)
    return np.array([[c, -s], [s, c]])


def nearest_on_boundary(poly: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Point of the closed polygon boundary (V, 2) nearest to p (2,)."""
    a = poly
    b = np.roll(poly, -1, axis=0)
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.einsum("ij,ij->i", ab, ab), 0.0, 1.0)
    q = a + t[:, None] * ab
    return q[int(np.argmin(np.linalg.norm(q - p, axis=1)))]


def contact_span(contact: np.ndarray) -> tuple[int, int]:
    """(first, last) indices of the samples with contact (T,) bool; (-1, -1) without any."""
    idx = np.flatnonzero(np.asarray(contact, dtype=bool))
    return (int(idx[0]), int(idx[-1])) if idx.size else (-1, -1)


def push_from_track(
    pad: np.ndarray,
    pose: np.ndarray,
    contact: np.ndarray,
    time: np.ndarray,
    polygon: np.ndarray | None = None,
    speed: float | None = None,
    shift: np.ndarray | None = None,
    pad_radius: float = 0.0,
) -> Push:
    """The constant push a recording performed (module doc for the rules).

    pad (T, 2) m world: the pad centre; pose (T, 3) object (x, y, θ) m, m, rad; contact (T,)
    bool; time (T,) s; polygon (V, 2) m: the footprint in the object frame, or None (then the
    contact point is the pad's front at onset, `pad_radius` m ahead of its centre).
    speed (m/s): None gives the pad's mean speed from onset to the last contact sample (over
    the whole push without contact). shift (2,) m is added to the contact point (world).
    """
    pad = np.asarray(pad, dtype=np.float64)
    pose = np.asarray(pose, dtype=np.float64)
    shift = np.zeros(2) if shift is None else np.asarray(shift, dtype=np.float64)
    first, last = contact_span(contact)
    k = max(first - 1, 0)
    d = pad[last] - pad[k] if first >= 0 else np.zeros(2)
    if np.linalg.norm(d) < MIN_DIRECTION_DISPLACEMENT:
        d = pad[-1] - pad[0]
    if np.linalg.norm(d) < MIN_DIRECTION_DISPLACEMENT:
        d = pose[k, :2] - pad[k]
    direction = math.atan2(d[1], d[0])
    if polygon is not None:
        tip_obj = rotation(pose[k, 2]).T @ (pad[k] - pose[k, :2])  # pad in the frame at k
        cp_obj = nearest_on_boundary(np.asarray(polygon, dtype=np.float64), tip_obj)
        cp = pose[0, :2] + rotation(pose[0, 2]) @ cp_obj + shift
    else:
        cp = pad[k] + pad_radius * np.array([math.cos(direction), math.sin(direction)]) + shift
    if speed is None:
        i, j = (k, last) if first >= 0 and last > k else (0, len(pad) - 1)
        dt = float(time[j] - time[i])
        speed = float(np.linalg.norm(pad[j] - pad[i]) / dt) if dt > 0 else 0.0
    return Push((float(cp[0]), float(cp[1])), float(direction), "constant", float(speed))
