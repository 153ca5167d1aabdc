"""Action map M_t (paper appendix): an anisotropic 2-D Gaussian at the contact point in the image.

The Gaussian is elongated along the push direction pd. Pixel scaling (documented choice):
the across-push standard deviation is `across_std_px` pixels at 64 px image width (scaled
linearly with the width); the along-push standard deviation is
`across_std_px · (1 + v / speed_ref)`, so faster pushes spread further ahead. With the
appendix's precision matrix K this is K = Rᵀ diag(1/σ_along², 1/σ_across²) R / 1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import ShapeError


@dataclass(frozen=True)
class ActionMapConfig:
    across_std_px: float = 1.5  # at a 64-pixel-wide image
    speed_ref: float = 0.1  # m/s


def action_map(
    contact_xy: torch.Tensor,
    direction: torch.Tensor,
    speed: torch.Tensor,
    camera: CameraModel,
    config: ActionMapConfig = ActionMapConfig(),
) -> torch.Tensor:
    """Render action maps.

    contact_xy: (B, 2) world contact point (m); direction: (B,) push direction pd (rad, world);
    speed: (B,) push speed v (m/s). Returns (B, 1, H, W) with peak value 1 at the contact pixel.
    """
    if contact_xy.ndim != 2 or contact_xy.shape[-1] != 2:
        raise ShapeError(f"expected contact_xy (B, 2), got {tuple(contact_xy.shape)}")
    B = contact_xy.shape[0]
    if direction.shape != (B,) or speed.shape != (B,):
        raise ShapeError(
            f"expected direction and speed of shape ({B},), got {tuple(direction.shape)} "
            f"and {tuple(speed.shape)}"
        )
    dtype, dev = contact_xy.dtype, contact_xy.device
    f = camera.focal_px / camera.position[2]
    cu, cv = camera.principal_point
    u0 = cu + f * (contact_xy[:, 0] - camera.position[0])
    v0 = cv - f * (contact_xy[:, 1] - camera.position[1])
    s_across = config.across_std_px * camera.width / 64.0
    s_along = s_across * (1.0 + speed / config.speed_ref)
    # Push direction in pixel axes: image v grows with world -y.
    du, dv = torch.cos(direction), -torch.sin(direction)
    uu = torch.arange(camera.width, dtype=dtype, device=dev).view(1, 1, -1)
    vv = torch.arange(camera.height, dtype=dtype, device=dev).view(1, -1, 1)
    ru = uu - u0.view(B, 1, 1)
    rv = vv - v0.view(B, 1, 1)
    along = ru * du.view(B, 1, 1) + rv * dv.view(B, 1, 1)
    across = -ru * dv.view(B, 1, 1) + rv * du.view(B, 1, 1)
    q = (along / s_along.view(B, 1, 1)) ** 2 + (across / s_across) ** 2
    return torch.exp(-0.5 * q).unsqueeze(1)


def action_map_np(contact_xy, direction, speed, camera: CameraModel, config=ActionMapConfig()):
    """numpy convenience wrapper around `action_map` for a single push → (H, W) float32."""
    m = action_map(
        torch.as_tensor(np.asarray(contact_xy, dtype=np.float32)).view(1, 2),
        torch.tensor([float(direction)]),
        torch.tensor([float(speed)]),
        camera,
        config,
    )
    return m[0, 0].numpy()
