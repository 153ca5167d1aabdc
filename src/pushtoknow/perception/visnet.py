"""VisNet as a render-and-compare pose sensor at run time (docs/DESIGN.md §5, §9): its inputs
from RGB-D frames and S_0, and the pose measurement. Used by inference and by training (which
fits the network, `training.fit_visnet`).

VisNet sees the current RGB-D image and S_0 warped to a *reference pose* (at inference the
filter's predicted mean; in training the true pose perturbed by noise) and outputs the pose of
the object relative to that reference, (Δx, Δy, sin Δθ, cos Δθ). Depth enters as height above
the table in units of the object thickness.
"""

from __future__ import annotations

import numpy as np
import torch
import torch.nn.functional as F

from pushtoknow.common.camera import CameraModel
from pushtoknow.geometry.affordances import mask_contour
from pushtoknow.geometry.warp import marker_mask, warp_mask
from pushtoknow.models.networks import VisNet
from pushtoknow.testbed.objects import DEFAULT_HEIGHT


def rgbd_input(rgb: torch.Tensor, depth: torch.Tensor, camera: CameraModel) -> torch.Tensor:
    """rgb (N, 3, H, W) in [0, 1] and depth (N, 1, H, W) metres → VisNet's (N, 4, H, W)."""
    height = (camera.position[2] - depth) / DEFAULT_HEIGHT
    return torch.cat([rgb, height], dim=1)


def visnet_inputs(rgbd, mask0, pose0, ref, camera: CameraModel, crop: int, marker=False):
    """VisNet's inputs: a crop×crop window (native resolution) centred on the reference
    position of [RGB, height, height − Ŝ_ref] (the last channel shows the misalignment, which
    makes small rotations visible), plus, with `marker`, where the orientation marker should
    be at the reference pose (`marker_mask` warped like S_0), and Ŝ_ref: S_0 warped to the
    reference pose."""
    s_ref = warp_mask(mask0, ref, pose0, camera)
    parts = [rgbd, rgbd[:, 3:4].clamp(0, 1) - s_ref]
    if marker:
        parts.append(warp_mask(marker_mask(mask0, pose0, camera), ref, pose0, camera))
    x = torch.cat([*parts, s_ref], dim=1)
    n = x.shape[0]
    f = camera.focal_px / camera.position[2]
    cu, cv = camera.principal_point
    u = cu + f * (ref[:, 0] - camera.position[0])
    v = cv - f * (ref[:, 1] - camera.position[1])
    centre = torch.stack([(2 * u + 1) / camera.width - 1, (2 * v + 1) / camera.height - 1], -1)
    scale = torch.tensor([crop / camera.width, crop / camera.height], dtype=x.dtype)
    theta = torch.cat([torch.diag_embed(scale.expand(n, 2)), centre[:, :, None]], -1)
    grid = F.affine_grid(theta, [n, x.shape[1], crop, crop], align_corners=False)
    w = F.grid_sample(x, grid, mode="bilinear", padding_mode="zeros", align_corners=False)
    return w[:, :-1], w[:, -1:]


def net_inputs(net: VisNet, rgbd, mask0, pose0, ref, camera):
    c = net.config
    return visnet_inputs(rgbd, mask0, pose0, ref, camera, c.image_size, c.marker_channel)


@torch.no_grad()
def visnet_measure(net: VisNet, rgbd, mask0, pose0, ref, camera) -> torch.Tensor:
    """Pose measurement (N, 3) = reference ⊕ VisNet residual."""
    rel = net(*net_inputs(net, rgbd, mask0, pose0, ref, camera))
    return VisNet.to_pose(rel, ref)


def frames_as_tensors(rgb: np.ndarray, depth: np.ndarray, camera: CameraModel) -> torch.Tensor:
    """(T, H, W, 3) uint8 and (T, H, W) float → (T, 4, H, W) VisNet input."""
    r = torch.as_tensor(rgb).permute(0, 3, 1, 2).float() / 255.0
    d = torch.as_tensor(depth, dtype=torch.float32)[:, None]
    return rgbd_input(r, d, camera)


@torch.no_grad()
def start_pose(
    net: VisNet,
    camera: CameraModel,
    view,
    initial_pose: np.ndarray | None,
    previous: tuple[np.ndarray, np.ndarray, np.ndarray] | None,
) -> np.ndarray:
    """(3,) the object's pose (x, y, θ) at a push's start, seen in `view`
    (`testbed.executor.View`). Before the first push (`previous` None) the given initial pose,
    which defines the object frame, or S_0's centroid with θ = 0; later VisNet's measurement
    against the previous push's S_0 at its start pose, about the previous push's last pose
    moved by the executor's re-centring. previous: (S_0 (H, W), pose0 (3,), last pose (3,))."""
    if previous is None:
        if initial_pose is not None:
            return np.asarray(initial_pose, dtype=float)
        c = mask_contour(view.s0, camera).centroid
        return np.array([c[0], c[1], 0.0])
    s0_prev, pose0_prev, last_pose = previous
    ref = np.array(last_pose, dtype=np.float64)
    if view.moved_by is not None:
        ref[:2] += np.asarray(view.moved_by)
    return visnet_poses(net, camera, view.rgb[None], view.depth[None], s0_prev, pose0_prev, ref)[0]


@torch.no_grad()
def visnet_poses(net: VisNet, camera: CameraModel, rgb, depth, s0, pose0, ref) -> np.ndarray:
    """VisNet's poses (N, 3) (x, y, θ) of frames rgb (N, H, W, 3) uint8, depth (N, H, W) m,
    against the mask S_0 (H, W) taken at pose0 (3,), about reference poses ref (N, 3) or (3,)."""
    frames = frames_as_tensors(rgb, depth, camera)
    n = len(frames)
    mask0 = torch.as_tensor(s0, dtype=torch.float32)[None, None].expand(n, -1, -1, -1)
    p0 = torch.as_tensor(pose0, dtype=torch.float32)[None].expand(n, -1)
    r = torch.as_tensor(np.broadcast_to(ref, (n, 3)).copy(), dtype=torch.float32)
    return visnet_measure(net, frames, mask0, p0, r, camera).double().numpy()
