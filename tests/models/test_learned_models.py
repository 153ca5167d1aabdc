"""Learned models wired into the filters: context, encodings, crop, filters, gradients."""

import dataclasses

import pytest
import torch
from tiny_models import CAMERA, prior, square_context, tiny_config
from torch.autograd import gradcheck
from torch.func import functional_call

from pushtoknow.common.errors import ShapeError
from pushtoknow.filters import DualFilter, FilterConfig, JointFilter
from pushtoknow.filters.gaussian import gaussian_log_prob
from pushtoknow.geometry.warp import warp_mask
from pushtoknow.models import (
    EncoderConfig,
    EncodingConfig,
    LearnedModelsConfig,
    ShapeActionEncoderNet,
    ShapeActionEncoding,
    build_filter,
    build_learned_models,
)

F64 = torch.float64
KINDS = ["dual", "joint", "vision_only"]


def observation_for(filt, mean, ctx):
    with torch.no_grad():
        return filt.observation(mean.unsqueeze(1), ctx).squeeze(1) + 0.01


def test_context_validation_names_the_field():
    ctx = square_context(2)
    ctx.validate(2)
    with pytest.raises(ShapeError, match=r"context.mask0: expected shape \(B=3, 1=1, H=16"):
        ctx.validate(3)
    with pytest.raises(ShapeError, match=r"context.pose0: expected shape \(B=2, 3=3\), got \(2,"):
        dataclasses.replace(ctx, pose0=torch.zeros(2, 2)).validate(2)
    filt = build_filter("dual", models_config=tiny_config())
    mean, cov = prior(3)
    with pytest.raises(ShapeError, match="context.mask0"):
        filt(mean, cov, torch.zeros(3, 5), ctx, generator=torch.Generator())


def test_mean_mode_equals_per_sigma_when_all_points_share_the_pose():
    torch.manual_seed(0)
    cfg = EncoderConfig(image_size=8, channels=(2, 2, 2), kernel_sizes=(3, 3, 3), out_dim=3)
    net = ShapeActionEncoderNet(cfg)
    ctx = square_context(2)
    pose = torch.tensor([[0.01, -0.02, 0.3], [0.0, 0.03, -0.1]]).unsqueeze(1).expand(2, 5, 3)
    per = ShapeActionEncoding(net, EncodingConfig(mode="per_sigma", crop_size=8))
    mean = ShapeActionEncoding(net, EncodingConfig(mode="mean", crop_size=8))
    enc_p, anchor_p = per(pose, ctx)
    enc_m, anchor_m = mean(pose, ctx)
    assert enc_p.shape == (2, 5, 3) and enc_m.shape == (2, 1, 3)
    torch.testing.assert_close(enc_p, enc_m.expand_as(enc_p))
    torch.testing.assert_close(anchor_p, anchor_m.expand_as(anchor_p))


def test_crop_of_the_full_image_equals_the_warped_mask():
    """A crop as large as the image, centred on an object at the image centre, is the image."""
    ctx = square_context(3, F64)
    pose = torch.tensor([[0.0, 0.0, 0.4], [0.0, 0.0, -1.0], [0.0, 0.0, 0.0]], dtype=F64)
    enc = ShapeActionEncoding(ShapeActionEncoderNet(), EncodingConfig(crop_size=CAMERA.width))
    amap = ctx.action_map(EncodingConfig().action_map, F64)
    imgs = enc.images(pose, ctx, amap)
    torch.testing.assert_close(imgs[:, :1], warp_mask(ctx.mask0, pose, ctx.pose0, CAMERA))
    torch.testing.assert_close(imgs[:, 1:], amap)


def test_action_map_is_cached_per_context():
    ctx = square_context(2)
    cfg = EncodingConfig().action_map
    assert ctx.action_map(cfg, torch.float32) is ctx.action_map(cfg, torch.float32)


@pytest.mark.parametrize("kind", KINDS)
@pytest.mark.parametrize(("mode", "crop"), [("mean", 8), ("per_sigma", 8), ("per_sigma", None)])
def test_learned_filters_run_in_every_configuration(kind, mode, crop):
    torch.manual_seed(1)
    filt = build_filter(
        kind, models_config=tiny_config(mode, crop), filter_config=FilterConfig(num_sigma_points=20)
    )
    assert isinstance(filt, JointFilter if kind == "joint" else DualFilter)
    ctx = square_context(2)
    mean, cov = prior(2)
    z = observation_for(filt, mean, ctx)
    gen = torch.Generator().manual_seed(2)
    for _ in range(3):
        mean, cov, _ = filt(mean, cov, z, ctx, generator=gen)
    assert torch.isfinite(mean).all() and torch.isfinite(cov).all()
    assert (torch.linalg.eigvalsh(cov.double()) > 0).all()


def test_shared_encoder_and_config_validation():
    models = build_learned_models(tiny_config())
    assert models.dynamics.encoding is models.observation.encoding
    with pytest.raises(ValueError, match="crop_size"):
        LearnedModelsConfig(encoding=EncodingConfig(crop_size=16))
    with pytest.raises(ValueError, match="input_dim"):
        LearnedModelsConfig(param_dim=4)


def test_observation_noise_does_not_depend_on_where_the_object_is():
    models = build_learned_models(tiny_config())
    ctx = square_context(1)
    z = torch.tensor([[0.01, 0.02, 0.1, 1.0, -0.5]])
    r = models.observation_noise(z, ctx)
    moved = square_context(1)
    moved.pose0.add_(torch.tensor([[0.2, -0.1, 2 * torch.pi]]))
    z_moved = z + torch.tensor([[0.2, -0.1, 2 * torch.pi, 0.0, 0.0]])
    torch.testing.assert_close(models.observation_noise(z_moved, moved), r)


@pytest.mark.parametrize("kind", KINDS)
def test_gradcheck_one_step_wrt_model_weights(kind):
    """float64 gradcheck of (mean, cov) after one predict + update w.r.t. every weight of the
    tiny networks (fast mode: random directional derivatives), and in full mode w.r.t. the
    output biases of ProcessNet and ObsNoiseNet."""
    torch.manual_seed(3)
    filt = build_filter(
        kind, models_config=tiny_config(), filter_config=FilterConfig(num_sigma_points=16)
    ).double()
    ctx = square_context(2, F64)
    mean, cov = prior(2, F64)
    z = observation_for(filt, mean, ctx)
    noise = filt.draw_noise(2, torch.Generator().manual_seed(4), F64)
    names = [n for n, _ in filt.named_parameters()]
    params = tuple(p.detach().clone().requires_grad_(True) for _, p in filt.named_parameters())

    def step(*values, names=names):
        out = functional_call(filt, dict(zip(names, values)), (mean, cov, z, ctx), {"noise": noise})
        return out[0], out[1]

    assert gradcheck(step, params, eps=1e-6, atol=1e-5, rtol=1e-3, fast_mode=True)
    heads = [i for i, n in enumerate(names) if n.endswith(("mlp.rest.1.2.bias", "net.mlp.2.bias"))]
    assert heads
    fixed = list(params)

    def head_step(*values):
        for i, v in zip(heads, values):
            fixed[i] = v
        return step(*fixed)

    assert gradcheck(head_step, tuple(params[i] for i in heads), eps=1e-6, atol=1e-5, rtol=1e-3)


def test_gradients_stay_finite_through_50_steps():
    torch.manual_seed(5)
    filt = build_filter(
        "dual", models_config=tiny_config(), filter_config=FilterConfig(num_sigma_points=16)
    )
    ctx = square_context(2)
    mean, cov = prior(2)
    gen = torch.Generator().manual_seed(6)
    truth = torch.zeros(2, 8)
    loss = torch.zeros(())
    for t in range(50):
        truth[:, 0] = 0.002 * t
        z = torch.cat([truth[:, :3], torch.tensor([[2.0, 0.1]]).expand(2, 2)], -1)
        mean, cov, _ = filt(mean, cov, z, ctx, generator=gen)
        loss = loss - gaussian_log_prob(truth, mean, cov, angle_indices=(2,)).mean()
    loss.backward()
    grads = [p.grad for p in filt.parameters()]
    assert all(g is not None and torch.isfinite(g).all() for g in grads)
    assert sum(g.abs().sum() for g in grads) > 0


def test_crop_follows_the_object():
    """Moved by whole pixels, the object looks the same in a crop centred on it."""
    ctx = square_context(1, F64)
    enc = ShapeActionEncoding(ShapeActionEncoderNet(), EncodingConfig(crop_size=8))
    amap = ctx.action_map(EncodingConfig().action_map, F64)
    px = CAMERA.metres_per_pixel()
    moved = torch.tensor([[3 * px, -2 * px, 0.0]], dtype=F64)
    at_rest = enc.images(ctx.pose0, ctx, amap)[:, :1]
    torch.testing.assert_close(enc.images(moved, ctx, amap)[:, :1], at_rest)
    assert at_rest.sum() > 4  # the square is in the crop
