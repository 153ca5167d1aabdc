"""Supervised warm-up of the filter's networks on ground-truth transitions (docs/DESIGN.md §8).

Before training end to end through the filter, each learned model is fitted where its target is
known exactly from simulation, which is far cheaper than back-propagating through the filter:

* ProcessNet (+ encoder): Gaussian NLL of the true pose change ψ_{t+1} − ψ_t under
  N(Δψ, diag Q) at the true state s_t, with the pad at its commanded position for t + 1;
* TacNet: MSE of the measured force at t + 1 (in units of `force_scale`) at the true state
  s_{t+1}, plus BCE of the contact flag;
* ObsNoiseNet: Gaussian NLL of the observation residual z_{t+1} − h(s_{t+1}) (VisNet pose and
  measured force) under R(z_{t+1}).
"""

from __future__ import annotations

import math
import time

import torch
import torch.nn.functional as F
from pydantic import Field

from pushtoknow.common.frozen_config import Config
from pushtoknow.models.context import PushContext, with_pad_track
from pushtoknow.models.learned import LearnedModels
from pushtoknow.training.push_tensors import PushTensors


class SupervisedConfig(Config):
    steps: int = Field(2000, ge=1)
    batch_size: int = Field(256, ge=1)
    lr: float = Field(2e-3, gt=0)
    weight_decay: float = Field(1e-5, ge=0)
    grad_clip: float = Field(5.0, gt=0)
    force_weight: float = Field(1.0, ge=0)
    contact_weight: float = Field(0.2, ge=0)
    noise_weight: float = Field(0.1, ge=0)
    log_every: int = Field(100, ge=1)


def push_context(pt: PushTensors, push: torch.Tensor, t: torch.Tensor) -> PushContext:
    """Context of the step that ends at sample t (B,) (pad at its position at t, and its
    track around t) for pushes `push` (B,)."""
    paths = pt.pusher[push]
    ctx = PushContext(
        mask0=pt.mask0[push],
        pose0=pt.pose[push, 0],
        contact_xy=paths[:, 0],
        direction=pt.action[push, 2],
        speed=pt.action[push, 3],
        camera=pt.camera,
        footprint=pt.footprint[push],
        release=pt.release[push],
    )
    return with_pad_track(ctx, paths, t, pt.step_dt)


def true_state(pt: PushTensors, push: torch.Tensor, t: torch.Tensor) -> torch.Tensor:
    """(B, 1, 8) true (pose, φ̃) at sample t."""
    return torch.cat([pt.pose[push, t], pt.params_norm[push]], dim=-1).unsqueeze(1)


def observation(pt: PushTensors, push: torch.Tensor, t: torch.Tensor, tactile=True) -> torch.Tensor:
    """z_t (B, 5): VisNet pose (truth if no vision poses were computed) and measured force;
    (B, 3) pose only when `tactile` is False (V-DDF)."""
    pose = pt.vision_pose[push, t] if pt.vision_pose is not None else pt.pose[push, t]
    return torch.cat([pose, pt.tactile[push, t, :2]], dim=-1) if tactile else pose


def tactile_losses(models: LearnedModels, pt: PushTensors, push, t, ctx=None):
    """TacNet at the true states of samples t (B,) of pushes `push` (B,): predicted forces
    (B, 2) N, force MSE against the measurement (units of force_scale²) and contact BCE.
    ctx: `push_context(pt, push, t)` if the caller already has it (its action map is cached)."""
    ctx = push_context(pt, push, t) if ctx is None else ctx
    forces, logit = models.observation.tactile(true_state(pt, push, t), ctx)
    scale = models.observation.tac_net.config.force_scale
    meas = pt.tactile[push, t]
    mse = ((forces[:, 0] - meas[:, :2]) / scale).square().sum(-1).mean()
    bce = F.binary_cross_entropy_with_logits(logit[:, 0], meas[:, 2])
    return forces[:, 0], mse, bce


def supervised_losses(models: LearnedModels, pt: PushTensors, push, t, cfg: SupervisedConfig):
    """Losses for transitions t → t+1 of the given pushes; returns (total, parts). Models
    without a tactile observation (V-DDF) get no force and contact terms."""
    ctx = push_context(pt, push, t + 1)
    s_t = true_state(pt, push, t)
    s_next = true_state(pt, push, t + 1)
    delta, q = models.dynamics(s_t, ctx)
    target = (pt.pose[push, t + 1] - pt.pose[push, t]).unsqueeze(1)
    proc = 0.5 * ((delta - target).square() / q + q.log()).sum(-1).mean()
    has_tactile = hasattr(models.observation, "tactile")
    parts = {"process_nll": proc.item()}
    total = proc
    h = s_next[:, 0, :3]
    if has_tactile:
        forces, tac, contact = tactile_losses(models, pt, push, t + 1, ctx)
        total = total + cfg.force_weight * tac + cfg.contact_weight * contact
        parts.update({"force_mse": tac.item(), "contact_bce": contact.item()})
        h = torch.cat([h, forces.detach()], -1)
    z = observation(pt, push, t + 1, has_tactile)
    resid = z - h
    resid[:, 2] = torch.remainder(resid[:, 2] + math.pi, 2 * math.pi) - math.pi
    r = models.observation_noise(z, ctx)
    noise = 0.5 * (resid.square() / r + r.log()).sum(-1).mean()
    total = total + cfg.noise_weight * noise
    parts["noise_nll"] = noise.item()
    return total, parts


def train_supervised(
    models: LearnedModels,
    train: PushTensors,
    val: PushTensors | None,
    cfg: SupervisedConfig,
    seed: int = 0,
    log=None,
    progress=None,
) -> list[dict]:
    """Adam on random transitions; validation losses every `log_every` steps."""
    gen = torch.Generator().manual_seed(seed)
    params = list(models.modules().parameters())
    opt = torch.optim.AdamW(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    sched = torch.optim.lr_scheduler.CosineAnnealingLR(opt, cfg.steps)
    T = train.horizon_steps
    history = []
    task = progress.add_task("filter networks (supervised)", total=cfg.steps) if progress else None
    t0 = time.perf_counter()
    for step in range(1, cfg.steps + 1):
        push = torch.randint(len(train), (cfg.batch_size,), generator=gen)
        t = torch.randint(T - 1, (cfg.batch_size,), generator=gen)
        loss, parts = supervised_losses(models, train, push, t, cfg)
        opt.zero_grad()
        loss.backward()
        torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
        opt.step()
        sched.step()
        if progress:
            progress.advance(task)
        if step % cfg.log_every == 0 or step == cfg.steps:
            row = {
                "step": step,
                "train_loss": loss.item(),
                **parts,
                "seconds": time.perf_counter() - t0,
            }
            if val is not None and len(val):
                row.update(evaluate_supervised(models, val, cfg, seed))
            history.append(row)
            if log:
                log(row)
    return history


@torch.no_grad()
def evaluate_supervised(
    models, val: PushTensors, cfg: SupervisedConfig, seed: int = 0, n: int = 2048
) -> dict:
    gen = torch.Generator().manual_seed(seed + 12345)
    push = torch.randint(len(val), (n,), generator=gen)
    t = torch.randint(val.horizon_steps - 1, (n,), generator=gen)
    loss, parts = supervised_losses(models, val, push, t, cfg)
    return {"val_loss": loss.item(), **{f"val_{k}": v for k, v in parts.items()}}
