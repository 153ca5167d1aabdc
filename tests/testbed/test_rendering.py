"""Rendering: segmentation vs the camera model, metric depth, frame strip sanity."""

import numpy as np
import pytest

from helpers import iou, rasterise_footprint
from pushtoknow.common.params import ObjectParams
from pushtoknow.testbed.objects import ObjectSpec, catalogue_object
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushSimulator


@pytest.mark.parametrize(
    ("shape", "pose"),
    [
        ("rect3", (0.03, -0.02, 0.4)),
        ("tri2", (-0.05, 0.04, -1.0)),
        ("ellip3", (0.0, 0.0, 2.0)),
        ("hex", (0.08, 0.05, 0.1)),
    ],
)
def test_segmentation_matches_projected_footprint(shape, pose):
    spec = ObjectSpec(shape=shape, params=ObjectParams(0.8, 0.5, 0.0, 0.0, 0.5e-3))
    sim = PushSimulator(spec)
    sim.reset(pose)
    rec = sim.execute(Push((5.0, 5.0), 0.0), np.random.default_rng(0), render=True)
    expected = rasterise_footprint(spec.footprint.vertices, rec.pose[0], sim.camera)
    assert iou(rec.s0, expected) >= 0.8
    sim.close()


def test_depth_is_metric_and_rgb_shows_object():
    spec = catalogue_object(3)
    sim = PushSimulator(spec)
    sim.reset((0.0, 0.0, 0.0))
    rec = sim.execute(Push((-0.2, 0.0), 0.0), np.random.default_rng(0), render=True)
    d = rec.depth[0]
    cam = sim.config.camera
    table = d[~rec.s0]
    top = d[rec.s0]
    # Table pixels: depth along the optical axis = camera height (flat plane), within 1 mm.
    assert np.median(table) == pytest.approx(cam.distance, abs=1e-3)
    # Object top is `height` closer to the camera.
    assert np.median(top) == pytest.approx(cam.distance - spec.height, abs=2e-3)
    # The object is coloured differently from the table.
    assert np.abs(rec.rgb[0][rec.s0].mean(0) - rec.rgb[0][~rec.s0].mean(0)).sum() > 60
    assert rec.rgb.shape == (61, cam.height, cam.width, 3)  # 6 s at 10 Hz


@pytest.mark.parametrize(("shape", "theta"), [("ellip1", 2.0), ("rect1", -0.7), ("hex", 3.0)])
def test_orientation_marker_shows_the_object_frame_x_axis(shape, theta):
    """The dark decal covers the +x half of the object frame, so even a disc's θ is visible:
    the direction from the object's centre to the dark pixels is θ."""
    from pushtoknow.testbed.sim_config import SimConfig

    spec = ObjectSpec(shape=shape, params=ObjectParams(0.8, 0.5, 0.0, 0.0, 0.5e-3))
    sim = PushSimulator(spec, SimConfig(orientation_marker=True))
    sim.reset((0.0, 0.0, theta))
    rec = sim.execute(Push((5.0, 5.0), 0.0), np.random.default_rng(0), render=True)
    rgb = rec.rgb[0].astype(float)
    dark = rec.s0 & (rgb.sum(-1) < 150)
    assert 0.3 < dark.sum() / rec.s0.sum() < 0.7  # about half of the object
    v, u = np.nonzero(dark)
    xy = sim.camera.pixel_to_world(np.stack([u, v], -1)).mean(0)
    assert abs(np.angle(np.exp(1j * (np.arctan2(xy[1], xy[0]) - theta)))) < np.radians(12)
    # the decal belongs to the object: segmentation still covers the whole footprint
    expected = rasterise_footprint(spec.footprint.vertices, rec.pose[0], sim.camera)
    assert iou(rec.s0, expected) >= 0.8
    sim.close()


def test_orientation_marker_changes_pixels_not_physics():
    from pushtoknow.testbed.sim_config import SimConfig

    spec = catalogue_object(500)
    recs = []
    for marker in (False, True):
        sim = PushSimulator(spec, SimConfig(orientation_marker=marker))
        sim.reset((0.0, 0.0, 0.3))
        push = Push((-0.08, 0.01), 0.0)
        recs.append(sim.execute(push, np.random.default_rng(3), render=True))
        sim.close()
    plain, marked = recs
    np.testing.assert_array_equal(plain.pose, marked.pose)
    np.testing.assert_array_equal(plain.tactile, marked.tactile)
    np.testing.assert_array_equal(plain.s0, marked.s0)
    assert not (plain.rgb[0][plain.s0].astype(float).sum(-1) < 150).any()
    assert (marked.rgb[0][marked.s0].astype(float).sum(-1) < 150).any()


def test_outline_mask_is_the_top_face_at_four_times_the_resolution():
    """S_0 at the outline resolution shows the top face (13 mm up) as the camera model places
    it, and agrees with S_0 where a whole image pixel is inside or outside; so does the mask
    at the push's end."""
    spec = catalogue_object(300)
    sim = PushSimulator(spec)
    sim.reset((0.03, -0.02, 0.7))
    rec = sim.execute(Push((5.0, 5.0), 0.0), np.random.default_rng(0), render=True)
    k = sim.config.camera.outline_scale
    fine = sim.camera.scaled(k)
    assert rec.outline_mask.shape == (k * 64, k * 64)
    expected = rasterise_footprint(spec.footprint.vertices, rec.pose[0], fine, spec.height)
    assert iou(rec.outline_mask, expected) >= 0.99  # measured 0.999; a fine pixel off: 0.95
    rec = sim.execute(Push((-0.08, 0.01), 0.0), np.random.default_rng(0), render=True)
    assert np.hypot(*(rec.pose[-1, :2] - rec.pose[0, :2])) > 0.01  # the push moved it
    end = rasterise_footprint(spec.footprint.vertices, rec.pose[-1], fine, spec.height)
    assert iou(rec.outline_mask_end, end) >= 0.99  # the same mask at rest after the push
    share = rec.outline_mask.reshape(64, k, 64, k).mean((1, 3))
    whole = (share == 0) | (share == 1)
    assert (rec.s0[whole] == (share[whole] == 1)).all()
    with pytest.raises(ValueError, match="exceeds the model's offscreen buffer"):
        sim.renderer.segmentation(sim.data, 2 * k)
    sim.close()
