"""The outline the simulator replays: corners rounded by smoothing are refitted sharp, curves
stay curves."""

import numpy as np
import pytest
from shapely.geometry import Point, Polygon

from pushtoknow.perception.footprint import OUTLINE_SMOOTHING, sharpen_corners


def rounded(vertices, radius: float = OUTLINE_SMOOTHING) -> np.ndarray:
    """A polygon's outline with every convex corner rounded to `radius`, densely sampled."""
    poly = Polygon(vertices).buffer(-radius, join_style="round").buffer(radius, quad_segs=32)
    return np.asarray(poly.exterior.coords)[:-1]


@pytest.mark.parametrize(
    "vertices",
    [
        [[-0.05, -0.02], [0.06, -0.03], [0.02, 0.04]],  # a triangle with a 46° tip
        [[-0.045, -0.056], [0.045, -0.056], [0.045, 0.056], [-0.045, 0.056]],  # a rectangle
        [[-0.06, -0.02], [0.06, -0.02], [0.06, 0.02], [0.02, 0.02], [0.0, 0.06], [-0.06, 0.02]],
    ],
)
def test_rounded_corners_are_refitted_sharp(vertices):
    truth = Polygon(vertices)
    contour = rounded(vertices)
    assert Polygon(contour).hausdorff_distance(truth) > 2e-3  # the rounding clipped the corners
    sharp = Polygon(sharpen_corners(contour))
    assert sharp.is_valid
    assert sharp.hausdorff_distance(truth) < 1.5e-3


def test_a_curve_stays_a_curve():
    circle = np.asarray(Point(0, 0).buffer(0.05, quad_segs=64).exterior.coords)[:-1]
    for contour in (circle, circle * np.array([1.0, 0.6])):
        out = Polygon(sharpen_corners(contour))
        assert out.hausdorff_distance(Polygon(contour)) < 1.5e-3


def test_an_elongated_ellipse_end_is_moved_at_most_the_extension_bound():
    """The end of a 2.5:1 ellipse looks like a rounded corner at this smoothing: what a wrong
    refit costs is bounded."""
    from pushtoknow.perception.footprint import REPLAY_MAX_EXTENSION

    circle = np.asarray(Point(0, 0).buffer(0.05, quad_segs=64).exterior.coords)[:-1]
    ellipse = circle * np.array([1.0, 0.4])
    out = Polygon(sharpen_corners(ellipse))
    assert out.hausdorff_distance(Polygon(ellipse)) <= REPLAY_MAX_EXTENSION + 1e-6


def test_a_contour_smoothed_less_has_its_corners_extended_less():
    """How far a corner may be refitted beyond the contour scales with the smoothing the
    contour was traced with: the end of a 2.5:1 ellipse, which the 5 mm smoothing's rule
    extends by 10 mm (measured: 10.4 mm), stays as traced under the 2.5 mm rule the fused
    outline uses (measured: 0.9 mm from the ellipse)."""
    from pushtoknow.perception.footprint import FUSION_SMOOTHING, REPLAY_MAX_EXTENSION

    circle = np.asarray(Point(0, 0).buffer(0.05, quad_segs=64).exterior.coords)[:-1]
    ellipse = Polygon(circle * np.array([1.0, 0.4]))
    coarse = Polygon(sharpen_corners(np.asarray(ellipse.exterior.coords)[:-1]))
    fine = Polygon(sharpen_corners(np.asarray(ellipse.exterior.coords)[:-1], FUSION_SMOOTHING))
    assert coarse.hausdorff_distance(ellipse) > 0.5 * REPLAY_MAX_EXTENSION
    assert fine.hausdorff_distance(ellipse) < 1.5e-3
