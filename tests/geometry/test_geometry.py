"""Affordances, action maps and the differentiable warp against the rendered truth."""

import math

import numpy as np
import pytest
import torch

from helpers import iou, rasterise_footprint
from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import ShapeError
from pushtoknow.geometry.action_maps import action_map
from pushtoknow.geometry.affordances import mask_contour, sample_push_affordances
from pushtoknow.geometry.warp import warp_mask
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape

CAM = CameraModel(64, 64, 45.0, (0.0, 0.0, 0.75))
HIRES = CameraModel(256, 256, 45.0, (0.0, 0.0, 0.75))


def test_camera_round_trip():
    xy = np.array([[0.1, -0.2], [0.0, 0.0], [-0.05, 0.13]])
    assert np.allclose(CAM.pixel_to_world(CAM.world_to_pixel(xy)), xy)
    # +x to the right, +y up in the image
    u0, v0 = CAM.world_to_pixel(np.array([0.0, 0.0]))
    u1, v1 = CAM.world_to_pixel(np.array([0.05, 0.05]))
    assert u1 > u0 and v1 < v0


@pytest.mark.parametrize("shape", ["rect3", "tri3", "ellip2"])
def test_contour_lies_on_the_true_boundary(shape):
    fp = footprint_from_shape(CATALOGUE_SHAPES[shape])
    pose = (0.03, -0.01, 0.5)
    mask = rasterise_footprint(fp.vertices, pose, HIRES)
    c = mask_contour(mask, HIRES)
    R = np.array([[math.cos(0.5), -math.sin(0.5)], [math.sin(0.5), math.cos(0.5)]])
    poly = fp.polygon
    from shapely.geometry import Point

    local = (c.points - np.array(pose[:2])) @ R
    dist = np.array([poly.exterior.distance(Point(p)) for p in local])
    assert np.median(dist) < HIRES.metres_per_pixel()
    assert np.allclose(c.centroid, pose[:2], atol=HIRES.metres_per_pixel())
    # Outward normals point away from the centroid.
    assert np.mean(np.sum(c.normals * (c.points - c.centroid), axis=1) > 0) > 0.95


def test_affordances_point_inwards_within_5_degrees_of_normal():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])
    mask = rasterise_footprint(fp.vertices, (0.0, 0.0, 0.0), HIRES)
    cp, pd = sample_push_affordances(mask, HIRES, 200, np.random.default_rng(0))
    # Away from corners, the inward normal of a square side is axis-aligned.
    side = np.abs(np.abs(cp).max(1) - 0.045) < 0.003
    mid = side & (np.abs(cp).min(1) < 0.03)
    inward = -np.sign(cp[mid]) * (np.abs(cp[mid]) == np.abs(cp[mid]).max(1, keepdims=True))
    d = np.stack([np.cos(pd[mid]), np.sin(pd[mid])], 1)
    ang = np.degrees(np.arccos(np.clip((d * inward).sum(1), -1, 1)))
    assert mid.sum() > 50
    assert ang.max() < 5.0 + 3.0  # δ ≤ 5° plus the contour's normal error
    assert ang.std() > 1.0  # δ really is random


def test_affordances_are_seeded():
    fp = footprint_from_shape(CATALOGUE_SHAPES["hex"])
    mask = rasterise_footprint(fp.vertices, (0.0, 0.0, 0.0), CAM)
    a = sample_push_affordances(mask, CAM, 5, np.random.default_rng(7))
    b = sample_push_affordances(mask, CAM, 5, np.random.default_rng(7))
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_warp_moves_mask_to_the_new_pose():
    fp = footprint_from_shape(CATALOGUE_SHAPES["tri2"])
    p0, p1 = (0.0, 0.0, 0.0), (0.08, -0.05, 0.6)
    m0 = rasterise_footprint(fp.vertices, p0, CAM)
    m1 = rasterise_footprint(fp.vertices, p1, CAM)
    warped = (
        warp_mask(
            torch.tensor(m0, dtype=torch.float32)[None, None],
            torch.tensor([p1]),
            torch.tensor([p0]),
            CAM,
        )[0, 0].numpy()
        > 0.5
    )
    assert iou(warped, m1) > 0.8


def test_warp_is_differentiable_in_pose():
    fp = footprint_from_shape(CATALOGUE_SHAPES["rect1"])
    m0 = torch.tensor(rasterise_footprint(fp.vertices, (0, 0, 0), CAM), dtype=torch.float64)
    pose = torch.tensor([[0.01, 0.0, 0.1]], dtype=torch.float64, requires_grad=True)
    out = warp_mask(m0[None, None], pose, torch.zeros(1, 3, dtype=torch.float64), CAM)
    (out * torch.linspace(0, 1, 64, dtype=torch.float64)).sum().backward()
    assert pose.grad is not None and torch.isfinite(pose.grad).all() and pose.grad[0, 0] > 0


def test_warp_rejects_bad_shapes():
    with pytest.raises(ShapeError, match="expected mask0"):
        warp_mask(torch.zeros(2, 64, 64), torch.zeros(2, 3), torch.zeros(2, 3), CAM)


def test_action_map_peaks_at_contact_and_stretches_along_push():
    cp = torch.tensor([[0.05, 0.02]])
    m = action_map(cp, torch.tensor([0.0]), torch.tensor([0.2]), CAM)[0, 0]
    v, u = divmod(int(m.argmax()), 64)
    eu, ev = CAM.world_to_pixel(cp[0].numpy())
    assert abs(u - eu) <= 1 and abs(v - ev) <= 1
    # Along +x (image columns) the map is wider than across (rows).
    row = m[v]
    col = m[:, u]
    assert (row > 0.5).sum() > (col > 0.5).sum()
    fast = action_map(cp, torch.tensor([0.0]), torch.tensor([0.5]), CAM)[0, 0]
    assert (fast > 0.5).sum() > (m > 0.5).sum()


def test_marker_mask_is_the_half_with_positive_object_x():
    from pushtoknow.geometry.warp import marker_mask

    cam = CAM
    h, w = cam.height, cam.width
    mask = torch.ones(2, 1, h, w)
    pose0 = torch.tensor([[0.02, -0.01, 0.0], [0.0, 0.0, math.pi / 2]])
    half = marker_mask(mask, pose0, cam)
    assert half.shape == (2, 1, h, w)
    u = torch.arange(w, dtype=torch.float32)
    v = torch.arange(h, dtype=torch.float32)
    xy = torch.as_tensor(cam.pixel_to_world(np.stack(np.meshgrid(u, v), -1)), dtype=torch.float32)
    # θ0 = 0: pixels right of x = 0.02 m; θ0 = π/2: pixels above y = 0 (object +x = world +y)
    torch.testing.assert_close(half[0, 0], (xy[..., 0] >= 0.02).float())
    torch.testing.assert_close(half[1, 0], (xy[..., 1] >= 0).float())
    # only inside S_0
    assert marker_mask(torch.zeros(1, 1, h, w), pose0[:1], cam).sum() == 0
