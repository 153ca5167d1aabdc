"""The object's pose before a push, found geometrically (docs/DESIGN.md §12): the contour
traced before the first push, registered rigidly to the contour of the mask seen before a
later one.

Both contours are traced the same way (`perception.footprint.replay_contour`), so smoothing
rounds their corners alike and the registration is unbiased by it. The fit is point-to-line
ICP (Gauss–Newton on each outline point's distance along its normal, Huber-weighted) fused
with a guess, the learned pose sensor's (`GUESS_STD`). Where the guess is wrong (its fit is
worse than the best of fits from `STARTS` rotations), the outline decides, among a symmetric
outline's copies the one nearest the guess; an outline that does not fix its rotation (a disc)
keeps the guess's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from pushtoknow.common.angles import wrap_angle
from pushtoknow.geometry.affordances import Contour
from pushtoknow.perception.footprint import resample, to_object_frame

POINT_SPACING = 5e-4  # m: the contours are resampled to a point per this arc length
CONTOUR_NOISE = 1e-3  # m: a traced contour point's error (the residuals' scale)
HUBER = 2e-3  # m: residuals beyond this are down-weighted (an occluded or changed boundary)
# (m, m, rad): the guess's error (the learned pose sensor's, typically 1–3 mm and 0.5–5°),
# where the outline leaves the pose to it (a near-circle's rotation)
GUESS_STD = np.array([0.003, 0.003, math.radians(3.0)])
STEP_DAMPING = 1.0 / np.array([0.01, 0.01, math.radians(10.0)]) ** 2  # Levenberg damping
# An outline that a turn of ROTATION_PROBE moves by less than SYMMETRY_RMS (RMS over its
# points, along its normals) does not fix its rotation (a disc): the guess's is kept. The
# traced contours fit each other to 0.2–0.55 mm RMS at the true pose.
ROTATION_PROBE = math.radians(5.0)
SYMMETRY_RMS = 5e-4
STARTS = 12  # rotations tried, evenly over the circle from the guess's
TIE = (1.2, 1e-4)  # fits with RMS ≤ TIE[0] × the best's + TIE[1] (m) fit the outline alike
ITERATIONS = 50
# a fit from one of the STARTS still this many times the guess's fit's RMS, plus the margin (m),
# after ABANDON_AFTER iterations cannot tie with it: it stops there (they crawl, Huber-weighted)
ABANDON_AFTER = 10
ABANDON = (5.0, 1e-3)
STEP_TOLERANCE = 1e-7  # m (and rad·m): the iteration stops when the step is below this


@dataclass(frozen=True)
class Registration:
    """pose: (3,) (x, y, θ) placing the outline on the mask; rms: the outline points' RMS
    distance (m) from the nearest of the mask's contour points (every `POINT_SPACING`)."""

    pose: np.ndarray
    rms: float


def outline_points(contour: Contour, pose0: np.ndarray) -> np.ndarray:
    """A traced contour's points (`_dense`) in the object frame of the pose (3,) (x, y, θ) it
    was traced at: (N, 2) m."""
    return to_object_frame(_dense(contour.points), np.asarray(pose0[:2]), pose0)


def register(points: np.ndarray, contour: Contour, guess: np.ndarray) -> Registration:
    """The pose (3,) placing object-frame points (N, 2) on a traced contour (world) (module
    doc). ICP from `guess` (3,), fused with it (`GUESS_STD`), where that fits the outline as
    well as the best of ICP runs from `STARTS` rotations of the guess (`TIE`); else, the guess
    being wrong, the best fit nearest it in rotation (of a symmetric outline's copies)."""
    target = _dense(contour.points)
    normals = _normals(points)
    tree = cKDTree(target)
    guess = np.asarray(guess, dtype=np.float64)
    if not fixes_rotation(points, normals):
        return _fit(points, target, normals, tree, guess, guess, rotation=False)
    fused = _fit(points, target, normals, tree, guess, guess)
    hopeless = ABANDON[0] * fused.rms + ABANDON[1]
    fits = []
    for j in range(STARTS):
        start = guess + np.array([0.0, 0.0, 2.0 * math.pi * j / STARTS])
        fits.append(_fit(points, target, normals, tree, start, None, abandon=hopeless))
    tie = TIE[0] * min(f.rms for f in fits) + TIE[1]
    if fused.rms <= tie:  # the guess lies in a best fit's basin
        return fused
    alike = [f for f in fits if f.rms <= tie]  # else the guess is wrong: the outline decides
    return min(alike, key=lambda f: abs(wrap_angle(f.pose[2] - guess[2])))


def _dense(points: np.ndarray) -> np.ndarray:
    """A closed contour's points (N, 2) resampled to one every `POINT_SPACING` (at least N)."""
    pts = np.asarray(points, dtype=np.float64)
    perimeter = float(np.linalg.norm(pts - np.roll(pts, 1, axis=0), axis=1).sum())
    return resample(pts, max(len(pts), int(perimeter / POINT_SPACING)))


def fixes_rotation(points: np.ndarray, normals: np.ndarray) -> bool:
    """Whether the outline's points (N, 2) with their normals (N, 2) fix its rotation: turned
    by ROTATION_PROBE about their mean, they lie more than SYMMETRY_RMS (RMS, along the
    nearest point's normal) off themselves."""
    centre = points.mean(axis=0)
    turned = _place(points - centre, np.array([0.0, 0.0, ROTATION_PROBE])) + centre
    _, idx = cKDTree(points).query(turned)
    off = np.einsum("ij,ij->i", normals[idx], turned - points[idx])
    return bool(np.sqrt(np.mean(off**2)) > SYMMETRY_RMS)


def _normals(points: np.ndarray) -> np.ndarray:
    """Unit normals (N, 2) of a closed contour's points (N, 2)."""
    tangent = np.roll(points, -1, 0) - np.roll(points, 1, 0)
    normals = np.stack([tangent[:, 1], -tangent[:, 0]], 1)
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def _place(points: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """Object-frame points (N, 2) at pose (3,): world (N, 2)."""
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return points @ np.array([[c, s], [-s, c]]) + pose[:2]


def _fit(
    points,
    target,
    normals,
    tree,
    start: np.ndarray,
    anchor,
    rotation: bool = True,
    abandon: float = np.inf,
) -> Registration:
    """Point-to-line ICP (Gauss–Newton, Levenberg-damped, Huber-weighted) of points (N, 2)
    with their normals (N, 2) onto the target contour's points (M, 2) from `start` (3,): the
    outline's own normals, so a rotation it does not fix is not fitted to the target's pixel
    staircase (fixed in the world, not the object). With `anchor` (3,), the guess fused in
    with GUESS_STD; without `rotation`, the rotation stays the start's. A fit whose
    point-to-line RMS (a lower bound of the returned RMS) still exceeds `abandon` (m) after
    `ABANDON_AFTER` iterations stops there."""
    pose = start.copy()
    weight = 1.0 / CONTOUR_NOISE**2
    prior = np.zeros(3) if anchor is None else 1.0 / GUESS_STD**2
    for iteration in range(ITERATIONS):
        world = _place(points, pose)
        arm = world - pose[:2]  # R(θ) q
        _, idx = tree.query(world)
        n = _place(normals, np.array([0.0, 0.0, pose[2]]))  # R(θ) n
        r = np.einsum("ij,ij->i", n, world - target[idx])
        if iteration >= ABANDON_AFTER and np.sqrt(np.mean(r**2)) > abandon:
            break
        jac = np.stack([n[:, 0], n[:, 1], n[:, 1] * arm[:, 0] - n[:, 0] * arm[:, 1]], 1)
        w = weight * np.minimum(1.0, HUBER / np.maximum(np.abs(r), 1e-12))
        info = jac.T @ (jac * w[:, None]) + np.diag(prior)
        grad = jac.T @ (w * r)
        if anchor is not None:
            grad = grad + prior * (pose - anchor)
        if not rotation:
            info, grad = info[:2, :2], grad[:2]
        step = -np.linalg.solve(info + np.diag(STEP_DAMPING[: len(grad)]), grad)
        step = np.append(step, 0.0) if not rotation else step
        pose = pose + step
        if np.linalg.norm(step[:2]) + abs(step[2]) * 0.05 < STEP_TOLERANCE:
            break
    dist, _ = tree.query(_place(points, pose))
    return Registration(pose, float(np.sqrt(np.mean(dist**2))))
