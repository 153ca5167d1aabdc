"""Objects of random shapes with continuous parameters (docs/DESIGN.md §3), for evaluating
estimators on shapes nothing was tuned on.

`random_object(rng)` draws one object: a shape family (`FAMILIES`, equal shares), a footprint of
that family 5–25 cm across (the largest distance between two footprint points), randomly
rotated and mirrored, then parameters. m and μ are uniform over the catalogue ranges; the CoM
is uniform over the footprint shrunk by `CATALOGUE_COM_MARGIN` (the catalogue's rule, stricter
than the convex-hull one); I_z is m·k² with k within a physically sensible band, 0.7–1.3 times
the footprint's uniform-density radius of gyration about its centroid: uniform over the
catalogue I_z range where the band meets it, else m·(k_u·U(0.7, 1.3))², in both cases within
what `validate_params` allows. A footprint that fails the testbed's checks (`validate_footprint`,
simple polygon, centroid frame) or this module's quality checks (no needles,
`_check_quality`) is redrawn within its family.

`random_objects(n, seed)`: object i comes from its own generator, seeded by
``SeedSequence(seed, spawn_key=(i,))`` (= ``SeedSequence(seed).spawn(n)[i]``), so it does not
depend on n; it is named ``random:{seed}:{i}:{family}`` and addressable as ``random:SEED:I``
(`object_refs.load_object_spec`).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable

import numpy as np
from shapely.geometry import Polygon

from pushtoknow.common.errors import ObjectSpecError
from pushtoknow.common.params import PARAM_RANGES, ObjectParams
from pushtoknow.testbed.objects import (
    CATALOGUE_COM_MARGIN,
    MIN_GYRATION_RADIUS,
    MIN_WIDTH,
    ObjectSpec,
    inertia_upper_bound,
    validate_catalogue_params,
)
from pushtoknow.testbed.shapes import ELLIPSE_VERTICES, Footprint, about_centroid

MIN_EXTENT = 0.05  # m, smallest largest-distance across a random footprint
MAX_EXTENT = 0.25  # m, largest (its radius from the centroid stays below MAX_RADIUS = 0.2 m)
WIDTH_MARGIN = 1.02  # the scale keeps the footprint's width this factor above MIN_WIDTH
MIN_EDGE = 0.002  # m, shortest polygon edge
MIN_ANGLE_DEG = 12.0  # smallest interior angle (no needles)
GYRATION_BAND = (0.7, 1.3)  # k / k_uniform: the physically sensible radii of gyration
MAX_SHAPE_TRIES = 200
MAX_COM_TRIES = 2000


def _loguniform(rng: np.random.Generator, lo: float, hi: float) -> float:
    return float(math.exp(rng.uniform(math.log(lo), math.log(hi))))


def _angles(rng: np.random.Generator, n: int, concentration: float = 4.0) -> np.ndarray:
    """n sorted angles around the circle, gaps Dirichlet-distributed (none tiny)."""
    gaps = rng.dirichlet(np.full(n, concentration)) * 2 * np.pi
    return rng.uniform(0, 2 * np.pi) + np.cumsum(gaps)


def _convex(rng: np.random.Generator) -> np.ndarray:
    """3–12 points on a stretched circle: a convex polygon, possibly elongated."""
    n = int(rng.integers(3, 13))
    t = _angles(rng, n)
    return np.stack([_loguniform(rng, 1.0, 4.0) * np.cos(t), np.sin(t)], 1)


def _nonconvex(rng: np.random.Generator) -> np.ndarray:
    """4–12 points at random radii around the centre (a star-shaped polygon), non-convex."""
    n = int(rng.integers(4, 13))
    t = _angles(rng, n)
    r = rng.uniform(0.35, 1.0, n)
    return np.stack([_loguniform(rng, 1.0, 3.0) * r * np.cos(t), r * np.sin(t)], 1)


def _bar(rng: np.random.Generator) -> np.ndarray:
    """A rectangle 2:1 to 6:1."""
    a = rng.uniform(2.0, 6.0)
    return np.array([[0, 0], [a, 0], [a, 1], [0, 1]], dtype=np.float64)


def _kite(rng: np.random.Generator) -> np.ndarray:
    """Two isosceles triangles on a common base (convex), long to squat."""
    h = _loguniform(rng, 0.6, 3.0)
    top = rng.uniform(0.15, 0.45) * h
    return np.array([[0, top], [-0.5, 0], [0, top - h], [0.5, 0]], dtype=np.float64)


def _obtuse_triangle(rng: np.random.Generator) -> np.ndarray:
    """A triangle with one angle of 95–140°."""
    g = math.radians(rng.uniform(95.0, 140.0))
    c = rng.uniform(0.35, 1.0)
    return np.array([[0, 0], [1, 0], [c * math.cos(g), c * math.sin(g)]], dtype=np.float64)


def _t_shape(rng: np.random.Generator) -> np.ndarray:
    """A crossbar of width 1 on a stem, the stem near the middle."""
    bar, stem_w = rng.uniform(0.18, 0.4), rng.uniform(0.18, 0.45)
    stem_l = rng.uniform(0.35, 1.3)
    x0 = 0.5 - stem_w / 2 + rng.uniform(-0.3, 0.3) * (1 - stem_w) / 2
    x1 = x0 + stem_w
    top = stem_l + bar
    return np.array(
        [
            [x0, 0],
            [x1, 0],
            [x1, stem_l],
            [1, stem_l],
            [1, top],
            [0, top],
            [0, stem_l],
            [x0, stem_l],
        ],
        dtype=np.float64,
    )


def _l_shape(rng: np.random.Generator) -> np.ndarray:
    """Two arms at a right angle, of their own lengths and thicknesses."""
    a, b = 1.0, rng.uniform(0.5, 1.5)
    ta, tb = rng.uniform(0.2, 0.55) * b, rng.uniform(0.2, 0.55) * a
    return np.array([[0, 0], [a, 0], [a, ta], [tb, ta], [tb, b], [0, b]], dtype=np.float64)


def _octagon(rng: np.random.Generator) -> np.ndarray:
    """A rectangle (1:1 to 2.5:1) with its four corners cut off, each by its own amount (a
    regular octagon is the square with equal cuts of 0.29)."""
    w, h = 1.0, 1.0 / _loguniform(rng, 1.0, 2.5)
    c = rng.uniform(0.15, 0.42, 4) * h
    return np.array(
        [
            [c[0], 0],
            [w - c[1], 0],
            [w, c[1]],
            [w, h - c[2]],
            [w - c[2], h],
            [c[3], h],
            [0, h - c[3]],
            [0, c[0]],
        ]
    )


def _star(rng: np.random.Generator) -> np.ndarray:
    """4–6 points (8–12 vertices), inner radius 0.4–0.7 of the outer, slightly irregular."""
    k = int(rng.integers(4, 7))
    inner = rng.uniform(0.4, 0.7)
    t = np.arange(2 * k) * np.pi / k + rng.uniform(-0.15, 0.15, 2 * k) * np.pi / k
    r = np.where(np.arange(2 * k) % 2 == 0, 1.0, inner) * rng.uniform(0.9, 1.0, 2 * k)
    return np.stack([_loguniform(rng, 1.0, 1.6) * r * np.cos(t), r * np.sin(t)], 1)


POLYGON_FAMILIES: dict[str, Callable[[np.random.Generator], np.ndarray]] = {
    "convex": _convex,
    "nonconvex": _nonconvex,
    "bar": _bar,
    "kite": _kite,
    "obtuse_triangle": _obtuse_triangle,
    "t_shape": _t_shape,
    "l_shape": _l_shape,
    "octagon": _octagon,
    "star": _star,
}
FAMILIES: tuple[str, ...] = (*POLYGON_FAMILIES, "ellipse")  # drawn with equal shares
# k such that the 48-gon of `ellipse_footprint` has vertices at k·(a cos t, b sin t)
_ELLIPSE_K = math.sqrt(2 * math.pi / (ELLIPSE_VERTICES * math.sin(2 * math.pi / ELLIPSE_VERTICES)))


def extent(vertices) -> float:
    """The largest distance between two points of a polygon (its vertices) (m)."""
    v = np.asarray(vertices, dtype=np.float64)
    return float(np.max(np.linalg.norm(v[:, None] - v[None], axis=-1)))


def width_and_length(vertices) -> tuple[float, float]:
    """(shorter, longer) side of the minimum rotated rectangle around the polygon (m)."""
    rect = Polygon(np.asarray(vertices, dtype=np.float64)).minimum_rotated_rectangle
    xy = np.asarray(rect.exterior.coords)[:3]
    s = sorted((float(np.linalg.norm(xy[1] - xy[0])), float(np.linalg.norm(xy[2] - xy[1]))))
    return s[0], s[1]


def gyration_radius(vertices) -> float:
    """Radius of gyration (m) about the area centroid of a uniform plate of this polygon."""
    v = np.asarray(vertices, dtype=np.float64)
    v = v - Polygon(v).centroid.coords[0]
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cross = x * y1 - x1 * y
    area = 0.5 * np.sum(cross)
    polar = np.sum(cross * (x * x + x * x1 + x1 * x1 + y * y + y * y1 + y1 * y1)) / 12.0
    return float(math.sqrt(polar / area))


def _interior_angles_deg(v: np.ndarray) -> np.ndarray:
    """Interior angles of a counter-clockwise polygon (degrees; > 180 at reflex vertices)."""
    a = np.roll(v, 1, axis=0) - v
    b = np.roll(v, -1, axis=0) - v
    ang = np.degrees(np.arctan2(b[:, 0] * a[:, 1] - b[:, 1] * a[:, 0], np.sum(a * b, axis=1)))
    return np.mod(ang, 360.0)


def _check_quality(fp: Footprint) -> None:
    """Refuse needles the testbed's own checks let through: short edges and sharp corners."""
    v = fp.vertices
    edges = np.linalg.norm(np.roll(v, -1, axis=0) - v, axis=1)
    if edges.min() < MIN_EDGE:
        raise ObjectSpecError("shape", f"edge {edges.min():.4f} m", f"shorter than {MIN_EDGE} m")
    if fp.kind == "polygon":
        angles = _interior_angles_deg(v)
        if angles.min() < MIN_ANGLE_DEG:
            raise ObjectSpecError("shape", f"angle {angles.min():.1f}°", "a needle")


def _polygon_shape(rng: np.random.Generator, family: str) -> dict:
    v = POLYGON_FAMILIES[family](rng)
    if rng.random() < 0.5:
        v = v * np.array([-1.0, 1.0])  # mirror image (chiral families: L, T, triangles)
    th = rng.uniform(0, 2 * np.pi)
    rot = np.array([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]])
    v = v @ rot.T
    if Polygon(v).exterior.is_ccw is False:
        v = v[::-1]
    # Size: uniform in the extents whose width stays above MIN_WIDTH.
    d = extent(v)
    w, _ = width_and_length(v)
    lo = max(MIN_EXTENT, WIDTH_MARGIN * MIN_WIDTH * d / w)
    if lo > MAX_EXTENT:
        raise ObjectSpecError("shape", f"aspect {d / w:.1f}", "too thin for MAX_EXTENT")
    v = v * (rng.uniform(lo, MAX_EXTENT) / d)
    return {"type": "polygon", "vertices": about_centroid(v)}


def _ellipse_shape(rng: np.random.Generator) -> dict:
    """Axis-aligned (the spec has no rotation), long axis along x or y; any aspect the width
    bound allows."""
    size = rng.uniform(MIN_EXTENT, MAX_EXTENT)
    aspect = _loguniform(rng, 1.0, size / (WIDTH_MARGIN * MIN_WIDTH))
    a = size / (2 * _ELLIPSE_K)
    b = a / aspect
    if rng.random() < 0.5:
        a, b = b, a
    return {"type": "ellipse", "a": a, "b": b}


def _draw_shape(rng: np.random.Generator, family: str) -> tuple[ObjectSpec, int]:
    """A valid footprint of the family (as a spec with placeholder parameters) and the number
    of redraws it took."""
    for tries in range(MAX_SHAPE_TRIES):
        try:
            shape = _ellipse_shape(rng) if family == "ellipse" else _polygon_shape(rng, family)
            # Placeholder parameters that any footprint accepts: ObjectSpec runs the testbed's
            # footprint checks (simple polygon, centroid frame, radius, width).
            spec = ObjectSpec(shape=shape, params=ObjectParams(1.0, 0.5, 0.0, 0.0, 1e-4))
            _check_quality(spec.footprint)
            if family == "nonconvex" and spec.footprint.is_convex():
                raise ObjectSpecError("shape", family, "convex")
            if spec.footprint.polygon.buffer(-CATALOGUE_COM_MARGIN).area <= 0:
                raise ObjectSpecError("shape", family, "no room for the CoM")
        except ObjectSpecError:
            continue
        return spec, tries
    raise RuntimeError(f"no valid {family} footprint in {MAX_SHAPE_TRIES} tries")


def _draw_com(rng: np.random.Generator, fp: Footprint) -> tuple[float, float]:
    """Uniform over the footprint's points `CATALOGUE_COM_MARGIN` inside it."""
    poly = fp.polygon
    minx, miny, maxx, maxy = poly.buffer(-CATALOGUE_COM_MARGIN).bounds
    for _ in range(MAX_COM_TRIES):
        x, y = rng.uniform(minx, maxx), rng.uniform(miny, maxy)
        if fp.contains((x, y), margin=CATALOGUE_COM_MARGIN):
            return float(x), float(y)
    raise RuntimeError(f"no CoM inside the footprint in {MAX_COM_TRIES} tries")


def _draw_inertia(rng: np.random.Generator, mass: float, fp: Footprint, com) -> float:
    """I_z = m·k², k within `GYRATION_BAND` of the uniform plate's radius of gyration: uniform
    over the catalogue range where it meets that band, else m·(k_u·U(band))²; clipped to what
    `validate_params` allows."""
    lo_valid = mass * MIN_GYRATION_RADIUS**2 * 1.001
    hi_valid = inertia_upper_bound(mass, fp, com) * 0.999
    ku = gyration_radius(fp.vertices)
    band = (mass * (GYRATION_BAND[0] * ku) ** 2, mass * (GYRATION_BAND[1] * ku) ** 2)
    cat = PARAM_RANGES["inertia"]
    lo = max(cat[0], band[0], lo_valid)
    hi = min(cat[1], band[1], hi_valid)
    if lo < hi:
        return float(rng.uniform(lo, hi))
    k = ku * rng.uniform(*GYRATION_BAND)
    return float(np.clip(mass * k * k, lo_valid, hi_valid))


def _draw(rng: np.random.Generator) -> tuple[ObjectSpec, str, int]:
    """(spec, family, footprint redraws)."""
    family = FAMILIES[int(rng.integers(len(FAMILIES)))]
    shape_spec, redraws = _draw_shape(rng, family)
    fp = shape_spec.footprint
    mass = float(rng.uniform(*PARAM_RANGES["mass"]))
    friction = float(rng.uniform(*PARAM_RANGES["friction"]))
    com = _draw_com(rng, fp)
    inertia = _draw_inertia(rng, mass, fp, com)
    params = ObjectParams(mass, friction, com[0], com[1], inertia)
    validate_catalogue_params(params, fp)  # holds by construction
    spec = ObjectSpec(shape=shape_spec.shape, params=params, name=f"random:{family}")
    return spec, family, redraws


def is_random_shape(name: str | None) -> bool:
    """An object called `name` (`ObjectSpec.name`) was drawn here: it starts ``random:``."""
    return (name or "").startswith("random:")


def random_object(rng: np.random.Generator) -> ObjectSpec:
    """One object of a random shape with continuous parameters (module docstring), named
    ``random:{family}``."""
    return _draw(rng)[0]


def random_object_rng(seed: int, index: int) -> np.random.Generator:
    """Object `index`'s generator for `seed`: ``SeedSequence(seed).spawn(n)[index]`` for any n."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ObjectSpecError("random seed", seed, "must be a non-negative integer")
    if isinstance(index, bool) or not isinstance(index, (int, np.integer)) or index < 0:
        raise ObjectSpecError("random object index", index, "must be a non-negative integer")
    return np.random.default_rng(np.random.SeedSequence(int(seed), spawn_key=(int(index),)))


def random_object_at(seed: int, index: int) -> ObjectSpec:
    """Object `index` of the random objects of `seed`, named ``random:{seed}:{index}:{family}``."""
    spec, family, _ = _draw(random_object_rng(seed, index))
    return dataclasses.replace(spec, name=f"random:{seed}:{index}:{family}")


def random_objects(n: int, seed: int = 0) -> list[ObjectSpec]:
    """n random objects; object i is `random_object_at(seed, i)`, whatever n."""
    return [random_object_at(seed, i) for i in range(n)]


def parse_random_ref(ref: str) -> ObjectSpec:
    """``random:SEED:I`` (or a spec's full name ``random:SEED:I:FAMILY``) → that object."""
    parts = ref.split(":")
    usage = "must be random:SEED:I with non-negative integers SEED and I"
    if parts[0] != "random" or len(parts) not in (3, 4):
        raise ObjectSpecError("random object", ref, usage)
    try:
        seed, index = int(parts[1]), int(parts[2])
    except ValueError:
        raise ObjectSpecError("random object", ref, usage) from None
    if seed < 0 or index < 0:
        raise ObjectSpecError("random object", ref, usage)
    spec = random_object_at(seed, index)
    if len(parts) == 4 and spec.name != ref:
        raise ObjectSpecError("random object", ref, f"that object is {spec.name}")
    return spec
