"""VisNet as a render-and-compare pose sensor, trained supervised (docs/DESIGN.md §8, first stage).

VisNet sees the current RGB-D image and S_0 warped to a *reference pose* (at inference the
filter's predicted mean; in training the true pose perturbed by noise) and outputs the pose of
the object relative to that reference, (Δx, Δy, sin Δθ, cos Δθ). Because the residual is small
(well below half of any shape's symmetry angle), symmetric shapes (rectangles, ellipses, hex)
need no special treatment and the ±π wrap never arises. Without the testbed's orientation
marker a disc's rotation is invisible: VisNet learns Δθ ≈ 0 there, i.e. the measurement carries
no information about θ. With the marker (`SimConfig.orientation_marker`, on by default) VisNet
also sees where the marker should be at the reference pose and every shape's θ is visible.
Depth enters as height above the table in units of the object thickness.
"""

from __future__ import annotations

import math
import time
from dataclasses import asdict, dataclass

import torch
from pydantic import Field

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.frozen_config import Config
from pushtoknow.models.networks import VisNet, VisNetConfig
from pushtoknow.perception.visnet import net_inputs, visnet_measure


class VisNetTrainConfig(Config):
    epochs: int = Field(6, ge=1)
    batch_size: int = Field(128, ge=1)
    lr: float = Field(2e-3, gt=0)
    weight_decay: float = Field(1e-5, ge=0)
    ref_noise_xy: float = Field(0.01, ge=0, description="std of the reference offset (m)")
    ref_noise_theta: float = Field(0.15, ge=0, description="std of the reference turn (rad)")
    ref_noise_theta_max: float = Field(0.45, gt=0, description="clip (rad) < π/6 (hex)")
    frame_every: int = Field(5, ge=1, description="use every n-th frame of each push")
    val_fraction: float = Field(0.1, ge=0, lt=1)
    position_weight: float = Field(1.0, gt=0)
    net: VisNetConfig = VisNetConfig(
        in_channels=6, image_size=32, channels=(32, 32, 64, 64), strides=(1, 2, 2, 2)
    )


def perturb(pose: torch.Tensor, cfg: VisNetTrainConfig, gen: torch.Generator) -> torch.Tensor:
    """Reference poses: pose (N, 3) plus Gaussian noise (θ clipped)."""
    n = pose.shape[0]
    dxy = torch.randn(n, 2, generator=gen) * cfg.ref_noise_xy
    dth = (torch.randn(n, generator=gen) * cfg.ref_noise_theta).clamp(
        -cfg.ref_noise_theta_max, cfg.ref_noise_theta_max
    )
    return pose + torch.cat([dxy, dth[:, None]], 1)


def visnet_loss(net: VisNet, rgbd, mask0, pose, pose0, ref, camera, position_weight=1.0):
    """MSE between VisNet's relative pose and the truth relative to the reference."""
    out = net(*net_inputs(net, rgbd, mask0, pose0, ref, camera))
    target = VisNet.pose_to_target(pose, ref)
    scale = net.config.position_scale
    pos = ((out[:, :2] - target[:, :2]) / scale).square().sum(-1)
    ang = (out[:, 2:] - target[:, 2:]).square().sum(-1)
    return (position_weight * pos + ang).mean()


@dataclass
class VisNetResult:
    net: VisNet
    history: list[dict]
    val_error: dict


def train_visnet(
    frames, camera: CameraModel, cfg: VisNetTrainConfig, seed: int = 0, log=None, progress=None
) -> VisNetResult:
    """frames = (rgbd (F,4,H,W), mask0 (F,1,H,W), pose (F,3), pose0 (F,3), push id (F,)).

    Validation split by push (no frame of a validation push is trained on).
    """
    rgbd, mask0, pose, pose0, pid = frames
    torch.manual_seed(seed)
    gen = torch.Generator().manual_seed(seed)
    pushes = torch.unique(pid)
    perm = pushes[torch.randperm(len(pushes), generator=gen)]
    n_val = int(round(cfg.val_fraction * len(pushes)))
    val_mask = torch.isin(pid, perm[:n_val])
    tr = torch.nonzero(~val_mask).squeeze(1)
    va = torch.nonzero(val_mask).squeeze(1)
    net = VisNet(cfg.net)
    opt = torch.optim.AdamW(net.parameters(), lr=cfg.lr, weight_decay=cfg.weight_decay)
    steps = cfg.epochs * math.ceil(len(tr) / cfg.batch_size)
    sched = torch.optim.lr_scheduler.OneCycleLR(opt, cfg.lr, total_steps=steps)
    val_gen = torch.Generator().manual_seed(seed + 1)
    val_ref = perturb(pose[va], cfg, val_gen)
    history = []
    task = progress.add_task("VisNet", total=steps) if progress else None
    for epoch in range(cfg.epochs):
        net.train()
        t0 = time.perf_counter()
        order = tr[torch.randperm(len(tr), generator=gen)]
        total = 0.0
        for i in range(0, len(order), cfg.batch_size):
            b = order[i : i + cfg.batch_size]
            ref = perturb(pose[b], cfg, gen)
            loss = visnet_loss(
                net, rgbd[b], mask0[b], pose[b], pose0[b], ref, camera, cfg.position_weight
            )
            opt.zero_grad()
            loss.backward()
            opt.step()
            sched.step()
            total += loss.item() * len(b)
            if progress:
                progress.advance(task)
        err = evaluate_visnet(net, rgbd[va], mask0[va], pose[va], pose0[va], val_ref, camera)
        row = {
            "epoch": epoch + 1,
            "train_loss": total / max(len(tr), 1),
            "seconds": time.perf_counter() - t0,
            **{f"val_{k}": v for k, v in ({} if err is None else err.to_json()).items()},
        }
        history.append(row)
        if log:
            log(row)
    net.eval()
    return VisNetResult(net, history, history[-1] if history else {})


@dataclass(frozen=True)
class VisNetPoseError:
    """VisNet's pose error against the truth (`evaluate_visnet`): RMS position error (mm) and
    median |θ error| (deg) of its measurements (`xy_rmse_mm`, `theta_med_deg`) and of the
    reference poses it was given (`ref_xy_rmse_mm`, `ref_theta_med_deg`: what VisNet must
    beat). Training stores them per epoch with a `val_` prefix."""

    xy_rmse_mm: float
    theta_med_deg: float
    ref_xy_rmse_mm: float
    ref_theta_med_deg: float

    def to_json(self) -> dict:
        return asdict(self)


@torch.no_grad()
def evaluate_visnet(
    net, rgbd, mask0, pose, pose0, ref, camera, batch=512
) -> VisNetPoseError | None:
    """VisNet's measurements of the frames (rgbd (F,4,H,W), mask0 (F,1,H,W), pose0 (F,3),
    references ref (F,3)) against the true poses `pose` (F,3), in batches of `batch` frames
    (see `VisNetPoseError`); None without frames."""
    if len(pose) == 0:
        return None
    net.eval()
    meas = torch.cat(
        [
            visnet_measure(
                net,
                rgbd[i : i + batch],
                mask0[i : i + batch],
                pose0[i : i + batch],
                ref[i : i + batch],
                camera,
            )
            for i in range(0, len(pose), batch)
        ]
    )

    def errs(p):
        d = (p[:, :2] - pose[:, :2]).norm(dim=-1)
        dth = torch.remainder(p[:, 2] - pose[:, 2] + math.pi, 2 * math.pi) - math.pi
        return float(d.square().mean().sqrt() * 1e3), float(dth.abs().median() * 180 / math.pi)

    m_xy, m_th = errs(meas)
    r_xy, r_th = errs(ref)
    net.train()
    return VisNetPoseError(
        xy_rmse_mm=m_xy, theta_med_deg=m_th, ref_xy_rmse_mm=r_xy, ref_theta_med_deg=r_th
    )
