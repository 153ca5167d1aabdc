"""End-to-end training of the filter's networks through the filter (docs/DESIGN.md §8, second
stage).

Truncated windows: each training example is a window of `window` consecutive steps of one push.
The belief at the window's start is either the *prior* (parameters from the training
catalogue's moments) or a *partially converged* belief (true parameters plus noise of a random
scale, with a matching covariance), the pose being the truth plus noise; the filter then runs
over the window on the recorded observations, and the loss at every step is

    w_pose · NLL(ψ*) + w_param · NLL(φ̃*) + w_pose_mse · ‖μ_ψ - ψ*‖² / L²
    + w_force · ‖TacNet(s*) - F_meas‖² / force_scale²

(NLL of the true pose and parameters under the belief's marginals, the filtered pose's error,
and TacNet's force error at the true state, the last keeping TacNet anchored to the sensor).
Adam, gradient clipping, validation on held-out objects by running whole pushes from the prior.
"""

from __future__ import annotations

import math
import time

import torch
from pydantic import Field

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.filters.base import BeliefFilter
from pushtoknow.filters.gaussian import safe_cholesky
from pushtoknow.models.checkpoint import ParamPrior
from pushtoknow.training.push_tensors import PushTensors
from pushtoknow.training.supervised import observation, push_context


class EndToEndConfig(Config):
    steps: int = Field(300, ge=0)
    batch_size: int = Field(16, ge=1)
    window: int = Field(8, ge=1, description="filter steps per truncated window")
    num_sigma_points: int = Field(32, ge=MIN_SIGMA_POINTS)
    lr: float = Field(3e-4, gt=0)
    weight_decay: float = Field(1e-5, ge=0)
    grad_clip: float = Field(1.0, gt=0)
    pose_nll_weight: float = Field(0.1, ge=0)
    param_nll_weight: float = Field(1.0, ge=0)
    pose_mse_weight: float = Field(1.0, ge=0)
    pose_length_scale: float = Field(
        0.1, gt=0, description="m per unit of position error in the pose MSE (angles in rad)"
    )
    force_weight: float = Field(1.0, ge=0)
    prior_start_fraction: float = Field(
        0.5, ge=0, le=1, description="share of windows starting from the catalogue prior"
    )
    converged_std: tuple[float, float] = Field(
        (0.03, 0.3), description="range of the normalised parameter std of converged starts"
    )
    init_pose_std: tuple[float, float, float] = Field(
        (0.002, 0.002, 0.03), description="pose std at a window's start (m, m, rad)"
    )
    val_every: int = Field(50, ge=1)
    val_pushes: int = Field(32, ge=1, description="validation pushes (whole, from the prior)")
    val_num_sigma_points: int = Field(32, ge=MIN_SIGMA_POINTS)


def gaussian_nll(residual: torch.Tensor, cov: torch.Tensor) -> torch.Tensor:
    """-log N(residual; 0, cov) per batch element: residual (B, K), cov (B, K, K) → (B,)."""
    chol = safe_cholesky(cov)
    return -torch.distributions.MultivariateNormal(
        torch.zeros_like(residual), scale_tril=chol
    ).log_prob(residual)


def pose_error(mean: torch.Tensor, pose: torch.Tensor) -> torch.Tensor:
    """Belief mean's pose minus the true pose (B, 3) (m, m, rad; angle wrapped)."""
    return torch.cat([mean[:, :2] - pose[:, :2], wrap_angle(mean[:, 2:3] - pose[:, 2:3])], -1)


def belief_losses(
    mean: torch.Tensor, cov: torch.Tensor, pose: torch.Tensor, params: torch.Tensor, p: int = 3
) -> dict[str, torch.Tensor]:
    """NLL of the true pose (B, 3) and parameters (B, K) under the belief, each (B,)."""
    dpose = pose_error(mean, pose)
    return {
        "pose_nll": gaussian_nll(dpose, cov[:, :p, :p]),
        "param_nll": gaussian_nll(mean[:, p:] - params, cov[:, p:, p:]),
        "pose_err": dpose,
    }


def initial_belief(
    pose: torch.Tensor,
    params: torch.Tensor,
    prior: ParamPrior,
    cfg: EndToEndConfig,
    gen: torch.Generator,
    from_prior: torch.Tensor,
) -> tuple[torch.Tensor, torch.Tensor]:
    """Belief (mean (B, D), cov (B, D, D)) at a window's start; from_prior (B,) bool."""
    b, k = params.shape
    pose_std = torch.tensor(cfg.init_pose_std)
    mean_pose = pose + torch.randn(b, 3, generator=gen) * pose_std
    lo, hi = cfg.converged_std
    std = lo + (hi - lo) * torch.rand(b, 1, generator=gen)
    conv_mean = params + std * torch.randn(b, k, generator=gen)
    conv_cov = torch.diag_embed(std.expand(b, k).square())
    fp = from_prior.view(b, 1)
    mean_par = torch.where(fp, prior.mean.expand(b, k), conv_mean)
    cov_par = torch.where(fp.unsqueeze(-1), prior.cov.expand(b, k, k), conv_cov)
    mean = torch.cat([mean_pose, mean_par], -1)
    cov = torch.zeros(b, 3 + k, 3 + k)
    cov[:, :3, :3] = torch.diag(pose_std.square())
    cov[:, 3:, 3:] = cov_par
    return mean, cov


def run_window(
    filt: BeliefFilter,
    pt: PushTensors,
    push: torch.Tensor,
    t0: torch.Tensor | int,
    steps: int,
    mean: torch.Tensor,
    cov: torch.Tensor,
    gen: torch.Generator,
    num_sigma_points: int,
    vision_only: bool,
    update_every: int = 1,
):
    """Filter `steps` steps of pushes `push` from sample t0; yields (t, mean, cov) after each.

    t0 is one start sample for the whole batch (an int) or one per push (B,) tensor. The
    measurement update runs at every `update_every`-th step (and the last), prediction at all."""
    b = len(push)
    t0 = torch.as_tensor(t0).expand(b) if not isinstance(t0, int) else torch.full((b,), t0)
    for k in range(steps):
        t = t0 + k + 1
        ctx = push_context(pt, push, t)
        z = observation(pt, push, t, tactile=not vision_only)
        noise = filt.draw_noise(b, gen, mean.dtype, num_sigma_points=num_sigma_points)
        if (k + 1) % update_every == 0 or k == steps - 1:
            mean, cov, _ = filt(mean, cov, z, ctx, noise)
        else:
            mean, cov = filt.predict(mean, cov, ctx, noise)
        yield t, mean, cov


def window_loss(
    filt: BeliefFilter,
    pt: PushTensors,
    push: torch.Tensor,
    t0: torch.Tensor,
    prior: ParamPrior,
    cfg: EndToEndConfig,
    gen: torch.Generator,
    vision_only: bool,
    force_fn=None,
) -> tuple[torch.Tensor, dict]:
    """Loss of one batch of windows (see module docstring) and its parts (floats)."""
    b = len(push)
    from_prior = torch.rand(b, generator=gen) < cfg.prior_start_fraction
    params = pt.params_norm[push]
    mean0, cov0 = initial_belief(pt.pose[push, t0], params, prior, cfg, gen, from_prior)
    parts = {"pose_nll": 0.0, "param_nll": 0.0, "pose_mse": 0.0}
    total = torch.zeros(())
    for t, mean, cov in run_window(
        filt, pt, push, t0, cfg.window, mean0, cov0, gen, cfg.num_sigma_points, vision_only
    ):
        truth = pt.pose[push, t]
        losses = belief_losses(mean, cov, truth, params)
        err = losses["pose_err"]
        mse = ((err[:, :2] / cfg.pose_length_scale).square().sum(-1) + err[:, 2].square()).mean()
        step = (
            cfg.pose_nll_weight * losses["pose_nll"].mean()
            + cfg.param_nll_weight * losses["param_nll"].mean()
            + cfg.pose_mse_weight * mse
        )
        total = total + step / cfg.window
        parts["pose_nll"] += losses["pose_nll"].mean().item() / cfg.window
        parts["param_nll"] += losses["param_nll"].mean().item() / cfg.window
        parts["pose_mse"] += mse.item() / cfg.window
    if force_fn is not None and cfg.force_weight > 0:
        f = force_fn(push, t0 + 1)
        total = total + cfg.force_weight * f
        parts["force_mse"] = f.item()
    return total, parts


@torch.no_grad()
def evaluate_filter(
    filt: BeliefFilter,
    pt: PushTensors,
    prior: ParamPrior,
    num_sigma_points: int,
    vision_only: bool,
    seed: int = 0,
    max_pushes: int | None = None,
    batch: int = 64,
    update_every: int = 1,
) -> dict:
    """Whole pushes from the prior (pose from the truth at t = 0): parameter RMSE (normalised
    units) and NLL of the true parameters at the end, pose RMSE over the push."""
    gen = torch.Generator().manual_seed(seed)
    n = len(pt) if max_pushes is None else min(max_pushes, len(pt))
    start = EndToEndConfig(init_pose_std=(1e-3, 1e-3, 0.01))
    sq, nll, pose_sq, prior_sq, z90 = [], [], [], [], []
    for i in range(0, n, batch):
        push = torch.arange(i, min(i + batch, n))
        b = len(push)
        params = pt.params_norm[push]
        mean0, cov0 = initial_belief(
            pt.pose[push, 0], params, prior, start, gen, torch.ones(b, dtype=torch.bool)
        )
        errs = []
        steps = pt.horizon_steps - 1
        for t, mean, cov in run_window(  # noqa: B007 (the last belief is used below)
            filt, pt, push, 0, steps, mean0, cov0, gen, num_sigma_points, vision_only, update_every
        ):
            errs.append(pose_error(mean, pt.pose[push, t]))
        final = belief_losses(mean, cov, pt.pose[push, -1], params)
        sq.append((mean[:, 3:] - params).square())
        prior_sq.append((prior.mean - params).square())
        nll.append(final["param_nll"])
        z90.append(_inside90(mean[:, 3:] - params, cov[:, 3:, 3:]))
        pose_sq.append(torch.stack(errs).square().mean(0))
    sq, prior_sq, pose_sq = torch.cat(sq), torch.cat(prior_sq), torch.cat(pose_sq)
    return {
        "param_rmse": sq.mean(0).sqrt().tolist(),
        "param_rmse_mean": float(sq.mean(0).sqrt().mean()),
        "prior_param_rmse_mean": float(prior_sq.mean(0).sqrt().mean()),
        "param_nll": float(torch.cat(nll).mean()),
        "param_nll_median": float(torch.cat(nll).median()),
        "coverage90": float(torch.cat(z90).float().mean()),
        "pose_xy_rmse_mm": float(pose_sq[:, :2].sum(-1).mean().sqrt() * 1e3),
        "pose_theta_rmse_deg": float(pose_sq[:, 2].mean().sqrt() * 180 / math.pi),
    }


def _inside90(err: torch.Tensor, cov: torch.Tensor) -> torch.Tensor:
    """(B, K) bool: |err| inside each marginal's central 90% interval."""
    std = torch.diagonal(cov, dim1=-2, dim2=-1).clamp_min(0).sqrt()
    return err.abs() <= 1.6449 * std


def train_end_to_end(
    filt: BeliefFilter,
    train: PushTensors,
    val: PushTensors | None,
    prior: ParamPrior,
    cfg: EndToEndConfig,
    vision_only: bool,
    seed: int = 0,
    force_fn=None,
    log=None,
    progress=None,
) -> tuple[list[dict], dict | None]:
    """Adam through the filter on random windows; keeps the weights with the best validation
    parameter RMSE (returns (history, best validation row)); `force_fn(push, t) → loss` adds
    TacNet's supervised force term."""
    gen = torch.Generator().manual_seed(seed)
    params = [p for p in filt.parameters() if p.requires_grad]
    opt = torch.optim.Adam(params, lr=cfg.lr, weight_decay=cfg.weight_decay)
    T = train.horizon_steps
    history: list[dict] = []
    best, best_state = None, None

    def validate(step: int, row: dict) -> None:
        nonlocal best, best_state
        if val is None or not len(val):
            return
        filt.eval()
        res = evaluate_filter(
            filt, val, prior, cfg.val_num_sigma_points, vision_only, seed, cfg.val_pushes
        )
        filt.train()
        row.update({f"val_{k}": v for k, v in res.items() if not isinstance(v, list)})
        if best is None or res["param_rmse_mean"] < best["val_param_rmse_mean"]:
            best = {"step": step, **{f"val_{k}": v for k, v in res.items()}}
            best_state = {k: v.detach().clone() for k, v in filt.state_dict().items()}

    row0: dict = {"step": 0}
    validate(0, row0)
    history.append(row0)
    if log:
        log(row0)
    task = progress.add_task("filter networks (end to end)", total=cfg.steps) if progress else None
    t_start = time.perf_counter()
    for step in range(1, cfg.steps + 1):
        push = torch.randint(len(train), (cfg.batch_size,), generator=gen)
        t0 = torch.randint(T - cfg.window, (cfg.batch_size,), generator=gen)
        loss, parts = window_loss(filt, train, push, t0, prior, cfg, gen, vision_only, force_fn)
        opt.zero_grad()
        loss.backward()
        grads_ok = all(p.grad is None or torch.isfinite(p.grad).all() for p in params)
        if grads_ok:
            torch.nn.utils.clip_grad_norm_(params, cfg.grad_clip)
            opt.step()
        if progress:
            progress.advance(task)
        if step % cfg.val_every == 0 or step == cfg.steps:
            row = {
                "step": step,
                "train_loss": loss.item(),
                **parts,
                "skipped_nonfinite": int(not grads_ok),
                "seconds": time.perf_counter() - t_start,
            }
            validate(step, row)
            history.append(row)
            if log:
                log(row)
    if best_state is not None:
        filt.load_state_dict(best_state)
    return history, best
