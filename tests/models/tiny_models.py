"""Tiny learned models on a 16 px camera for fast tests (helpers, not tests)."""

from __future__ import annotations

import torch

from pushtoknow.common.camera import CameraModel
from pushtoknow.models import (
    EncoderConfig,
    EncodingConfig,
    LearnedModelsConfig,
    ObsNoiseNetConfig,
    ProcessNetConfig,
    PushContext,
    TacNetConfig,
)

CAMERA = CameraModel(width=16, height=16)
HALF_SIDE = 0.045  # m, square object


def tiny_config(mode: str = "mean", crop: int | None = 8) -> LearnedModelsConfig:
    size = crop or CAMERA.width
    return LearnedModelsConfig(
        encoding=EncodingConfig(mode=mode, crop_size=crop),
        encoder=EncoderConfig(
            image_size=size, channels=(2, 2, 2), kernel_sizes=(3, 3, 3), hidden_dim=4, out_dim=3
        ),
        process=ProcessNetConfig(enc_dim=3, hidden_dims=(4, 4)),
        tac=TacNetConfig(enc_dim=3, hidden_dims=(4, 4, 4)),
        obs_noise=ObsNoiseNetConfig(hidden_dim=4),
    )


def square_context(batch: int, dtype=torch.float32, camera: CameraModel = CAMERA) -> PushContext:
    """A 9 cm square at the origin, pushed along +x from its left side at 5 cm/s."""
    px = torch.arange(camera.width, dtype=torch.float64)
    x = (px - camera.principal_point[0]) * camera.metres_per_pixel()
    inside = (x.abs() <= HALF_SIDE + 0.5 * camera.metres_per_pixel()).to(dtype)
    mask = (inside.view(-1, 1) * inside.view(1, -1)).expand(batch, 1, -1, -1).contiguous()
    h = HALF_SIDE
    square = torch.tensor([[-h, -h], [h, -h], [h, h], [-h, h]], dtype=dtype)
    return PushContext(
        mask0=mask,
        pose0=torch.zeros(batch, 3, dtype=dtype),
        contact_xy=torch.tensor([[-h, 0.0]], dtype=dtype).expand(batch, 2).contiguous(),
        direction=torch.zeros(batch, dtype=dtype),
        speed=torch.full((batch,), 0.05, dtype=dtype),
        camera=camera,
        footprint=square.expand(batch, 4, 2).contiguous(),
    )


def prior(batch: int, dtype=torch.float32) -> tuple[torch.Tensor, torch.Tensor]:
    mean = torch.zeros(batch, 8, dtype=dtype)
    var = torch.tensor([1e-4, 1e-4, 1e-2, 0.2, 0.2, 0.2, 0.2, 0.2], dtype=dtype)
    return mean, torch.diag(var).expand(batch, 8, 8).clone()
