"""How the learned models see a sigma point: the shape-action encoding and the features.

State s = (x, y, θ, φ̃) (B, C, 8): pose of the geometric frame (m, m, rad), normalised
parameters. Per sigma point the models build

* the encoder input [Ŝ, M]: S_0 warped to the sigma point's pose (`geometry.warp`) and the
  action map of the push (`geometry.action_maps`), optionally cropped around the object;
* features (x - x0, y - y0) / L, sin(θ - θ0), cos(θ - θ0), φ̃, the deviation
  (δx / L, δy / L, δθ) of the point's pose from the pose the encoding was computed at, and the
  pad in the point's object frame: its position / L, the push direction (sin, cos) and the
  speed / `SPEED_SCALE` (12 + param_dim values, L = `length_scale`). The pad's pose is known
  exactly from the robot's kinematics; giving it explicitly spares the networks from reading
  millimetres off a 9 mm/pixel action map.

Encoder modes (`EncodingConfig.mode`):
* "per_sigma" (the paper): one encoding per sigma point; the deviation features are zero.
* "mean": one encoding per object and call, at the mean pose of the points passed in; each
  point's offset from that pose goes to ProcessNet/TacNet through the deviation features.
  ~70× fewer conv evaluations per filter step (3 instead of ~207 at C = 100).

The black-box models (`models.learned`) and the physics-structured ones (`models.physics`)
share both.
"""

from __future__ import annotations

from typing import Literal

import torch
import torch.nn.functional as F
from torch import nn

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.frozen_config import Config
from pushtoknow.geometry.action_maps import ActionMapConfig
from pushtoknow.geometry.warp import warp_affine_theta, warp_mask
from pushtoknow.models.context import PushContext
from pushtoknow.models.networks import ShapeActionEncoderNet

POSE_DIM = 3
NUM_POSE_FEATURES = 12  # (x - x0)/L, (y - y0)/L, sin, cos, δx/L, δy/L, δθ, pad (5)
SPEED_SCALE = 0.1  # m/s, normalises the push speed feature


class EncodingConfig(Config):
    """How sigma points are encoded. mode: see module docstring. crop_size: side (px) of the
    encoder input window centred on the object (None: the whole image); the encoder's
    image_size must equal it (or the camera's size when None). length_scale (m) normalises
    positions in the features."""

    mode: Literal["per_sigma", "mean"] = "mean"
    crop_size: int | None = 32
    length_scale: float = 0.1
    action_map: ActionMapConfig = ActionMapConfig()


def _world_to_grid(xy: torch.Tensor, camera: CameraModel) -> torch.Tensor:
    """World (N, 2) → `grid_sample` coordinates (align_corners=False) of the camera image."""
    f = camera.focal_px / camera.position[2]
    cu, cv = camera.principal_point
    u = cu + f * (xy[:, 0] - camera.position[0])
    v = cv - f * (xy[:, 1] - camera.position[1])
    return torch.stack([(2 * u + 1) / camera.width - 1, (2 * v + 1) / camera.height - 1], -1)


class ShapeActionEncoding(nn.Module):
    """ShapeActionEncoderNet applied to [Ŝ(pose), M_t], shared by the dynamics and observation
    models (one set of weights)."""

    def __init__(self, encoder: ShapeActionEncoderNet, config: EncodingConfig = EncodingConfig()):
        super().__init__()
        self.encoder = encoder
        self.config = config

    def images(self, pose: torch.Tensor, context: PushContext, amap: torch.Tensor) -> torch.Tensor:
        """Encoder input (N, 2, S, S) for poses (N, 3); rows of context tensors and `amap`
        (N, 1, H, W) already repeated to N."""
        cam, crop = context.camera, self.config.crop_size
        n = pose.shape[0]
        mask0 = context.mask0.to(pose.dtype)
        pose0 = context.pose0.to(pose.dtype)
        if crop is None:
            return torch.cat([warp_mask(mask0, pose, pose0, cam), amap], dim=1)
        centre = _world_to_grid(pose[:, :2], cam)  # (N, 2)
        scale = pose.new_tensor([crop / cam.width, crop / cam.height])
        crop_theta = torch.cat([torch.diag_embed(scale.expand(n, 2)), centre.unsqueeze(-1)], -1)
        full = warp_affine_theta(pose, pose0, cam)  # (N, 2, 3): output → S_0 coordinates
        mask_theta = torch.cat(
            [
                full[..., :2] @ crop_theta[..., :2],
                full[..., :2] @ crop_theta[..., 2:] + full[..., 2:],
            ],
            dim=-1,
        )
        size = [n, 1, crop, crop]
        grid_mask = F.affine_grid(mask_theta, size, align_corners=False)
        grid_amap = F.affine_grid(crop_theta, size, align_corners=False)
        s_hat = F.grid_sample(
            mask0, grid_mask, mode="bilinear", padding_mode="zeros", align_corners=False
        )
        m_crop = F.grid_sample(
            amap, grid_amap, mode="bilinear", padding_mode="zeros", align_corners=False
        )
        return torch.cat([s_hat, m_crop], dim=1)

    def forward(
        self, pose: torch.Tensor, context: PushContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """pose (B, S, 3) → (enc, anchor): encodings (B, S, E) and the pose each was computed at
        (B, S, 3); in "mean" mode (B, 1, E) and (B, 1, 3), to broadcast over the points."""
        b, s, _ = pose.shape
        amap = context.action_map(self.config.action_map, pose.dtype)
        if self.config.mode == "per_sigma":
            flat = pose.reshape(b * s, 3)
            ctx = context.repeat_interleave(s)
            imgs = self.images(flat, ctx, amap.repeat_interleave(s, dim=0))
            return self.encoder(imgs).view(b, s, -1), pose
        anchor = pose.mean(dim=1)  # (B, 3)
        enc = self.encoder(self.images(anchor, context, amap))
        return enc.unsqueeze(1), anchor.unsqueeze(1)


def sigma_point_features(
    states: torch.Tensor,
    pose0: torch.Tensor,
    anchor: torch.Tensor,
    length_scale: float,
    context: PushContext | None = None,
) -> torch.Tensor:
    """Network features (B, S, 12 + K) of states (B, S, 3 + K); pose0 (B, 3), anchor (B, S or
    1, 3). The pad features come from context.contact_xy (the pad's position), direction and
    speed (zeros without a context)."""
    pose0 = pose0.to(states.dtype).unsqueeze(1)
    rel = (states[..., :2] - pose0[..., :2]) / length_scale
    dth = states[..., 2] - pose0[..., 2]
    dev = states[..., :3] - anchor
    if context is None:
        pad = states.new_zeros(*states.shape[:-1], 5)
    else:
        th = states[..., 2]
        c, s = th.cos(), th.sin()
        d = context.contact_xy.to(states.dtype).unsqueeze(1) - states[..., :2]
        px = (c * d[..., 0] + s * d[..., 1]) / length_scale
        py = (-s * d[..., 0] + c * d[..., 1]) / length_scale
        pd = context.direction.to(states.dtype).unsqueeze(1) - th
        v = (context.speed.to(states.dtype) / SPEED_SCALE).unsqueeze(1).expand_as(px)
        pad = torch.stack([px, py, pd.sin(), pd.cos(), v], dim=-1)
    return torch.cat(
        [
            rel,
            dth.sin().unsqueeze(-1),
            dth.cos().unsqueeze(-1),
            states[..., 3:],
            dev[..., :2] / length_scale,
            dev[..., 2:],
            pad,
        ],
        dim=-1,
    )
