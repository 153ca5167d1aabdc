"""Object specs, validation errors, catalogue and continuous sampler."""

import json

import numpy as np
import pytest

from pushtoknow.common.errors import ObjectSpecError
from pushtoknow.common.params import CATALOGUE_GRID, PARAM_RANGES
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import (
    ObjectSpec,
    build_catalogue,
    inertia_upper_bound,
    novel_objects,
    sample_continuous_object,
)
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, about_centroid, footprint_from_shape

GOOD = {"shape": "rect1", "mass": 0.5, "friction": 0.5, "com": [0.0, 0.01], "inertia": 0.5e-3}


def spec(**kw):
    return ObjectSpec.from_dict({**GOOD, **kw})


@pytest.mark.parametrize(
    ("override", "field", "value"),
    [
        ({"mass": -0.1}, "mass", -0.1),
        ({"mass": 0}, "mass", 0),
        ({"mass": 1e6, "inertia": 1.0}, "mass", 1e6),  # the pad would pass through it
        ({"friction": 0.0}, "friction", 0.0),
        ({"inertia": -1e-3}, "inertia", -1e-3),
        ({"com": [0.2, 0.0]}, "com", [0.2, 0.0]),
        ({"shape": "banana"}, "shape", "banana"),
        (
            {"shape": {"type": "polygon", "vertices": [[0, 0], [0.1, 0.1], [0.1, 0], [0, 0.1]]}},
            "shape.vertices",
            None,
        ),
        ({"shape": {"type": "ellipse", "a": 0.05, "b": -1}}, "shape.b", -1),
        ({"shape": {"type": "star"}}, "shape.type", "star"),
        ({"mass": "heavy"}, "mass", "heavy"),
        ({"inertia": 1.0}, "inertia", 1.0),
    ],
)
def test_invalid_spec_names_field_and_value(override, field, value):
    with pytest.raises(ObjectSpecError) as e:
        spec(**override)
    assert e.value.field == field
    assert field in str(e.value)
    if value is not None:
        assert repr(value) in str(e.value)


def test_self_intersecting_polygon_message():
    bowtie = {"type": "polygon", "vertices": [[0, 0], [0.1, 0.1], [0.1, 0], [0, 0.1]]}
    with pytest.raises(ObjectSpecError, match="not simple"):
        spec(shape=bowtie)


def test_missing_and_unknown_fields():
    d = dict(GOOD)
    del d["mass"]
    with pytest.raises(ObjectSpecError, match="mass"):
        ObjectSpec.from_dict(d)
    with pytest.raises(ObjectSpecError, match="colour"):
        ObjectSpec.from_dict({**GOOD, "colour": "red"})


L_CORNER = [[0, 0], [0.1, 0], [0.1, 0.05], [0.05, 0.05], [0.05, 0.1], [0, 0.1]]


def test_non_convex_polygon_is_decomposed_into_convex_pieces():
    L = {"type": "polygon", "vertices": about_centroid(L_CORNER)}
    s = spec(shape=L, com=[0.0, 0.0], inertia=0.3e-3)
    pieces = s.footprint.convex_pieces()
    assert len(pieces) > 1
    from shapely.geometry import Polygon

    assert sum(Polygon(p).area for p in pieces) == pytest.approx(s.footprint.area, rel=1e-9)
    assert all(Polygon(p).convex_hull.area == pytest.approx(Polygon(p).area) for p in pieces)
    # Footprints are centred on their centroid.
    c = s.footprint.polygon.centroid
    assert abs(c.x) < 1e-12 and abs(c.y) < 1e-12


def test_catalogue_shapes_have_spec_dimensions():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect3"])
    minx, miny, maxx, maxy = fp.polygon.bounds
    assert maxx - minx == pytest.approx(0.1350) and maxy - miny == pytest.approx(0.0899)
    tri = footprint_from_shape(CATALOGUE_SHAPES["tri1"])
    assert tri.area == pytest.approx(0.5 * 0.1259**2)
    ell = footprint_from_shape(CATALOGUE_SHAPES["ellip2"])
    assert ell.area == pytest.approx(np.pi * 0.0525 * 0.0654, rel=1e-3)


def test_catalogue_is_825_valid_seeded_objects():
    cat = build_catalogue()
    assert len(cat.objects) == 825
    assert cat.rejected > 0  # some grid combinations are physically impossible
    assert len({(o.shape, tuple(o.params.as_array())) for o in cat.objects}) == 825
    for name in CATALOGUE_SHAPES:
        assert sum(o.shape == name for o in cat.objects) == 75
    for o in cat.objects:
        for k, v in o.params.to_dict().items():
            assert any(np.isclose(v, g) for g in CATALOGUE_GRID[k])
    again = build_catalogue.__wrapped__()
    assert [o.params for o in again.objects] == [o.params for o in cat.objects]


def test_catalogue_and_novel_objects_are_pinned():
    """The catalogue and the novel objects are the ones every model was trained and evaluated
    on: a change of the validity rules must not change them."""
    import hashlib

    def digest(objects):
        a = np.array([o.params.as_array() for o in objects])
        return hashlib.sha256(a.tobytes()).hexdigest()[:16]

    cat = build_catalogue()
    assert (digest(cat.objects), cat.rejected) == ("29adb4a96efc611b", 30)
    assert digest(novel_objects(40, 0)) == "1b9cbcbb9939dd95"


def test_off_centroid_polygon_is_refused_with_its_offset():
    with pytest.raises(ObjectSpecError, match=r"centroid at \(33\.333, 33\.333\) mm") as e:
        spec(shape={"type": "polygon", "vertices": [[0, 0], [0.1, 0], [0, 0.1]]}, com=[0, 0])
    assert e.value.field == "shape.vertices"
    centred = about_centroid([[0, 0], [0.1, 0], [0, 0.1]])
    assert spec(shape={"type": "polygon", "vertices": centred}, com=[0, 0], inertia=1e-4)


def test_stored_legacy_polygon_keeps_its_centroid_frame_com():
    """Datasets written before the frame rule kept off-centroid vertices with the CoM already
    in the centroid frame: read back, the footprint is centred and the CoM is unchanged."""
    d = {**GOOD, "shape": {"type": "polygon", "vertices": L_CORNER}, "com": [0.004, -0.003]}
    d["inertia"] = 0.3e-3
    s = ObjectSpec.from_dict(d, stored=True)
    assert (s.params.com_x, s.params.com_y) == (0.004, -0.003)
    c = s.footprint.polygon.centroid
    assert abs(c.x) < 1e-12 and abs(c.y) < 1e-12
    with pytest.raises(ObjectSpecError, match="centroid at"):
        ObjectSpec.from_dict(d)


def test_com_rule_follows_physics_for_non_convex_footprints():
    """Any mass distribution over a footprint has its CoM in the footprint's convex hull: an
    L's notch is allowed (mass in both arms), a point beyond the hull is not, and the CoM may
    come closer to an edge than the catalogue's 5 mm."""
    from shapely.geometry import Polygon

    L = {"type": "polygon", "vertices": about_centroid(L_CORNER)}
    c = Polygon(L_CORNER).centroid
    notch = [0.065 - c.x, 0.065 - c.y]  # in the notch, 14 mm inside the hull's diagonal
    s = spec(shape=L, com=notch, inertia=0.3e-3)
    assert not s.footprint.contains(notch)
    with pytest.raises(ObjectSpecError, match="convex hull") as e:
        spec(shape=L, com=[0.09 - c.x, 0.09 - c.y], inertia=0.3e-3)
    assert e.value.field == "com"
    assert spec(com=[0.0415, 0.0])  # 3.5 mm from rect1's edge


@pytest.mark.parametrize(
    ("override", "needle"),
    [
        ({"shape": {"type": "rectangle", "width": 4.0, "height": 4.0}}, "radius 2.828 m"),
        ({"shape": {"type": "rectangle", "width": 0.02, "height": 0.09}}, "width 0.0200 m"),
        ({"height": 0.005}, "height=0.005"),
        ({"height": 1000.0}, "height=1000.0"),
        ({"inertia": 1e-12, "shape": "rect1"}, "inertia=1e-12"),
    ],
)
def test_objects_the_testbed_cannot_simulate_are_refused(override, needle):
    with pytest.raises(ObjectSpecError, match=needle.replace(".", r"\.")):
        spec(**{"com": [0.0, 0.0], "inertia": 1e-4, **override})


def test_catalogue_rejections_are_physical():
    # 0.2 kg rect1 cannot have I_z = 1.5 g·m²: all mass at the corners gives only 0.81.
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])
    assert inertia_upper_bound(0.2, fp, (0, 0)) == pytest.approx(0.2 * 2 * 0.045**2)


def test_catalogue_address_and_files(tmp_path):
    assert load_object_spec("catalogue:10") == build_catalogue().objects[10]
    with pytest.raises(ObjectSpecError, match="catalogue id"):
        load_object_spec("catalogue:9999")
    p = tmp_path / "obj.yaml"
    p.write_text(
        "shape: {type: ellipse, a: 0.05, b: 0.04}\nmass: 0.4\nfriction: 0.6\n"
        "com: [0.005, 0]\ninertia: 0.4e-3\n"
    )
    s = load_object_spec(p)
    assert s.footprint.kind == "ellipse" and s.params.friction == 0.6
    j = tmp_path / "obj.json"
    j.write_text(json.dumps(GOOD))
    assert load_object_spec(j).params.mass == 0.5
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    with pytest.raises(ObjectSpecError, match="bad.json"):
        load_object_spec(bad)


def test_continuous_sampler_is_seeded_and_in_range():
    a = [sample_continuous_object(np.random.default_rng([5, i])) for i in range(20)]
    b = [sample_continuous_object(np.random.default_rng([5, i])) for i in range(20)]
    assert [x.params for x in a] == [x.params for x in b]
    for o in a:
        for k, v in o.params.to_dict().items():
            lo, hi = PARAM_RANGES[k]
            assert lo <= v <= hi
    # Not on the grid: continuous values.
    assert not all(np.isclose(a[0].params.mass, g) for g in CATALOGUE_GRID["mass"])


@pytest.mark.parametrize("name", [n for n in CATALOGUE_SHAPES if n != "butter"])
def test_catalogue_shapes_match_mit_push_frames(name):
    # Same footprint and frame as the real objects (MIT Push reader), so parameters mean the
    # same in simulation and on real data. butter differs on purpose: docs/DESIGN.md §3 uses a
    # convex approximation; the real outline is non-convex.
    from shapely.geometry import Polygon

    from pushtoknow.datasets.mit_push import mit_polygon

    a = Polygon(mit_polygon(name))
    b = footprint_from_shape(CATALOGUE_SHAPES[name]).polygon
    assert a.intersection(b).area / a.union(b).area > 0.99


def test_novel_objects_are_valid_seeded_and_partly_unseen():
    from pushtoknow.testbed.objects import NOVEL_SHAPES, novel_objects

    a, b = novel_objects(6, seed=4), novel_objects(6, seed=4)
    assert [o.to_dict() for o in a] == [o.to_dict() for o in b]
    unseen = [o for o in a if isinstance(o.shape, dict)]
    assert len(unseen) == 3 and all(o.name.split(":")[2] in NOVEL_SHAPES for o in unseen)
    for o in a:  # continuous parameters, round-trip through JSON like the evaluation does
        assert load_object_spec(o.to_json()).to_dict() == o.to_dict()
        assert o.params.mass not in (0.2, 0.5, 0.8, 1.2)


def test_a_file_that_is_not_an_object_spec_is_refused_in_one_short_line(tmp_path):
    """A text file that parses as YAML but holds no mapping (any text file does) is named with
    what it holds, and the message never carries the whole file."""
    path = tmp_path / "notes.txt"
    path.write_text("a line of notes " * 500, encoding="utf-8")
    with pytest.raises(ObjectSpecError) as e:
        load_object_spec(path)
    message = str(e.value)
    assert str(path) in message and "holds a str, not a mapping" in message
    assert "\n" not in message and len(message) < 200 + len(str(path))


def test_a_long_value_is_cut_short_in_the_message_a_long_path_is_not(tmp_path):
    with pytest.raises(ObjectSpecError) as e:
        ObjectSpec.from_dict(["x" * 10_000])
    assert len(str(e.value)) < 400 and "…" in str(e.value)
    deep = tmp_path.joinpath(*["a-long-folder-name"] * 8, "spec.yaml")
    with pytest.raises(ObjectSpecError) as e:
        load_object_spec(deep)
    assert str(deep) in str(e.value)
