"""Gradients through the filters (analytic models with learnable parameters): gradcheck in
float64 through one predict + update, including an update where the ESS guard tempers."""

import pytest
import torch
from filter_toys import F64, planar_toy, pushed_block
from torch.autograd import gradcheck
from torch.func import functional_call

from pushtoknow.filters import DualFilter, JointFilter, vision_only_filter
from pushtoknow.models.analytic import ConstantObservationNoise


def check_step(filt, mean, cov, z, noise, wrt_belief=True):
    names = [n for n, _ in filt.named_parameters()]
    params = [p.detach().clone().requires_grad_(True) for _, p in filt.named_parameters()]
    inputs = params + ([mean.clone().requires_grad_(True)] if wrt_belief else [])

    def step(*values):
        state_mean = values[len(names)] if wrt_belief else mean
        out = functional_call(
            filt,
            dict(zip(names, values[: len(names)])),
            (state_mean, cov, z, None),
            {"noise": noise},
        )
        return out[0], out[1]

    assert gradcheck(step, tuple(inputs), eps=1e-6, atol=1e-6, rtol=1e-4)


@pytest.mark.parametrize("kind", ["dual", "dual_tempered", "joint", "vision_only"])
def test_gradcheck_one_step_wrt_model_parameters_and_mean(kind):
    toy = planar_toy() if kind != "dual_tempered" else pushed_block(force_std=0.01)
    dyn, obs, noise_model = toy.models(learnable=True)
    cfg = toy.config(num_sigma_points=16)
    if kind == "joint":
        filt = JointFilter(dyn, obs, noise_model, cfg)
    elif kind == "vision_only":
        cfg = cfg.model_copy(update={"pose_angle_indices": (2,)})
        filt = vision_only_filter(
            dyn, ConstantObservationNoise(toy.r_diag[:3], learnable=True), cfg
        )
    else:
        filt = DualFilter(dyn, obs, noise_model, cfg)
    b = 2
    _, observations = toy.simulate(b, 1, torch.Generator().manual_seed(0))
    z = observations[0][:, : filt.observation.obs_dim]
    mean = toy.prior_mean.expand(b, -1).clone()
    cov = toy.prior_cov.expand(b, -1, -1).clone()
    noise = filt.draw_noise(b, torch.Generator().manual_seed(1), F64)
    if kind == "dual_tempered":
        _, _, info = filt(mean, cov, z, None, noise=noise)
        assert (info.stages > 1).all()  # the guard is active in this check
    check_step(filt, mean, cov, z, noise)


def test_gradients_with_respect_to_the_covariance_are_finite():
    toy = planar_toy()
    filt = DualFilter(*toy.models(learnable=True), toy.config(num_sigma_points=16))
    _, obs = toy.simulate(2, 1, torch.Generator().manual_seed(2))
    cov = toy.prior_cov.expand(2, -1, -1).clone().requires_grad_(True)
    mean = toy.prior_mean.expand(2, -1)
    post_mean, post_cov, _ = filt(mean, cov, obs[0], None, generator=torch.Generator())
    (post_mean.sum() + post_cov.sum()).backward()
    assert torch.isfinite(cov.grad).all() and cov.grad.abs().sum() > 0
