"""Object specifications, validation, the 825-object catalogue and the continuous sampler.

An object is an extruded footprint (see `shapes`) with parameters φ = (m, μ, c_x, c_y, I_z) in SI.
Specs are read from JSON/YAML:

    name: my_box            # optional
    shape: {type: rectangle, width: 0.09, height: 0.09}   # or a catalogue shape name: "rect1"
    mass: 0.5               # kg
    friction: 0.5           # object–table Coulomb coefficient
    com: [0.01, -0.005]     # m, object frame (origin at the footprint centroid)
    inertia: 0.9e-3         # kg·m² about the vertical axis through the CoM

Catalogue objects are addressable as ``catalogue:ID`` (ID in 0..824).
"""

from __future__ import annotations

import dataclasses
import json
import math
from dataclasses import dataclass, field
from functools import lru_cache
from pathlib import Path

import numpy as np
import yaml

from pushtoknow.common.errors import ObjectSpecError
from pushtoknow.common.params import CATALOGUE_GRID, PARAM_RANGES, ObjectParams
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, Footprint, footprint_from_shape

DEFAULT_HEIGHT = 0.013  # m, extrusion height (the MIT Push objects are 13 mm thick)
COM_MARGIN = 0.005  # m, the CoM must lie at least this far inside the footprint
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
        fp = footprint_from_shape(resolve_shape(self.shape))
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
    def from_dict(cls, d: dict) -> ObjectSpec:
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
            shape=d["shape"],
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
    if p.friction > 2.0:
        raise ObjectSpecError("friction", p.friction, "implausible Coulomb coefficient (> 2)")
    com = (p.com_x, p.com_y)
    if not footprint.contains(com, margin=COM_MARGIN):
        raise ObjectSpecError(
            "com",
            list(com),
            f"centre of mass must lie inside the footprint (margin {COM_MARGIN} m)",
        )
    bound = inertia_upper_bound(p.mass, footprint, com)
    if p.inertia > bound:
        raise ObjectSpecError(
            "inertia",
            p.inertia,
            f"exceeds the largest inertia {bound:.3e} kg·m² possible for mass {p.mass} kg "
            "inside this footprint",
        )


def load_object_spec(source: str | Path) -> ObjectSpec:
    """Object from ``catalogue:ID``, a JSON/YAML file path, or an inline JSON string."""
    s = str(source)
    if s.startswith("catalogue:"):
        key = s.split(":", 1)[1]
        try:
            idx = int(key)
        except ValueError:
            raise ObjectSpecError("catalogue id", key, "must be an integer 0..824") from None
        return catalogue_object(idx)
    if s.lstrip().startswith("{"):
        try:
            return ObjectSpec.from_dict(json.loads(s))
        except json.JSONDecodeError as e:
            raise ObjectSpecError("<inline json>", s[:60], f"not valid JSON: {e}") from None
    path = Path(s)
    if not path.exists():
        raise ObjectSpecError("<file>", s, "no such file (and not of the form catalogue:ID)")
    try:
        data = yaml.safe_load(path.read_text())  # YAML is a superset of JSON
    except yaml.YAMLError as e:
        raise ObjectSpecError("<file>", s, f"not valid JSON/YAML: {e}") from None
    return ObjectSpec.from_dict(data)


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
                validate_params(p, fp)
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
        "vertices": [[-0.065, -0.045], [0.065, -0.045], [0.035, 0.045], [-0.035, 0.045]],
    },
    "ellip4": {"type": "ellipse", "a": 0.045, "b": 0.09},
    "l_shape": {  # non-convex: decomposed into convex pieces for collision
        "type": "polygon",
        "vertices": [
            [-0.055, -0.055],
            [0.055, -0.055],
            [0.055, -0.005],
            [-0.005, -0.005],
            [-0.005, 0.055],
            [-0.055, 0.055],
        ],
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
            validate_params(p, fp)
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
