"""The five networks: shapes, positive floored noise, VisNet's relative-pose conversion."""

import math

import pytest
import torch
from torch import nn

from pushtoknow.common.errors import ShapeError
from pushtoknow.models import (
    EncoderConfig,
    ObsNoiseNet,
    ObsNoiseNetConfig,
    ProcessNet,
    ProcessNetConfig,
    ShapeActionEncoderNet,
    TacNet,
    VisNet,
    VisNetConfig,
)


def count_layers(module, kind):
    return sum(isinstance(m, kind) for m in module.modules())


def test_paper_layer_counts_and_output_shapes():
    enc = ShapeActionEncoderNet()
    assert count_layers(enc, nn.Conv2d) == 3 and count_layers(enc, nn.Linear) == 2
    assert enc(torch.rand(5, 2, 64, 64)).shape == (5, 64)
    proc = ProcessNet()
    assert count_layers(proc, nn.Linear) == 4  # 3 FC layers, the first split in two halves
    delta, q = proc(torch.randn(2, 7, 17), torch.randn(2, 1, 64))  # shared encoding
    assert delta.shape == q.shape == (2, 7, 3)
    tac = TacNet()
    assert count_layers(tac, nn.Linear) == 5  # 4 FC layers, the first split in two halves
    forces, logit = tac(torch.randn(6, 17), torch.randn(6, 64))
    assert forces.shape == (6, 2) and logit.shape == (6,)
    noise = ObsNoiseNet()
    assert count_layers(noise, nn.Linear) == 2
    assert noise(torch.randn(4, 5)).shape == (4, 5)
    vis = VisNet()
    assert count_layers(vis, nn.Linear) == 3
    assert vis(torch.rand(3, 4, 64, 64), torch.rand(3, 1, 64, 64)).shape == (3, 4)


def test_split_first_layer_equals_the_concatenated_mlp():
    proc = ProcessNet().double()
    f, e = torch.randn(3, 17, dtype=torch.float64), torch.randn(3, 64, dtype=torch.float64)
    w = torch.cat([proc.mlp.first_features.weight, proc.mlp.first_enc.weight], dim=1)
    h = torch.relu(torch.cat([f, e], -1) @ w.T + proc.mlp.first_features.bias)
    out = proc.mlp.rest[1](h)
    torch.testing.assert_close(proc.mlp(f, e), out)


def test_process_and_observation_noise_are_positive_and_floored():
    proc = ProcessNet(ProcessNetConfig())
    noise = ObsNoiseNet(ObsNoiseNetConfig())
    for net in (proc, noise):
        for p in net.parameters():
            nn.init.constant_(p, -50.0)  # drives softplus to 0: the floor must hold
    _, q = proc(torch.ones(4, 17), torch.ones(4, 64))
    floor_q = torch.tensor(ProcessNetConfig().q_floor_std) ** 2
    assert (q >= floor_q * (1 - 1e-5)).all() and torch.isfinite(q).all()
    r = noise(torch.ones(4, 5))
    floor_r = torch.tensor(ObsNoiseNetConfig().std_floor) ** 2
    assert (r >= floor_r * (1 - 1e-5)).all()
    for p in noise.parameters():
        nn.init.constant_(p, 50.0)
    assert torch.isfinite(noise(torch.ones(4, 5))).all()


def test_visnet_pose_round_trip_and_wrap():
    pose0 = torch.tensor([[0.1, -0.2, 3.0], [0.0, 0.0, -3.1], [0.3, 0.1, 0.0]], dtype=torch.float64)
    pose = pose0 + torch.tensor(
        [[0.05, 0.01, 0.3], [-0.02, 0.03, -0.2], [0.0, 0.0, math.pi - 1e-3]], dtype=torch.float64
    )
    target = VisNet.pose_to_target(pose, pose0)
    back = VisNet.to_pose(target, pose0)
    torch.testing.assert_close(back, pose)
    # crosses ±π in absolute terms (3.0 + 0.3 > π) but the relative angle is continuous
    assert back[0, 2] > math.pi
    # a relative rotation beyond π comes back as the equivalent angle (filter wraps residuals)
    far = pose0.clone()
    far[:, 2] += 4.0
    back_far = VisNet.to_pose(VisNet.pose_to_target(far, pose0), pose0)
    torch.testing.assert_close(back_far[:, 2], far[:, 2] - 2 * math.pi)


@pytest.mark.parametrize("order", [2, 4, 6])
def test_visnet_symmetric_targets_below_half_the_symmetry_angle(order):
    half = math.pi / order
    pose0 = torch.zeros(5, 3, dtype=torch.float64)
    pose = pose0.clone()
    pose[:, 2] = torch.tensor([-0.9, -0.5, 0.0, 0.5, 0.9], dtype=torch.float64) * half
    target = VisNet.pose_to_target(pose, pose0, symmetry_order=order)
    torch.testing.assert_close(VisNet.to_pose(target, pose0), pose)
    # the image after a full symmetry turn is identical: same target
    turned = pose.clone()
    turned[:, 2] += 2 * math.pi / order
    torch.testing.assert_close(VisNet.pose_to_target(turned, pose0, order), target)


def test_visnet_output_is_unit_direction_and_backbone_hook():
    vis = VisNet(VisNetConfig(image_size=32))
    out = vis(torch.rand(2, 4, 32, 32), torch.rand(2, 1, 32, 32))
    torch.testing.assert_close(out[:, 2:].norm(dim=-1), torch.ones(2))
    backbone = nn.Sequential(nn.Conv2d(5, 8, 3), nn.AdaptiveAvgPool2d(1), nn.Flatten())
    hooked = VisNet(VisNetConfig(image_size=32), backbone=backbone, backbone_dim=8)
    assert hooked(torch.rand(2, 4, 32, 32), torch.rand(2, 1, 32, 32)).shape == (2, 4)
    with pytest.raises(ValueError, match="backbone_dim"):
        VisNet(backbone=backbone)


def test_network_shape_errors_and_config_validation():
    with pytest.raises(ShapeError, match=r"expected shape \(N, 2, 64, 64\), got \(1, 2, 32, 32\)"):
        ShapeActionEncoderNet()(torch.rand(1, 2, 32, 32))
    with pytest.raises(ShapeError, match=r"TacNet features: expected shape \(\.\.\., 17\)"):
        TacNet()(torch.rand(3, 11), torch.rand(3, 64))
    with pytest.raises(ShapeError, match="VisNet rgbd"):
        VisNet()(torch.rand(1, 3, 64, 64), torch.rand(1, 1, 64, 64))
    with pytest.raises(ValueError, match="q_floor_std"):
        ProcessNetConfig(q_floor_std=(0.0, 1e-4, 1e-3))
    with pytest.raises(ValueError, match="obs_dim"):
        ObsNoiseNetConfig(obs_dim=3)
    assert EncoderConfig(image_size=32).image_size == 32
