"""Objects of random shapes with continuous parameters (`testbed.random_shapes`, docs/DESIGN.md
§3): valid by the testbed's own checks, covering every family, seeded per object."""

import math
import re

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import LineString, Polygon

from pushtoknow.common.errors import ObjectSpecError
from pushtoknow.common.params import PARAM_RANGES
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import (
    MAX_RADIUS,
    MIN_GYRATION_RADIUS,
    MIN_WIDTH,
    ObjectSpec,
    check_polygon_frame,
    inertia_upper_bound,
    validate_catalogue_params,
    validate_footprint,
)
from pushtoknow.testbed.random_shapes import (
    FAMILIES,
    GYRATION_BAND,
    MAX_EXTENT,
    MIN_EXTENT,
    extent,
    gyration_radius,
    random_object,
    random_object_at,
    random_objects,
    width_and_length,
)

N = 300
SEED = 20250101


@pytest.fixture(scope="module")
def objects() -> list[ObjectSpec]:
    return random_objects(N, SEED)


def family(spec: ObjectSpec) -> str:
    return spec.name.rsplit(":", 1)[1]


def assert_valid(spec: ObjectSpec) -> None:
    """Every check the testbed makes, and the catalogue's stricter CoM rule, hold; the spec
    survives its own serialisation."""
    assert ObjectSpec.from_dict(spec.to_dict()) == spec
    fp, p = spec.footprint, spec.params
    validate_footprint(fp)
    validate_catalogue_params(p, fp)
    shape = spec.shape
    if shape["type"] == "polygon":
        check_polygon_frame(shape["vertices"])
        assert Polygon(shape["vertices"]).is_valid  # simple: no self-intersection
        assert 3 <= len(shape["vertices"]) <= 12
    else:
        assert shape["type"] == "ellipse"
    assert fp.max_radius_from((0.0, 0.0)) <= MAX_RADIUS
    assert width_and_length(fp.vertices)[0] >= MIN_WIDTH
    assert MIN_EXTENT - 1e-9 <= extent(fp.vertices) <= MAX_EXTENT + 1e-9
    for name in ("mass", "friction"):
        lo, hi = PARAM_RANGES[name]
        assert lo <= getattr(p, name) <= hi
    assert p.mass * MIN_GYRATION_RADIUS**2 <= p.inertia
    assert p.inertia <= inertia_upper_bound(p.mass, fp, (p.com_x, p.com_y))


def test_every_drawn_object_is_valid(objects):
    assert len(objects) == N
    for i, spec in enumerate(objects):
        assert re.fullmatch(rf"random:{SEED}:{i}:[a-z_]+", spec.name)
        assert family(spec) in FAMILIES
        assert_valid(spec)


def test_families_shapes_sizes_and_inertia_cover_the_intended_range(objects):
    families = [family(s) for s in objects]
    assert set(families) == set(FAMILIES)
    for f in FAMILIES:  # equal shares: 30 each expected among 300
        assert 12 <= families.count(f) <= 50, f
    nonconvex = [s for s in objects if not s.footprint.is_convex()]
    assert len(nonconvex) > N // 4
    for s in objects:
        if family(s) in ("nonconvex", "star", "t_shape", "l_shape"):
            assert not s.footprint.is_convex(), s.name
        if family(s) in ("convex", "bar", "kite", "obtuse_triangle", "octagon", "ellipse"):
            assert s.footprint.is_convex(), s.name
    aspects = [np.divide(*width_and_length(s.footprint.vertices)[::-1]) for s in objects]
    assert sum(a >= 4 for a in aspects) >= 10
    assert max(a for a, s in zip(aspects, objects) if family(s) == "bar") > 5
    sizes = [extent(s.footprint.vertices) for s in objects]
    assert min(sizes) < 0.06 and max(sizes) > 0.24
    obtuse = [s for s in objects if family(s) == "obtuse_triangle"]
    for s in obtuse:
        v = np.asarray(s.shape["vertices"])
        sides = sorted(np.linalg.norm(v - np.roll(v, 1, axis=0), axis=1))
        assert sides[2] ** 2 > sides[0] ** 2 + sides[1] ** 2  # an obtuse angle
    # I_z: m·k² with k within the sensible band of the uniform plate's radius of gyration, and
    # within the catalogue range for most objects.
    lo, hi = PARAM_RANGES["inertia"]
    in_range = 0
    for s in objects:
        p = s.params
        k = math.sqrt(p.inertia / p.mass) / gyration_radius(s.footprint.vertices)
        cap = math.sqrt(inertia_upper_bound(1.0, s.footprint, (p.com_x, p.com_y)))
        cap /= gyration_radius(s.footprint.vertices)
        assert GYRATION_BAND[0] - 1e-6 <= k <= min(GYRATION_BAND[1], cap) + 1e-6
        in_range += lo <= p.inertia <= hi
    assert in_range > N // 2
    # The CoM is anywhere in the footprint, not only in the catalogue's CoM box.
    assert max(math.hypot(s.params.com_x, s.params.com_y) for s in objects) > 0.05


def test_seeded_per_object_whatever_n(objects):
    again = random_objects(12, SEED)
    assert [s.to_dict() for s in again] == [s.to_dict() for s in objects[:12]]
    assert random_object_at(SEED, 7).to_dict() == objects[7].to_dict()
    assert load_object_spec(f"random:{SEED}:7") == objects[7]
    assert load_object_spec(objects[7].name).name == objects[7].name


def test_different_seeds_give_different_objects():
    a, b = random_objects(6, 1), random_objects(6, 2)
    assert all(x.to_dict() != y.to_dict() for x, y in zip(a, b))
    assert len({s.to_json() for s in a}) == 6


def test_random_object_from_any_generator():
    spec = random_object(np.random.default_rng(5))
    assert spec.name.startswith("random:") and spec.name.split(":")[1] in FAMILIES
    assert_valid(spec)
    assert random_object(np.random.default_rng(5)) == spec


@pytest.mark.parametrize(
    ("ref", "needle"),
    [
        ("random:x:1", "random:SEED:I"),
        ("random:1", "random:SEED:I"),
        ("random:-1:2", "random:SEED:I"),
        ("random:1:2:3:4", "random:SEED:I"),
        ("random:1:2:no_such_family", "that object is random:1:2:"),
    ],
)
def test_bad_random_references_are_refused(ref, needle):
    with pytest.raises(ObjectSpecError, match=re.escape(needle)):
        load_object_spec(ref)


@settings(max_examples=25, deadline=None)
@given(seed=st.integers(0, 2**63), index=st.integers(0, 10**9))
def test_any_seed_and_index_gives_a_valid_reproducible_object(seed, index):
    spec = random_object_at(seed, index)
    assert spec.name.startswith(f"random:{seed}:{index}:")
    assert_valid(spec)
    assert random_object_at(seed, index) == spec


def test_a_random_object_is_simulated():
    """One constant push on a non-convex random object: the pad meets it, pushes it and the
    record is finite."""
    from pushtoknow.testbed.push import Push
    from pushtoknow.testbed.sim import PushSimulator

    spec = next(s for s in random_objects(10, 3) if not s.footprint.is_convex())
    hit = spec.footprint.polygon.intersection(LineString([(-1.0, 0.0), (1.0, 0.0)]))
    contact = (float(hit.bounds[0]), 0.0)  # where the +x push line through the centroid enters
    sim = PushSimulator(spec)
    try:
        sim.reset((0.0, 0.0, 0.0))
        rec = sim.execute(
            Push(contact, 0.0, "constant", 0.02), np.random.default_rng(0), render=False
        )
    finally:
        sim.close()
    assert np.isfinite(rec.pose).all() and np.isfinite(rec.force_clean).all()
    assert rec.tactile[:, 2].mean() > 0.5  # in contact for most of the push
    assert rec.pose[-1, 0] - rec.pose[0, 0] > 0.02
    p = spec.params
    force = np.linalg.norm(rec.force_clean, axis=1)
    assert force.max() < 3 * p.friction * p.mass * 9.81  # no blow-up


def test_uniform_plate_radius_of_gyration():
    square = [[0, 0], [2, 0], [2, 2], [0, 2]]  # about its centre: (a² + a²)/12 with a = 2
    assert gyration_radius(square) == pytest.approx(math.sqrt(8 / 12))
    assert gyration_radius(np.asarray(square)[::-1] + 5.0) == pytest.approx(math.sqrt(8 / 12))
    bar = [[0, 0], [6, 0], [6, 1], [0, 1]]
    assert gyration_radius(bar) == pytest.approx(math.sqrt(37 / 12))
    assert extent(bar) == pytest.approx(math.sqrt(37))
    assert width_and_length(bar) == pytest.approx((1.0, 6.0))
