"""Object specifications, validation, the 825-object catalogue and the continuous sampler.

An object is an extruded footprint (see `shapes`) with parameters φ = (m, μ, c_x, c_y, I_z) in SI.
Specs are read from JSON/YAML:

    name: my_box            # optional
    shape: {type: rectangle, width: 0.09, height: 0.09}   # or a catalogue shape name: "rect1"
    mass: 0.5               # kg
    friction: 0.5           # object–table Coulomb coefficient
    com: [0.01, -0.005]     # m, object frame (origin at the footprint centroid)
    inertia: 0.9e-3         # kg·m² about the vertical axis through the CoM

Catalogue objects are addressable as ``catalogue:ID`` (ID in 0..824), random-shape objects
(`random_shapes`) as ``random:SEED:I``; `object_refs.load_object_spec` resolves both.

The vertices of a `polygon` shape are given in the object frame too, about their area centroid:
an off-centroid polygon is refused with its offset, since moving it silently would leave the
CoM in another frame. What the testbed simulates faithfully (docs/DESIGN.md §3) bounds a spec:
mass ≤ `MAX_MASS`, footprint width ≥ `MIN_WIDTH` and radius ≤ `MAX_RADIUS`, height ≥
`MIN_HEIGHT` and ≤ `MAX_HEIGHT`, the CoM inside the footprint's convex hull (`COM_MARGIN`), I_z
between m·`MIN_GYRATION_RADIUS`² and what the footprint allows.
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np
from shapely.geometry import Point

from pushtoknow.common.errors import ObjectSpecError
from pushtoknow.common.params import CATALOGUE_GRID, PARAM_RANGES, ObjectParams
from pushtoknow.testbed.shapes import (
    CATALOGUE_SHAPES,
    Footprint,
    about_centroid,
    footprint_from_shape,
    polygon_centroid,
)
from pushtoknow.testbed.sim_config import CameraConfig, PadConfig

DEFAULT_HEIGHT = 0.013  # m, extrusion height (the MIT Push objects are 13 mm thick)
# m: the CoM lies at least this far inside the footprint's convex hull. Any mass distribution
# over the footprint has its CoM in that hull (a non-convex footprint's notch included); the
# testbed's supports sit 2 mm inside the outline (SupportConfig.edge_margin) and carry any CoM
# 3 mm inside the hull with positive loads.
COM_MARGIN = 0.003
CATALOGUE_COM_MARGIN = 0.005  # m: catalogue and sampled objects keep the CoM this far inside
# the footprint itself (the catalogue's rule, stricter than physics)
POLYGON_CENTROID_TOLERANCE = 1e-6  # m: a polygon's centroid may sit this far from the origin
_VIEW_HALF_WIDTH = CameraConfig().distance * math.tan(math.radians(CameraConfig().fovy_deg) / 2)
MAX_RADIUS = 0.2  # m, centroid to the farthest footprint point: the object and a 0.1 m push
# stay inside the camera's view (±0.31 m on the table)
MIN_WIDTH = 0.03  # m, the footprint's smallest width: narrower objects span under 3 pixels of
# the 64-pixel camera (9.7 mm per pixel), too few for a footprint from S_0
MIN_HEIGHT = PadConfig().z + PadConfig().half_height  # m: lower objects pass under the pad's top
MAX_HEIGHT = 0.15  # m: a pushed object this tall would tip in reality (the testbed's cannot)
MIN_GYRATION_RADIUS = 0.003  # m: I_z ≥ m·(3 mm)². Measured: at 0.45 mm (rect1, 0.5 kg) the
# simulation breaks down (0.36 N of force against μ·m·g = 2.45 N) and at 0.18 mm (30 kg) the
# object slides away at 26 N of 589 N; from 1.4 mm up the force is right
FRICTION_LIMIT = 2.0  # the largest plausible Coulomb coefficient the testbed simulates
MAX_MASS = 30.0  # kg: heavier objects are not simulated faithfully. Measured on rect1 at μ = 0.5
# and 20 mm/s: the pad sinks 0.16 mm into 30 kg (below the 0.5 mm pose noise), 0.5 mm into
# 100 kg and 4.9 mm into 1000 kg, and it passes through 10⁶ kg
CATALOGUE_SEED = 20240925
CATALOGUE_PER_SHAPE = 75


@dataclass(frozen=True)
class ObjectSpec:
    """A pushable object: footprint, parameters and extrusion height (all SI)."""

    shape: dict
    params: ObjectParams
    height: float = DEFAULT_HEIGHT
    name: str = "object"
    footprint: Footprint = field(init=False, repr=False, compare=False)

    def __post_init__(self):
        shape = resolve_shape(self.shape)
        fp = footprint_from_shape(shape)
        if shape.get("type") == "polygon":
            check_polygon_frame(shape["vertices"])
        validate_footprint(fp)
        object.__setattr__(self, "footprint", fp)
        validate_params(self.params, fp, self.height)

    def to_dict(self) -> dict:
        p = self.params
        return {
            "name": self.name,
            "shape": self.shape,
            "mass": p.mass,
            "friction": p.friction,
            "com": [p.com_x, p.com_y],
            "inertia": p.inertia,
            "height": self.height,
        }

    def to_json(self) -> str:
        return json.dumps(self.to_dict())

    @classmethod
    def from_dict(cls, d: dict, stored: bool = False) -> ObjectSpec:
        """A spec from its mapping (module docstring). `stored`: read from a dataset, where an
        older writer may have kept a polygon off its centroid (`recentred_legacy_shape`)."""
        if not isinstance(d, dict):
            raise ObjectSpecError("<root>", d, "an object spec must be a mapping")
        unknown = set(d) - {"name", "shape", "mass", "friction", "com", "inertia", "height"}
        if unknown:
            raise ObjectSpecError(sorted(unknown)[0], d[sorted(unknown)[0]], "unknown field")
        for key in ("shape", "mass", "friction", "com", "inertia"):
            if key not in d:
                raise ObjectSpecError(key, None, "missing")
        com = d["com"]
        if not isinstance(com, (list, tuple)) or len(com) != 2:
            raise ObjectSpecError("com", com, "must be [c_x, c_y] in metres")
        params = ObjectParams(
            mass=_number("mass", d["mass"]),
            friction=_number("friction", d["friction"]),
            com_x=_number("com[0]", com[0]),
            com_y=_number("com[1]", com[1]),
            inertia=_number("inertia", d["inertia"]),
        )
        return cls(
            shape=recentred_legacy_shape(d["shape"]) if stored else d["shape"],
            params=params,
            height=_number("height", d.get("height", DEFAULT_HEIGHT)),
            name=str(d.get("name", "object")),
        )


def _number(field_name: str, value) -> float:
    if isinstance(value, bool):
        raise ObjectSpecError(field_name, value, "must be a number")
    try:
        x = float(value)
    except (TypeError, ValueError):
        raise ObjectSpecError(field_name, value, "must be a number") from None
    if not math.isfinite(x):
        raise ObjectSpecError(field_name, value, "must be finite")
    return x


def resolve_shape(shape) -> dict:
    """A shape dict, or a catalogue shape name such as "rect1" → a shape dict."""
    if isinstance(shape, str):
        if shape not in CATALOGUE_SHAPES:
            raise ObjectSpecError(
                "shape", shape, f"unknown shape; catalogue shapes are {sorted(CATALOGUE_SHAPES)}"
            )
        return CATALOGUE_SHAPES[shape]
    return shape


def check_polygon_frame(vertices) -> None:
    """Refuse polygon vertices whose area centroid is not the object frame's origin (the CoM is
    given in that frame, so the polygon must be too)."""
    offset = polygon_centroid(vertices)
    if np.hypot(*offset) > POLYGON_CENTROID_TOLERANCE:
        x, y = 1e3 * offset
        raise ObjectSpecError(
            "shape.vertices",
            f"centroid at ({x:.3f}, {y:.3f}) mm",
            "the object frame has its origin at the footprint's centroid: give the vertices "
            f"and the com about it (subtract ({x:.3f}, {y:.3f}) mm from both)",
        )


def recentred_legacy_shape(shape):
    """A stored spec's polygon moved about its centroid. Datasets written before polygons had
    to be given about their centroid kept such vertices with the CoM already in the centroid
    frame, so only the vertices move."""
    if isinstance(shape, dict) and shape.get("type") == "polygon":
        try:
            return {**shape, "vertices": about_centroid(shape["vertices"])}
        except (TypeError, ValueError):
            return shape  # refused with its reason by ObjectSpec
    return shape


def narrowest_side(fp: Footprint) -> np.ndarray:
    """The short side (2,) (m, object frame) of the footprint's minimum-area rotated rectangle:
    its length is the width `validate_footprint` checks."""
    xy = np.asarray(fp.polygon.minimum_rotated_rectangle.exterior.coords)[:3]
    return min((xy[1] - xy[0], xy[2] - xy[1]), key=lambda side: float(np.linalg.norm(side)))


def validate_footprint(fp: Footprint) -> None:
    """Refuse footprints the testbed cannot simulate faithfully (size bounds, see the module
    docstring), naming the bound."""
    radius = fp.max_radius_from((0.0, 0.0))
    if radius > MAX_RADIUS:
        raise ObjectSpecError(
            "shape",
            f"radius {radius:.3f} m",
            f"too large: beyond {MAX_RADIUS} m from its centroid the object leaves the camera's "
            f"view (±{_VIEW_HALF_WIDTH:.2f} m) while pushed",
        )
    width = float(np.linalg.norm(narrowest_side(fp)))
    if width < MIN_WIDTH:
        raise ObjectSpecError(
            "shape",
            f"width {width:.4f} m",
            f"too small: narrower than {MIN_WIDTH} m the object spans under 3 camera pixels",
        )


def inertia_upper_bound(mass: float, footprint: Footprint, com) -> float:
    """Largest I_z any mass distribution inside the footprint with this CoM can have (kg·m²).

    All mass at the farthest footprint point gives I_z ≤ m · max‖p − c‖²; larger values
    are physically impossible for a rigid body of this footprint.
    """
    return mass * footprint.max_radius_from(com) ** 2


def validate_params(p: ObjectParams, footprint: Footprint, height: float = DEFAULT_HEIGHT) -> None:
    """Raise ObjectSpecError naming the field and value of the first invalid parameter."""
    for name, value in (
        ("mass", p.mass),
        ("friction", p.friction),
        ("inertia", p.inertia),
        ("height", height),
    ):
        if not (math.isfinite(value) and value > 0):
            raise ObjectSpecError(name, value, "must be positive")
    if p.mass > MAX_MASS:
        raise ObjectSpecError(
            "mass",
            p.mass,
            f"above the {MAX_MASS:g} kg the testbed simulates faithfully (heavier objects let "
            "the pad sink into them)",
        )
    if p.friction > FRICTION_LIMIT:
        raise ObjectSpecError(
            "friction", p.friction, f"implausible Coulomb coefficient (> {FRICTION_LIMIT:g})"
        )
    if height < MIN_HEIGHT:
        raise ObjectSpecError(
            "height", height, f"below {MIN_HEIGHT:.4f} m the pad passes over the object"
        )
    if height > MAX_HEIGHT:
        raise ObjectSpecError(
            "height", height, f"above {MAX_HEIGHT} m a pushed object tips (the testbed's cannot)"
        )
    if p.inertia < p.mass * MIN_GYRATION_RADIUS**2:
        raise ObjectSpecError(
            "inertia",
            p.inertia,
            f"below m·({MIN_GYRATION_RADIUS * 1e3:g} mm)² = {p.mass * MIN_GYRATION_RADIUS**2:.2e} "
            "kg·m² (all the mass within 3 mm of the CoM), where the simulation breaks down",
        )
    com = (p.com_x, p.com_y)
    if not footprint.com_region(COM_MARGIN).contains(Point(*com)):
        raise ObjectSpecError(
            "com",
            list(com),
            "no mass distribution over this footprint has its centre of mass there (it must "
            f"lie inside the footprint's convex hull, {COM_MARGIN * 1e3:g} mm from its edge)",
        )
    bound = inertia_upper_bound(p.mass, footprint, com)
    if p.inertia > bound:
        raise ObjectSpecError(
            "inertia",
            p.inertia,
            f"exceeds the largest inertia {bound:.3e} kg·m² possible for mass {p.mass} kg "
            "inside this footprint",
        )


def validate_catalogue_params(p: ObjectParams, footprint: Footprint) -> None:
    """`validate_params` and the catalogue's own rule: the CoM at least `CATALOGUE_COM_MARGIN`
    inside the footprint (catalogue and sampled objects)."""
    validate_params(p, footprint)
    if not footprint.contains((p.com_x, p.com_y), margin=CATALOGUE_COM_MARGIN):
        raise ObjectSpecError(
            "com", [p.com_x, p.com_y], f"not {CATALOGUE_COM_MARGIN} m inside the footprint"
        )


@dataclass(frozen=True)
class Catalogue:
    objects: tuple[ObjectSpec, ...]
    rejected: int  # grid combinations drawn and rejected as physically invalid
    seed: int


@lru_cache(maxsize=4)
def build_catalogue(seed: int = CATALOGUE_SEED, per_shape: int = CATALOGUE_PER_SHAPE) -> Catalogue:
    """The paper's catalogue: for each of the 11 shapes, `per_shape` parameter combinations of
    the Table I grid drawn without replacement (seeded); invalid combinations are rejected,
    counted, and replaced by further draws. IDs run shape by shape in `CATALOGUE_SHAPES` order."""
    rng = np.random.default_rng(seed)
    grid = [CATALOGUE_GRID[k] for k in ("mass", "friction", "com_x", "com_y", "inertia")]
    combos = np.array(np.meshgrid(*grid, indexing="ij")).reshape(5, -1).T
    objects, rejected = [], 0
    for shape_name in CATALOGUE_SHAPES:
        fp = footprint_from_shape(CATALOGUE_SHAPES[shape_name])
        order = rng.permutation(len(combos))
        chosen = 0
        for i in order:
            p = ObjectParams.from_array(combos[i])
            try:
                validate_catalogue_params(p, fp)
            except ObjectSpecError:
                rejected += 1
                continue
            objects.append(ObjectSpec(shape=shape_name, params=p, name=f"catalogue:{len(objects)}"))
            chosen += 1
            if chosen == per_shape:
                break
        if chosen < per_shape:
            raise RuntimeError(f"only {chosen} valid combinations for {shape_name}")
    return Catalogue(tuple(objects), rejected, seed)


CATALOGUE_TEST_PER_SHAPE = 8  # held-out objects per shape (≈ 10%; 88 of 825)


@lru_cache(maxsize=1)
def catalogue_split() -> tuple[tuple[int, ...], tuple[int, ...]]:
    """The fixed train/test split of the catalogue by object: (train IDs, test IDs), stratified
    by shape (`CATALOGUE_TEST_PER_SHAPE` test objects of each shape), seeded. Training data come
    from the train IDs, accuracy is measured on the test IDs, and the demo uses a test object."""
    cat = build_catalogue()
    rng = np.random.default_rng(CATALOGUE_SEED + 1)
    test: list[int] = []
    for shape_name in CATALOGUE_SHAPES:
        ids = [i for i, o in enumerate(cat.objects) if o.shape == shape_name]
        test += sorted(rng.choice(ids, CATALOGUE_TEST_PER_SHAPE, replace=False).tolist())
    test_set = set(test)
    train = tuple(i for i in range(len(cat.objects)) if i not in test_set)
    return train, tuple(sorted(test))


DEMO_SHAPE = "rect2"


def demo_object_id() -> int:
    """The demo's object: the held-out (`catalogue_split` test) `DEMO_SHAPE` object whose CoM
    lies farthest from the centre, so that its pushes rotate it visibly."""
    cat = build_catalogue()
    test = [i for i in catalogue_split()[1] if cat.objects[i].shape == DEMO_SHAPE]
    return max(
        test, key=lambda i: math.hypot(cat.objects[i].params.com_x, cat.objects[i].params.com_y)
    )


def catalogue_object(idx: int) -> ObjectSpec:
    cat = build_catalogue()
    if not 0 <= idx < len(cat.objects):
        raise ObjectSpecError("catalogue id", idx, f"must be in 0..{len(cat.objects) - 1}")
    return cat.objects[idx]


# Shapes no training object has (the "novel shapes" of docs/DESIGN.md §9), sizes like the
# catalogue's.
NOVEL_SHAPES: dict[str, dict] = {
    "pentagon": {
        "type": "polygon",
        "vertices": [
            [0.058 * math.cos(2 * math.pi * k / 5), 0.058 * math.sin(2 * math.pi * k / 5)]
            for k in range(5)
        ],
    },
    "trapezoid": {
        "type": "polygon",
        "vertices": about_centroid(
            [[-0.065, -0.045], [0.065, -0.045], [0.035, 0.045], [-0.035, 0.045]]
        ),
    },
    "ellip4": {"type": "ellipse", "a": 0.045, "b": 0.09},
    "l_shape": {  # non-convex: decomposed into convex pieces for collision
        "type": "polygon",
        "vertices": about_centroid(
            [
                [-0.055, -0.055],
                [0.055, -0.055],
                [0.055, -0.005],
                [-0.005, -0.005],
                [-0.005, 0.055],
                [-0.055, 0.055],
            ]
        ),
    },
}


def sample_continuous_object(
    rng: np.random.Generator, shapes=None, max_tries: int = 1000
) -> ObjectSpec:
    """A novel object: a shape (default: a catalogue shape; `shapes` may name catalogue or
    `NOVEL_SHAPES` ones) with parameters drawn uniformly within the catalogue ranges
    (rejection-sampled for physical validity)."""
    names = list(shapes or CATALOGUE_SHAPES)
    shape = names[int(rng.integers(len(names)))]
    if shape not in CATALOGUE_SHAPES and shape not in NOVEL_SHAPES:
        raise ObjectSpecError("shape", shape, "not a catalogue or novel shape name")
    shape_dict = CATALOGUE_SHAPES.get(shape) or NOVEL_SHAPES[shape]
    fp = footprint_from_shape(shape_dict)
    for _ in range(max_tries):
        vals = [
            rng.uniform(*PARAM_RANGES[k]) for k in ("mass", "friction", "com_x", "com_y", "inertia")
        ]
        p = ObjectParams(*vals)
        try:
            validate_catalogue_params(p, fp)
        except ObjectSpecError:
            continue
        spec_shape = shape if shape in CATALOGUE_SHAPES else shape_dict
        return ObjectSpec(shape=spec_shape, params=p, name=f"continuous:{shape}")
    raise RuntimeError(f"no valid continuous parameters for {shape} in {max_tries} tries")


def novel_objects(n: int, seed: int = 0) -> list[ObjectSpec]:
    """n novel objects (docs/DESIGN.md §9): alternately an unseen shape (`NOVEL_SHAPES`) and a
    catalogue shape, both with continuous parameters within the catalogue ranges; seeded."""
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        pool = list(NOVEL_SHAPES) if i % 2 == 0 else list(CATALOGUE_SHAPES)
        spec = sample_continuous_object(rng, pool)
        out.append(dataclasses.replace(spec, name=f"novel:{i}:{spec.name.split(':', 1)[1]}"))
    return out
