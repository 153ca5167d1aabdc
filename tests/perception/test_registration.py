"""The object's pose before a push, registered geometrically: the first view's contour placed
on a later view's mask, rendered here from a known outline at a known pose."""

import math

import numpy as np
import pytest
from shapely.geometry import Point

from helpers import rasterise_footprint
from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.camera import CameraModel
from pushtoknow.perception import registration
from pushtoknow.perception.footprint import replay_contour, resample
from pushtoknow.perception.registration import _normals, fixes_rotation, outline_points, register

CAMERA = CameraModel(position=(0.0, 0.0, 0.75))
OUTLINE_SCALE = 4  # the testbed's outline masks: 4 × the camera's resolution
HEIGHT = 0.013  # m: the object's top above the table

KITE = np.array([[0.0, 0.06], [-0.03, 0.0], [0.0, -0.03], [0.035, 0.005]])  # no symmetry
SQUARE = np.array([[-0.04, -0.04], [0.04, -0.04], [0.04, 0.04], [-0.04, 0.04]])
DISC = np.asarray(Point(0, 0).buffer(0.05, quad_segs=64).exterior.coords)[:-1]


def contour_of(outline: np.ndarray, pose):
    """The replay contour of an object-frame outline (V, 2) at pose (x, y, θ), its top HEIGHT
    above the table, seen from CAMERA at the outline resolution."""
    fine = rasterise_footprint(outline, pose, CAMERA.scaled(OUTLINE_SCALE), HEIGHT)
    s0 = fine.reshape(CAMERA.height, OUTLINE_SCALE, CAMERA.width, OUTLINE_SCALE).any(axis=(1, 3))
    depth = np.where(s0, CAMERA.position[2] - HEIGHT, CAMERA.position[2])
    return replay_contour(s0, depth, fine, CAMERA)


def template(outline: np.ndarray, pose0) -> np.ndarray:
    return outline_points(contour_of(outline, pose0), np.asarray(pose0))


def registered(outline, pose0, pose, guess):
    return register(template(outline, pose0), contour_of(outline, pose), np.asarray(guess, float))


def angle_error(a: float, b: float, period: float = 2 * math.pi) -> float:
    return abs((a - b + period / 2) % period - period / 2)


POSE0 = (0.004, -0.006, 0.3)


@pytest.mark.parametrize(
    "pose, offset",
    [
        ((0.03, 0.012, 1.1), (0.003, -0.002, math.radians(6))),
        ((-0.02, 0.025, -0.7), (-0.004, 0.003, math.radians(-9))),
    ],
)
def test_a_later_pose_is_found_from_a_guess_a_few_degrees_off(pose, offset):
    reg = registered(KITE, POSE0, pose, np.add(pose, offset))
    assert np.hypot(*(reg.pose[:2] - pose[:2])) < 3e-4
    assert angle_error(reg.pose[2], pose[2]) < math.radians(0.6)
    assert reg.rms < 5e-4


def test_a_guess_far_off_on_an_outline_without_symmetry_is_overruled():
    pose = (0.01, 0.02, 2.0)
    reg = registered(KITE, POSE0, pose, (0.025, 0.0, 2.0 + math.radians(70)))
    assert np.hypot(*(reg.pose[:2] - pose[:2])) < 3e-4
    assert angle_error(reg.pose[2], pose[2]) < math.radians(0.6)


@pytest.mark.parametrize("turn", [math.radians(4), math.radians(70)])
def test_a_symmetric_outline_takes_the_copy_nearest_the_guess(turn):
    """A square looks the same every 90°: the registration lands on the copy of the pose
    nearest the guess, at the square's true placement."""
    pose = (0.01, -0.01, 0.5)
    reg = registered(SQUARE, POSE0, pose, (0.012, -0.008, pose[2] + turn))
    nearest = pose[2] + math.pi / 2 * round(turn / (math.pi / 2))
    assert angle_error(reg.pose[2], nearest) < math.radians(0.6)
    assert angle_error(reg.pose[2], pose[2], math.pi / 2) < math.radians(0.6)
    assert np.hypot(*(reg.pose[:2] - pose[:2])) < 3e-4


def test_a_disc_keeps_the_guess_rotation_and_finds_its_centre():
    pose = (0.02, 0.01, 0.4)
    guess = (0.023, 0.012, 0.4 + math.radians(7))
    reg = registered(DISC, POSE0, pose, guess)
    assert wrap_angle(reg.pose[2] - guess[2]) == pytest.approx(0.0, abs=1e-12)
    # the disc's centre: the object origin's placement moved by the rotation's difference
    centre = np.asarray(pose[:2])  # the disc is centred on the object origin
    assert np.hypot(*(reg.pose[:2] - centre)) < 3e-4


def test_rotation_is_fixed_by_an_ellipse_and_a_hexagon_not_a_disc():
    th = np.linspace(0, 2 * math.pi, 400, endpoint=False)

    def fixes(points):
        pts = resample(points, 700)
        return fixes_rotation(pts, _normals(pts))

    assert not fixes(np.stack([0.05 * np.cos(th), 0.05 * np.sin(th)], 1))
    assert fixes(np.stack([0.0525 * np.cos(th), 0.0654 * np.sin(th)], 1))
    six = np.arange(6) * math.pi / 3
    hexagon = 0.06 * np.stack([np.cos(six), np.sin(six)], 1)
    assert fixes(hexagon)


@pytest.mark.parametrize(
    "outline, offset",
    [(KITE, (0.003, -0.002, 0.1)), (KITE, (0.0, 0.0, 2.5)), (SQUARE, (0.002, 0.0, 1.4))],
)
def test_starts_abandoned_as_hopeless_leave_the_registration_as_it_was(
    outline, offset, monkeypatch
):
    """Starts whose fit stays far worse than the guess's stop early (`ABANDON`): the pose is
    the one every start run to the end gives, near or far guess, symmetric outline or not."""
    pose = np.array([0.02, -0.01, 0.8])
    points, contour = template(outline, POSE0), contour_of(outline, pose)
    early = register(points, contour, pose + offset)
    monkeypatch.setattr(registration, "ABANDON", (math.inf, math.inf))
    full = register(points, contour, pose + offset)
    np.testing.assert_array_equal(early.pose, full.pose)
