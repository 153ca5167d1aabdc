"""Support points and the loads that put the centre of pressure under the CoM."""

import numpy as np
import pytest
from hypothesis import example, given, settings
from hypothesis import strategies as st

from pushtoknow.testbed.objects import COM_MARGIN, NOVEL_SHAPES
from pushtoknow.testbed.scene import support_loads, support_points
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape

MARGIN = 0.002


@pytest.mark.parametrize("shape", sorted(CATALOGUE_SHAPES))
def test_support_points_lie_inside_and_reach_the_edge(shape):
    fp = footprint_from_shape(CATALOGUE_SHAPES[shape])
    pts = support_points(fp, 0.016, MARGIN)
    assert len(pts) >= 8
    assert all(fp.contains(p, margin=MARGIN - 1e-9) for p in pts)
    # Their hull reaches to within the margin (+ a pitch along the edge) of the outline.
    from shapely.geometry import MultiPoint

    hull = MultiPoint([tuple(p) for p in pts]).convex_hull
    assert hull.area > fp.polygon.buffer(-MARGIN - 0.002).area


def test_centred_com_gives_the_centroid_of_the_points():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])
    pts = support_points(fp, 0.016, MARGIN)
    w = support_loads(pts, pts.mean(axis=0))
    np.testing.assert_allclose(w, 1.0 / len(pts), atol=1e-9)  # uniform pressure


SHAPES = {**CATALOGUE_SHAPES, **NOVEL_SHAPES}


@settings(max_examples=120, deadline=None)
@given(
    shape=st.sampled_from(sorted(SHAPES)),
    u=st.floats(0.0, 1.0),
    v=st.floats(0.0, 1.0),
)
@example(shape="rect3", u=0.0002, v=0.001953125)  # a corner CoM needed a stiffer balance
@example(shape="l_shape", u=0.99, v=0.99)  # in the notch, near the hull's diagonal
def test_loads_are_nonnegative_sum_to_one_and_balance_at_the_com(shape, u, v):
    """Every CoM the object rule allows (the convex hull less COM_MARGIN, a non-convex
    footprint's notch included) is carried by the supports with non-negative loads."""
    fp = footprint_from_shape(SHAPES[shape])
    poly = fp.com_region(COM_MARGIN)
    minx, miny, maxx, maxy = poly.bounds
    com = np.array([minx + u * (maxx - minx), miny + v * (maxy - miny)])
    from shapely.geometry import Point

    if not poly.contains(Point(*com)):
        return
    pts = support_points(fp, 0.016, MARGIN, com)
    w = support_loads(pts, com)
    assert (w >= 0).all()
    assert w.sum() == pytest.approx(1.0, abs=1e-12)
    np.testing.assert_allclose(w @ pts, com, atol=2e-5)


def test_corner_com_gets_corner_supports_and_others_keep_theirs():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect2"])
    corner = (0.0393, 0.0505)  # 5 mm inside the corner diagonal: beyond the ring's hull
    plain = support_points(fp, 0.016, MARGIN)
    with pytest.raises(ValueError, match="outside their hull"):
        support_loads(plain, corner)
    more = support_points(fp, 0.016, MARGIN, corner)
    assert len(more) == len(plain) + 4
    np.testing.assert_allclose(support_loads(more, corner) @ more, corner, atol=2e-5)
    # a CoM the plain supports carry changes nothing (the catalogue's physics is unchanged)
    np.testing.assert_array_equal(support_points(fp, 0.016, MARGIN, (0.01, 0.02)), plain)


def test_a_com_the_supports_cannot_carry_is_refused():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])
    with pytest.raises(ValueError, match="outside their hull"):
        support_loads(support_points(fp, 0.016, MARGIN), (0.2, 0.0))
