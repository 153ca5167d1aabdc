"""Differentiable warp of the initial segmentation S_0 by a pose (paper: expected mask Ŝ_t)."""

from __future__ import annotations

import torch
import torch.nn.functional as F

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import ShapeError


def _world_to_norm(camera: CameraModel, dtype, device) -> tuple[torch.Tensor, torch.Tensor]:
    """Affine map world (x, y) → grid_sample coordinates (align_corners=False): n = G p + g."""
    f = camera.focal_px / camera.position[2]
    cu, cv = camera.principal_point
    w, h = camera.width, camera.height
    px, py = camera.position[0], camera.position[1]
    G = torch.tensor([[2 * f / w, 0.0], [0.0, -2 * f / h]], dtype=dtype, device=device)
    g = torch.tensor(
        [(2 * (cu - f * px) + 1) / w - 1, (2 * (cv + f * py) + 1) / h - 1],
        dtype=dtype,
        device=device,
    )
    return G, g


def warp_affine_theta(pose: torch.Tensor, pose0: torch.Tensor, camera: CameraModel) -> torch.Tensor:
    """2×3 matrices for `F.affine_grid` that move the object from pose0 to pose.

    pose, pose0: (B, 3) world (x, y, θ) of the object's geometric frame (m, m, rad).
    Returns (B, 2, 3): for each output pixel, where to sample S_0 (normalised coordinates).
    """
    if pose.ndim != 2 or pose.shape[-1] != 3 or pose0.shape != pose.shape:
        raise ShapeError(
            f"expected pose and pose0 of shape (B, 3), got {tuple(pose.shape)} "
            f"and {tuple(pose0.shape)}"
        )
    G, g = _world_to_norm(camera, pose.dtype, pose.device)
    Ginv = torch.linalg.inv(G)
    dth = pose[:, 2] - pose0[:, 2]
    c, s = torch.cos(-dth), torch.sin(-dth)
    R = torch.stack([torch.stack([c, -s], -1), torch.stack([s, c], -1)], -2)  # (B, 2, 2)
    GR = G @ R  # (B, 2, 2)
    M = GR @ Ginv
    t = pose[:, :2].unsqueeze(-1)
    t0 = pose0[:, :2].unsqueeze(-1)
    off = -(M @ g.view(2, 1)) - GR @ t + G @ t0 + g.view(2, 1)
    return torch.cat([M, off], dim=-1)


def warp_mask(
    mask0: torch.Tensor, pose: torch.Tensor, pose0: torch.Tensor, camera: CameraModel
) -> torch.Tensor:
    """Expected segmentation Ŝ: S_0 (taken at pose0) moved rigidly to pose.

    mask0: (B, 1, H, W) in [0, 1]; pose, pose0: (B, 3). Returns (B, 1, H, W), differentiable
    in pose (bilinear sampling, zeros outside the image).
    """
    if mask0.ndim != 4 or mask0.shape[1] != 1 or mask0.shape[0] != pose.shape[0]:
        raise ShapeError(
            f"expected mask0 of shape (B={pose.shape[0]}, 1, H, W), got {tuple(mask0.shape)}"
        )
    if mask0.shape[-2:] != (camera.height, camera.width):
        raise ShapeError(
            f"mask size {tuple(mask0.shape[-2:])} does not match camera "
            f"({camera.height}, {camera.width})"
        )
    theta = warp_affine_theta(pose, pose0, camera).to(mask0.dtype)
    grid = F.affine_grid(theta, list(mask0.shape), align_corners=False)
    return F.grid_sample(mask0, grid, mode="bilinear", padding_mode="zeros", align_corners=False)


def marker_mask(mask0: torch.Tensor, pose0: torch.Tensor, camera: CameraModel) -> torch.Tensor:
    """Where the orientation marker (the object frame's x ≥ 0 half, see the testbed) lies in
    S_0: the pixels of mask0 (B, 1, H, W) whose centres, in the frame of pose0 (B, 3), have
    x ≥ 0. Returns (B, 1, H, W). Warp it like S_0 to get the expected marker at another pose."""
    if mask0.ndim != 4 or mask0.shape[1] != 1 or pose0.shape != (mask0.shape[0], 3):
        raise ShapeError(
            f"expected mask0 (B, 1, H, W) and pose0 (B, 3), got {tuple(mask0.shape)} "
            f"and {tuple(pose0.shape)}"
        )
    f = camera.focal_px / camera.position[2]
    cu, cv = camera.principal_point
    h, w = mask0.shape[-2:]
    u = torch.arange(w, dtype=mask0.dtype, device=mask0.device)
    v = torch.arange(h, dtype=mask0.dtype, device=mask0.device)
    x = camera.position[0] + (u - cu) / f  # (W,)
    y = camera.position[1] - (v - cv) / f  # (H,)
    dx = x[None, None, :] - pose0[:, 0, None, None].to(mask0.dtype)  # (B, 1, W)
    dy = y[None, :, None] - pose0[:, 1, None, None].to(mask0.dtype)  # (B, H, 1)
    th = pose0[:, 2, None, None].to(mask0.dtype)
    body_x = torch.cos(th) * dx + torch.sin(th) * dy  # (B, H, W)
    return mask0 * (body_x >= 0).to(mask0.dtype)[:, None]
