"""VisNet render-and-compare training on a tiny simulated dataset."""

import math

import numpy as np
import pytest
import torch

from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
from pushtoknow.perception.footprint import FOOTPRINT_VERTICES, footprint_from_mask
from pushtoknow.perception.visnet import visnet_inputs
from pushtoknow.testbed.sim_config import PushConfig, SimConfig
from pushtoknow.training.fit_visnet import (
    VisNetTrainConfig,
    evaluate_visnet,
    perturb,
    train_visnet,
)
from pushtoknow.training.push_tensors import dataset_camera, load_frames, load_push_tensors


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    out = tmp_path_factory.mktemp("tiny")
    cfg = GenerationConfig(
        objects=6,
        pushes=2,
        seed=3,
        objects_per_shard=3,
        sim=SimConfig(push=PushConfig(horizon=3.0)),
    )
    generate_dataset(out, cfg, progress=False)
    return out


def test_push_tensors(tiny):
    pt = load_push_tensors(tiny)
    assert len(pt) == 12 and pt.horizon_steps == 31
    assert pt.footprint.shape == (12, FOOTPRINT_VERTICES, 2)
    assert pt.params_norm.abs().max() <= 1.0 + 1e-6
    # The footprint seen is centred in the object frame (its area centroid at the origin).
    from shapely.geometry import Polygon

    centroids = np.array([Polygon(f).centroid.coords[0] for f in pt.footprint.numpy()])
    assert np.abs(centroids).max() < 1e-3
    sub = pt.subset([0, 5])
    assert len(sub) == 2 and torch.equal(sub.pose[1], pt.pose[5])


def test_footprint_from_mask_recovers_rotation():
    from helpers import rasterise_footprint
    from pushtoknow.common.camera import CameraModel
    from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape

    cam = CameraModel(256, 256, 45.0, (0, 0, 0.75))
    fp = footprint_from_shape(CATALOGUE_SHAPES["tri3"])
    pose = (0.02, 0.01, 0.8)
    est = footprint_from_mask(rasterise_footprint(fp.vertices, pose, cam), cam, pose)
    from shapely.geometry import Polygon

    a, b = Polygon(est), fp.polygon
    assert a.intersection(b).area / a.union(b).area > 0.9


def test_crop_is_centred_on_reference(tiny):
    rgbd, mask0, pose, pose0, _ = load_frames(tiny, every=10)
    camera, _ = dataset_camera(tiny)
    x, s_ref = visnet_inputs(rgbd[:4], mask0[:4], pose0[:4], pose[:4], camera, 32)
    assert x.shape == (4, 5, 32, 32) and s_ref.shape == (4, 1, 32, 32)
    # At the true pose the warped S_0 and the height map coincide: little misalignment.
    assert x[:, 4].abs().mean() < 0.1
    # The object sits in the middle of the crop.
    v, u = torch.nonzero(s_ref[0, 0] > 0.5, as_tuple=True)
    assert abs(u.float().mean() - 15.5) < 2 and abs(v.float().mean() - 15.5) < 2


def test_marker_channel_matches_the_painted_marker(tiny):
    """With the orientation marker the extra channel (expected marker at the reference) lies on
    the image's dark pixels at the true pose, and on other pixels at a pose turned by π."""
    from pushtoknow.training.pipeline import visnet_config_for

    rgbd, mask0, pose, pose0, _ = load_frames(tiny, every=10)
    camera, sim_cfg = dataset_camera(tiny)
    assert sim_cfg.orientation_marker
    cfg = visnet_config_for(VisNetTrainConfig(), sim_cfg)
    assert cfg.net.marker_channel and cfg.net.in_channels == VisNetTrainConfig().net.in_channels + 1
    x, s_ref = visnet_inputs(rgbd[:6], mask0[:6], pose0[:6], pose[:6], camera, 32, marker=True)
    assert x.shape == (6, 6, 32, 32)
    dark = (x[:, :3].sum(1) < 0.6 * 3 / 2).float()  # the decal is near black
    expected = x[:, 5]
    overlap = (dark * expected).sum() / expected.sum()
    turned = pose[:6] + torch.tensor([0.0, 0.0, math.pi])
    x_turned, _ = visnet_inputs(rgbd[:6], mask0[:6], pose0[:6], turned, camera, 32, marker=True)
    overlap_turned = (dark * x_turned[:, 5]).sum() / x_turned[:, 5].sum()
    assert overlap > 0.7 and overlap_turned < 0.3


@pytest.mark.slow
def test_visnet_learns_to_beat_its_reference(tiny):
    torch.manual_seed(0)
    frames = load_frames(tiny, every=1)
    camera, _ = dataset_camera(tiny)
    cfg = VisNetTrainConfig(epochs=25, batch_size=32, lr=3e-3, val_fraction=0.0)
    res = train_visnet(frames, camera, cfg, seed=0)
    rgbd, mask0, pose, pose0, _ = frames
    ref = perturb(pose, cfg, torch.Generator().manual_seed(9))
    err = evaluate_visnet(res.net, rgbd, mask0, pose, pose0, ref, camera)
    assert err is not None and err.xy_rmse_mm < 0.7 * err.ref_xy_rmse_mm
    assert res.history[-1]["train_loss"] < res.history[0]["train_loss"]
    assert math.isfinite(err.theta_med_deg)


def test_symmetry_orders_of_catalogue_shapes():
    from pushtoknow.geometry.symmetry import CONTINUOUS, symmetry_order
    from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape

    got = {n: symmetry_order(footprint_from_shape(s).vertices) for n, s in CATALOGUE_SHAPES.items()}
    assert got == {
        "rect1": 4,
        "rect2": 2,
        "rect3": 2,
        "tri1": 1,
        "tri2": 1,
        "tri3": 1,
        "ellip1": CONTINUOUS,
        "ellip2": 2,
        "ellip3": 2,
        "hex": 6,
        "butter": 2,
    }
    assert np.isfinite(list(got.values())).all()
