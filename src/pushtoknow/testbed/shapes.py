"""Footprint shapes: simple polygons (convex or not) and ellipses, in the object frame.

The object frame has its origin at the footprint centroid (area centroid) and the catalogue
orientation. Every shape exposes its footprint as a polygon (ellipses discretised) so that the
geometry code treats all shapes alike; collision uses convex pieces of that polygon.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from shapely.geometry import Point, Polygon
from shapely.validation import explain_validity

from pushtoknow.common.errors import ObjectSpecError

ELLIPSE_VERTICES = 48  # polygonal approximation of ellipse footprints (max radial error 0.2%)

# docs/DESIGN.md §3 catalogue shapes (metres). butter: approximated as a rounded rectangle (see
# below).
CATALOGUE_SHAPES: dict[str, dict] = {
    "rect1": {"type": "rectangle", "width": 0.090, "height": 0.090},
    "rect2": {"type": "rectangle", "width": 0.0899, "height": 0.1126},
    "rect3": {"type": "rectangle", "width": 0.1350, "height": 0.0899},
    "tri1": {"type": "right_triangle", "leg_x": 0.1259, "leg_y": 0.1259},
    # Right angle in the +x/+y corner, legs along −x and −y: the MIT Push object frame.
    "tri2": {"type": "right_triangle", "leg_x": 0.1510, "leg_y": 0.1259},
    "tri3": {"type": "right_triangle", "leg_x": 0.1765, "leg_y": 0.1256},
    "ellip1": {"type": "ellipse", "a": 0.0525, "b": 0.0525},
    "ellip2": {"type": "ellipse", "a": 0.0525, "b": 0.0654},
    "ellip3": {"type": "ellipse", "a": 0.0525, "b": 0.0785},
    "hex": {"type": "hexagon", "circumradius": 0.0605},
    # MIT "butter" is a convex rounded shape ~0.095 m wide; we approximate it by a rounded
    # rectangle 0.095 × 0.085 m with 0.02 m corner radius (our approximation, not measured).
    "butter": {"type": "rounded_rectangle", "width": 0.095, "height": 0.085, "radius": 0.02},
}


@dataclass(frozen=True)
class Footprint:
    """A planar footprint. vertices: (V, 2) counter-clockwise, centroid at the origin (m)."""

    vertices: np.ndarray
    kind: str = "polygon"  # "polygon" | "ellipse"
    ellipse_axes: tuple[float, float] | None = None  # semi-axes (a, b) for ellipses

    @property
    def polygon(self) -> Polygon:
        return Polygon(self.vertices)

    @property
    def area(self) -> float:
        return float(self.polygon.area)

    def contains(self, xy, margin: float = 0.0) -> bool:
        """True if point xy (object frame) lies inside, at least `margin` metres from the edge."""
        p = Point(float(xy[0]), float(xy[1]))
        poly = self.polygon
        return bool(poly.contains(p)) and poly.exterior.distance(p) >= margin

    def com_region(self, margin: float = 0.0) -> Polygon:
        """Where a centre of mass can lie: the convex hull of the footprint (any mass
        distribution over it has its CoM there, a non-convex footprint's notch included),
        shrunk by `margin` (m)."""
        return self.polygon.convex_hull.buffer(-margin)

    def max_radius_from(self, xy) -> float:
        """Largest distance from xy to any point of the footprint (m)."""
        return float(np.max(np.linalg.norm(self.vertices - np.asarray(xy)[None], axis=1)))

    def is_convex(self) -> bool:
        poly = self.polygon
        return bool(abs(poly.convex_hull.area - poly.area) < 1e-12)

    def convex_pieces(self) -> list[np.ndarray]:
        """Decompose into convex polygons (each (k, 2), CCW). Convex shapes return themselves."""
        if self.is_convex():
            return [self.vertices]
        import mapbox_earcut as earcut

        tri = earcut.triangulate_float64(self.vertices, np.array([len(self.vertices)]))
        tri = np.asarray(tri).reshape(-1, 3)
        return [_ccw(self.vertices[t]) for t in tri]


def _ccw(v: np.ndarray) -> np.ndarray:
    x, y = v[:, 0], v[:, 1]
    signed = 0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    return v if signed > 0 else v[::-1].copy()


def polygon_centroid(vertices) -> np.ndarray:
    """Area centroid (2,) of a simple polygon's vertices (m)."""
    c = Polygon(np.asarray(vertices, dtype=np.float64)).centroid
    return np.array([c.x, c.y])


def about_centroid(vertices) -> list[list[float]]:
    """The polygon's vertices moved so that its area centroid is the origin (object frame)."""
    v = np.asarray(vertices, dtype=np.float64)
    return (v - polygon_centroid(v)).tolist()


def _centre(v: np.ndarray) -> np.ndarray:
    return v - polygon_centroid(v)


def _positive(field: str, value) -> float:
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ObjectSpecError(field, value, "must be a number") from None
    if not math.isfinite(x) or x <= 0:
        raise ObjectSpecError(field, value, "must be a positive finite number (metres)")
    return x


def polygon_footprint(vertices, field: str = "shape.vertices") -> Footprint:
    """Footprint from any simple polygon (list of (x, y) in metres, any orientation/offset)."""
    try:
        v = np.asarray(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ObjectSpecError(field, vertices, "must be a list of [x, y] pairs") from None
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3:
        raise ObjectSpecError(field, vertices, "needs at least 3 [x, y] vertices")
    if not np.all(np.isfinite(v)):
        raise ObjectSpecError(field, vertices, "vertices must be finite")
    poly = Polygon(v)
    if not poly.is_valid:
        raise ObjectSpecError(field, vertices, f"polygon is not simple ({explain_validity(poly)})")
    if poly.area < 1e-6:
        raise ObjectSpecError(field, vertices, f"polygon area {poly.area:.2e} m² is too small")
    return Footprint(_centre(_ccw(v)))


def ellipse_footprint(a: float, b: float) -> Footprint:
    a = _positive("shape.a", a)
    b = _positive("shape.b", b)
    t = np.linspace(0, 2 * np.pi, ELLIPSE_VERTICES, endpoint=False)
    # Scale radii so the polygon has the ellipse's area (keeps mass distribution honest).
    k = math.sqrt(2 * math.pi / (ELLIPSE_VERTICES * math.sin(2 * math.pi / ELLIPSE_VERTICES)))
    v = np.stack([k * a * np.cos(t), k * b * np.sin(t)], axis=1)
    return Footprint(v, kind="ellipse", ellipse_axes=(a, b))


def footprint_from_shape(shape: dict) -> Footprint:
    """Build a footprint from a shape description (see `CATALOGUE_SHAPES` for the types)."""
    if not isinstance(shape, dict) or "type" not in shape:
        raise ObjectSpecError("shape", shape, "must be a mapping with a 'type'")
    kind = shape["type"]
    if kind == "polygon":
        return polygon_footprint(shape.get("vertices"))
    if kind == "ellipse":
        return ellipse_footprint(shape.get("a"), shape.get("b"))
    if kind == "rectangle":
        w, h = (
            _positive("shape.width", shape.get("width")),
            _positive("shape.height", shape.get("height")),
        )
        return polygon_footprint(
            [[-w / 2, -h / 2], [w / 2, -h / 2], [w / 2, h / 2], [-w / 2, h / 2]]
        )
    if kind == "right_triangle":
        a, b = (
            _positive("shape.leg_x", shape.get("leg_x")),
            _positive("shape.leg_y", shape.get("leg_y")),
        )
        # Right angle at the +x/+y corner, legs along −x and −y (as MIT Push's triangles).
        return polygon_footprint([[0, 0], [-a, 0], [0, -b]])
    if kind == "hexagon":
        r = _positive("shape.circumradius", shape.get("circumradius"))
        t = np.arange(6) * np.pi / 3
        return polygon_footprint(np.stack([r * np.cos(t), r * np.sin(t)], 1))
    if kind == "rounded_rectangle":
        w, h = (
            _positive("shape.width", shape.get("width")),
            _positive("shape.height", shape.get("height")),
        )
        r = _positive("shape.radius", shape.get("radius"))
        if 2 * r >= min(w, h):
            raise ObjectSpecError(
                "shape.radius", r, f"must be below half the smaller side {min(w, h) / 2}"
            )
        pts = []
        for cx, cy, a0 in [
            (w / 2 - r, h / 2 - r, 0),
            (-w / 2 + r, h / 2 - r, 90),
            (-w / 2 + r, -h / 2 + r, 180),
            (w / 2 - r, -h / 2 + r, 270),
        ]:
            for a in np.radians(a0 + np.linspace(0, 90, 7)):
                pts.append([cx + r * np.cos(a), cy + r * np.sin(a)])
        return polygon_footprint(pts)
    raise ObjectSpecError(
        "shape.type",
        kind,
        "unknown shape; use polygon, ellipse, rectangle, right_triangle, hexagon, "
        "rounded_rectangle",
    )
