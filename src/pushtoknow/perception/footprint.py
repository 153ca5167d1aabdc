"""The object's footprint as the camera sees it before a push (docs/DESIGN.md §5, §9)."""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np
from scipy.ndimage import gaussian_filter, map_coordinates
from shapely.geometry import Polygon

from pushtoknow.common.camera import CameraModel
from pushtoknow.geometry.affordances import Contour, largest_level_line, mask_contour
from pushtoknow.testbed.objects import MIN_WIDTH, narrowest_side
from pushtoknow.testbed.shapes import polygon_footprint

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
    return to_object_frame(pts, c.centroid, pose0)


def to_object_frame(points: np.ndarray, centroid: np.ndarray, pose0) -> np.ndarray:
    """World points (N, 2) on the traced plane → the object frame of pose0 (x, y, θ) whose
    origin is the traced contour's `centroid` (2,): translated to it and rotated by −θ0."""
    th = -float(pose0[2])
    rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    return (np.asarray(points) - centroid) @ rot.T


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


# The outline the simulator replays (`replay_outline`): traced with little smoothing, its straight
# edges fitted and extended to meet, so corners are as sharp as the object's. Smoothing rounds a
# corner of angle α by about σ / sin(α/2): 5 mm of it clips a 35° tip by 16 mm.
REPLAY_SMOOTHING = OUTLINE_SMOOTHING  # m: a staircase-free outline (its corners are refitted)
REPLAY_SIMPLIFY = 0.0015  # m: Douglas–Peucker tolerance finding the edges
REPLAY_MIN_EDGE = 0.012  # m: edges this long are fitted as lines; shorter ones are corner bevels
REPLAY_MIN_TURN = math.radians(20.0)  # adjacent fitted edges turning less meet as traced
REPLAY_MAX_EXTENSION = 0.012  # m: a corner is refitted at most this far beyond the contour
REPLAY_STRAIGHTNESS = 2e-4  # m: an edge is straight where its contour points lie this close
REPLAY_CLIP_SLACK = 0.001  # m: a refitted corner lies at most this beyond the clip smoothing makes


def _fit_line(points: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Total least squares line through points (N, 2): (point on it, unit direction, RMS
    distance of the points from it)."""
    c = points.mean(axis=0)
    _, sv, vt = np.linalg.svd(points - c, full_matrices=False)
    return c, vt[0], float(sv[-1] / np.sqrt(len(points)))


def sharpen_corners(contour: np.ndarray, smoothing: float = REPLAY_SMOOTHING) -> np.ndarray:
    """A polygon (V, 2) for a traced closed contour (N, 2), CCW. Douglas–Peucker edges at least
    `REPLAY_MIN_EDGE` long whose middle contour points lie on a line (RMS below
    `REPLAY_STRAIGHTNESS`) are refitted to those points; two such edges separated only by
    curved or short ones (a corner smoothing rounded off) are extended to meet, where they turn
    by more than `REPLAY_MIN_TURN` and meet no farther beyond the contour than smoothing rounds
    a corner of that angle (`_rounded_corner`; `smoothing`, m: the σ the contour was traced
    with). Curves stay as traced."""
    from shapely.geometry import Polygon

    pts = np.asarray(contour, dtype=np.float64)
    traced = Polygon(pts).buffer(0)
    pts = resample(pts, max(len(pts), int(traced.length / 5e-4)))  # ≥ 1 point per 0.5 mm
    rough = traced.simplify(REPLAY_SIMPLIFY)
    if rough.geom_type != "Polygon":
        return pts
    v = np.asarray(rough.exterior.coords)[:-1]
    if not Polygon(v).exterior.is_ccw:
        v = v[::-1]
    k = len(v)
    lines: list[tuple[np.ndarray, np.ndarray] | None] = []
    for i in range(k):
        a, b = v[i], v[(i + 1) % k]
        length = float(np.linalg.norm(b - a))
        line = None
        if length >= REPLAY_MIN_EDGE:
            d = (b - a) / length
            t = (pts - a) @ d
            off = np.abs((pts - a) @ np.array([-d[1], d[0]]))
            near = (t > 0.2 * length) & (t < 0.8 * length) & (off < 2 * REPLAY_SIMPLIFY)
            if near.sum() >= 3:
                p, e, rms = _fit_line(pts[near])
                if rms < REPLAY_STRAIGHTNESS:
                    line = (p, e if e @ d > 0 else -e)
        lines.append(line)
    straight = [i for i in range(k) if lines[i] is not None]
    if len(straight) < 2:
        return v
    out: list[np.ndarray] = []
    for j, i in enumerate(straight):
        nxt = straight[(j + 1) % len(straight)]
        chain = [v[(m + 1) % k] for m in range(i, i + ((nxt - i) % k or k))]  # traced corners
        (p, d), (q, e) = lines[i], lines[nxt]
        cross = d[0] * e[1] - d[1] * e[0]
        turn = math.atan2(cross, float(d @ e))
        corner = None
        if abs(turn) > REPLAY_MIN_TURN:
            s = ((q - p)[0] * e[1] - (q - p)[1] * e[0]) / cross
            x = p + s * d
            if _rounded_corner(x, turn, traced, smoothing):
                corner = x
        out.extend([corner] if corner is not None else chain)
    if len(out) < 3:  # two straight edges meeting at both ends: no polygon, keep the trace
        return v
    poly = Polygon(out)
    if not poly.is_valid or abs(poly.area / Polygon(pts).area - 1.0) > 0.15:
        return v
    return np.asarray(out)


def _rounded_corner(x: np.ndarray, turn: float, traced, smoothing: float) -> bool:
    """Whether a corner at x (2,) turning by `turn` (rad) lies no farther outside the traced
    contour than smoothing by σ = `smoothing` (m) rounds such a corner off: a corner of
    interior angle α rounded to radius r lies r (1 / sin(α/2) − 1) beyond its arc; r is taken
    as 2σ, plus `REPLAY_CLIP_SLACK`, and never more than `REPLAY_MAX_EXTENSION`: the end of
    an elongated ellipse looks like a rounded corner too, and this bounds what a wrong guess
    costs."""
    from shapely.geometry import Point

    half = 0.5 * (math.pi - abs(turn))
    clip = 2.0 * smoothing * (1.0 / math.sin(half) - 1.0) + REPLAY_CLIP_SLACK
    return traced.exterior.distance(Point(*x)) <= min(clip, REPLAY_MAX_EXTENSION)


def replay_outline(contour: Contour, pose0) -> np.ndarray:
    """The footprint (V, 2) a simulator replays the pushes with, in the object frame of pose0
    (x, y, θ): the `replay_contour` seen at pose0, corners sharpened (`sharpen_corners`), about
    its centroid."""
    return to_object_frame(sharpen_corners(contour.points), contour.centroid, pose0)


def replay_contour(
    s0: np.ndarray, depth: np.ndarray, outline_mask: np.ndarray | None, camera: CameraModel
) -> Contour:
    """The object's contour (world, m) seen before a push, as the replayed outline is traced:
    on the outline-resolution mask (else S_0 (H, W)) with `REPLAY_SMOOTHING`, on the plane of
    the object's top found in the depth (H, W) m."""
    mask = s0 if outline_mask is None else outline_mask
    return outline_contour(mask, camera, object_top(depth, s0, camera))


def outline_contour(mask: np.ndarray, camera: CameraModel, top: float) -> Contour:
    """The contour (world, m) traced as `replay_contour` traces it on an object mask (H, W) or
    (kH, kW), on the plane at height `top` (m, the object's top)."""
    return mask_contour(mask, camera, top, smoothing=REPLAY_SMOOTHING)


def replay_shape(
    mask: np.ndarray, camera: CameraModel, top: float, pose0
) -> tuple[dict, tuple[float, float]]:
    """The polygon spec a simulator replays the pushes of an object with, traced on its mask
    (H, W) or (kH, kW) seen at pose0 (x, y, θ) with its top at `top` (m) as the physics filter
    traces it (`outline_contour`, `sharpen_corners`, `outline_shape`): about its centroid, and
    that centroid's position in the object frame of pose0 (origin at pose0's x, y; m)."""
    contour = outline_contour(mask, camera, top)
    local = to_object_frame(sharpen_corners(contour.points), np.asarray(pose0)[:2], pose0)
    return outline_shape(local)


OUTLINE_SIMPLIFY = 2e-4  # m: the outline's vertices within this of a line are dropped


def outline_shape(footprint: np.ndarray) -> tuple[dict, tuple[float, float]]:
    """A polygon spec (`testbed.objects`) of a traced footprint (V, 2), object frame:
    simplified and centred on its centroid, as the testbed requires; and that centroid's
    position in the object frame (m), the replay's `frame_offset`."""
    poly = Polygon(np.asarray(footprint, dtype=np.float64)).buffer(0).simplify(OUTLINE_SIMPLIFY)
    if poly.geom_type != "Polygon":
        poly = max(poly.geoms, key=lambda g: g.area)
    c = poly.centroid
    verts = np.asarray(poly.exterior.coords)[:-1] - np.array([c.x, c.y])
    if Polygon(verts).exterior.is_ccw is False:
        verts = verts[::-1]
    return {"type": "polygon", "vertices": at_least_min_width(verts).tolist()}, (c.x, c.y)


WIDEN_ROUNDS = 8  # stretches `at_least_min_width` tries


def at_least_min_width(verts: np.ndarray) -> np.ndarray:
    """Polygon vertices (V, 2) about their centroid, stretched across their narrowest direction
    (the minimum rotated rectangle's short side) to 1% above `testbed.objects.MIN_WIDTH` where
    narrower, again until the testbed's width check passes (a stretch can tilt the rectangle):
    a traced outline loses up to a pixel on each side, and the testbed simulates no object
    narrower than the camera can see."""
    for _ in range(WIDEN_ROUNDS):  # a stretch can tilt the rectangle: stretch again
        short = narrowest_side(polygon_footprint(verts))  # as `validate_footprint` measures
        width = float(np.linalg.norm(short))
        if width >= MIN_WIDTH:
            return verts
        axis = short / width
        verts = verts + np.outer((verts @ axis) * (1.01 * MIN_WIDTH / width - 1.0), axis)
    return verts


# The outline refined from several views (`fused_outline`): each outline mask is smoothed this
# much, sampled on an object-frame grid this fine at the pose it was seen at, and the average
# traced at one half. The pixel staircase (2.4 mm pixels at the outline resolution) falls at
# another place on the object in each view, so fewer views need less smoothing than one.
FUSION_SMOOTHING = 0.0025  # m
FUSION_GRID = 5e-4  # m
FUSION_MARGIN = 0.01  # m: the grid reaches this beyond every mask's pixels


def fused_contour(
    masks: Sequence[np.ndarray], poses: Sequence[np.ndarray], camera: CameraModel, top: float
) -> np.ndarray:
    """The object's contour (N, 2) in its object frame, CCW, from outline masks (kH, kW) (or
    (H, W)) seen at poses (3,) (x, y, θ) of that frame, traced on the plane at height `top`
    (m): each mask smoothed by `FUSION_SMOOTHING` and sampled bilinearly on an object-frame
    grid of `FUSION_GRID`, the samples averaged over the views and traced at 0.5."""
    if len(masks) != len(poses) or not masks:
        raise ValueError(f"{len(masks)} masks for {len(poses)} poses: one pose per mask")
    cams = [camera.resolution_of(np.asarray(m)) for m in masks]
    seen = []
    for mask, pose, cam in zip(masks, poses, cams):
        v, u = np.nonzero(np.asarray(mask))
        if u.size == 0:
            raise ValueError("an outline mask is empty: the object is not in view")
        world = cam.pixel_to_world(np.stack([u, v], 1).astype(np.float64), top)
        seen.append(to_object_frame(world, np.asarray(pose[:2], dtype=np.float64), pose))
    pts = np.concatenate(seen)
    lo, hi = pts.min(axis=0) - FUSION_MARGIN, pts.max(axis=0) + FUSION_MARGIN
    gx, gy = np.arange(lo[0], hi[0], FUSION_GRID), np.arange(lo[1], hi[1], FUSION_GRID)
    grid = np.stack(np.meshgrid(gx, gy), -1).reshape(-1, 2)
    average = np.zeros(len(grid))
    for mask, pose, cam in zip(masks, poses, cams):
        sigma = FUSION_SMOOTHING / cam.metres_per_pixel(top)
        img = gaussian_filter(np.asarray(mask, np.float64), sigma)
        c, s = math.cos(pose[2]), math.sin(pose[2])
        world = grid @ np.array([[c, s], [-s, c]]) + np.asarray(pose[:2], dtype=np.float64)
        uv = cam.world_to_pixel(world, top)
        average += map_coordinates(img, [uv[:, 1], uv[:, 0]], order=1, mode="constant")
    average = (average / len(masks)).reshape(len(gy), len(gx))
    line = largest_level_line(average, gx, gy)
    x, y = line[:, 0], line[:, 1]
    if np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) < 0:
        line = line[::-1]
    return np.asarray(line, dtype=np.float64)


def fused_outline(
    masks: Sequence[np.ndarray], poses: Sequence[np.ndarray], camera: CameraModel, top: float
) -> np.ndarray:
    """The footprint (V, 2) a simulator replays pushes with, from several views
    (`fused_contour`, same arguments), corners sharpened (`sharpen_corners`) as rounded by
    `FUSION_SMOOTHING`, in the object frame the poses are of."""
    return sharpen_corners(fused_contour(masks, poses, camera, top), FUSION_SMOOTHING)
