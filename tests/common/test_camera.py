"""The camera model at the image resolution and at k × it (the outline's)."""

import numpy as np
import pytest

from pushtoknow.common.camera import CameraModel

CAM = CameraModel(64, 48, 45.0, (0.01, -0.02, 0.75))


@pytest.mark.parametrize("k", [2, 4])
def test_scaled_camera_sees_the_same_table_with_k_times_smaller_pixels(k):
    fine = CAM.scaled(k)
    assert (fine.width, fine.height) == (64 * k, 48 * k)
    assert fine.metres_per_pixel(0.013) == pytest.approx(CAM.metres_per_pixel(0.013) / k)
    assert fine.workspace_half_extent() == pytest.approx(CAM.workspace_half_extent())
    # the k × k fine pixels of coarse pixel (u, v) have their centres inside it, centred on it
    u, v = 10, 7
    sub = (np.arange(k) + 0.5) / k - 0.5
    uu, vv = np.meshgrid(u + sub, v + sub)
    fine_uv = np.stack([k * (uu + 0.5) - 0.5, k * (vv + 0.5) - 0.5], -1)
    world = fine.pixel_to_world(fine_uv)
    np.testing.assert_allclose(CAM.world_to_pixel(world), np.stack([uu, vv], -1), atol=1e-9)
    np.testing.assert_allclose(world.reshape(-1, 2).mean(0), CAM.pixel_to_world([u, v]))


def test_resolution_of_an_image_names_the_camera_or_the_shape():
    assert CAM.resolution_of(np.zeros((48, 64))) is CAM
    assert CAM.resolution_of(np.zeros((192, 256))) == CAM.scaled(4)
    for shape in [(48, 63), (100, 128), (24, 32), (96, 64)]:
        with pytest.raises(ValueError, match=r"not an integer multiple of the camera's \(48, 64\)"):
            CAM.resolution_of(np.zeros(shape))
