"""The five networks of docs/DESIGN.md §5 (paper §III-C/D), sizes configurable.

All take and return float tensors on the device/dtype of their weights; N is any batch size
(for the filter's models N = B · C, objects times sigma points). Units are SI; outputs that
are variances (Q, R) are positive and floored.
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Sequence

import torch
import torch.nn.functional as F
from pydantic import model_validator
from torch import nn

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.errors import ShapeError
from pushtoknow.common.frozen_config import Config


def _conv_stack(
    in_channels: int, channels: Sequence[int], kernels: Sequence[int], strides: Sequence[int]
) -> tuple[nn.Sequential, int]:
    """Conv + ReLU layers ("same" padding). Returns the stack and its total stride."""
    layers: list[nn.Module] = []
    c_in, total = in_channels, 1
    for c_out, k, s in zip(channels, kernels, strides):
        layers += [nn.Conv2d(c_in, c_out, k, stride=s, padding=k // 2), nn.ReLU(inplace=True)]
        c_in, total = c_out, total * s
    return nn.Sequential(*layers), total


def _conv_out_size(size: int, kernels: Sequence[int], strides: Sequence[int]) -> int:
    for k, s in zip(kernels, strides):
        size = (size + 2 * (k // 2) - k) // s + 1
    return size


def _mlp(sizes: Sequence[int]) -> nn.Sequential:
    """Linear layers between consecutive sizes, ReLU between them (none after the last)."""
    layers: list[nn.Module] = []
    for i, (a, b) in enumerate(itertools.pairwise(sizes)):
        layers.append(nn.Linear(a, b))
        if i < len(sizes) - 2:
            layers.append(nn.ReLU(inplace=True))
    return nn.Sequential(*layers)


class _FeatureEncodingMLP(nn.Module):
    """MLP on cat(features, enc) whose first layer is split as W_f f + W_e e + b, so that an
    encoding shared by many rows (enc (..., 1, E) broadcast against features (..., S, F)) is
    multiplied once. Same function and layer count as the plain MLP on the concatenation."""

    def __init__(self, feature_dim: int, enc_dim: int, hidden: Sequence[int], out_dim: int):
        super().__init__()
        self.first_features = nn.Linear(feature_dim, hidden[0])
        self.first_enc = nn.Linear(enc_dim, hidden[0], bias=False)
        self.rest = nn.Sequential(nn.ReLU(inplace=True), _mlp([*hidden, out_dim]))

    def forward(self, features: torch.Tensor, enc: torch.Tensor) -> torch.Tensor:
        return self.rest(self.first_features(features) + self.first_enc(enc))


def _check_image(x: torch.Tensor, name: str, channels: int, size: int) -> None:
    if x.ndim != 4 or x.shape[1] != channels or x.shape[-2:] != (size, size):
        raise ShapeError(
            f"{name}: expected shape (N, {channels}, {size}, {size}), got {tuple(x.shape)}"
        )


def _check_features(x: torch.Tensor, name: str, dim: int) -> None:
    if x.ndim < 2 or x.shape[-1] != dim:
        raise ShapeError(f"{name}: expected shape (..., {dim}), got {tuple(x.shape)}")


# --------------------------------------------------------------------------------------------
class EncoderConfig(Config):
    """ShapeActionEncoderNet: 3 conv layers + 2 FC on [Ŝ_t, M_t] (2 channels).

    image_size: side of the (square) encoder input in pixels: the camera image, or the crop
    around the object when the learned models crop (see `models.encoding.EncodingConfig`).
    """

    in_channels: int = 2
    image_size: int = 64
    channels: tuple[int, int, int] = (16, 32, 32)
    kernel_sizes: tuple[int, int, int] = (5, 3, 3)
    strides: tuple[int, int, int] = (2, 2, 2)
    hidden_dim: int = 128
    out_dim: int = 64


class ShapeActionEncoderNet(nn.Module):
    """[Ŝ_t, M_t] (N, 2, S, S) → enc (N, out_dim)."""

    def __init__(self, config: EncoderConfig = EncoderConfig()):
        super().__init__()
        self.config = config
        self.conv, _ = _conv_stack(
            config.in_channels, config.channels, config.kernel_sizes, config.strides
        )
        side = _conv_out_size(config.image_size, config.kernel_sizes, config.strides)
        self.fc = _mlp([config.channels[-1] * side * side, config.hidden_dim, config.out_dim])

    def forward(self, images: torch.Tensor) -> torch.Tensor:
        c = self.config
        _check_image(images, "ShapeActionEncoderNet input", c.in_channels, c.image_size)
        return self.fc(self.conv(images).flatten(1))


# --------------------------------------------------------------------------------------------
class ProcessNetConfig(Config):
    """ProcessNet: 3 FC on (sigma-point features, enc) → Δψ and diagonal Q.

    Δψ = delta_scale ⊙ out (m, m, rad per step); √Q = q_floor_std + q_scale ⊙ softplus(out'),
    so Q ≥ q_floor_std² (m², m², rad²).
    """

    input_dim: int = 17
    enc_dim: int = 64
    hidden_dims: tuple[int, int] = (128, 128)
    pose_dim: int = 3
    delta_scale: tuple[float, ...] = (0.01, 0.01, 0.05)
    q_scale: tuple[float, ...] = (0.002, 0.002, 0.02)
    q_floor_std: tuple[float, ...] = (1e-4, 1e-4, 1e-3)

    @model_validator(mode="after")
    def _lengths(self) -> ProcessNetConfig:
        for name in ("delta_scale", "q_scale", "q_floor_std"):
            if len(getattr(self, name)) != self.pose_dim:
                raise ValueError(f"{name} needs pose_dim={self.pose_dim} entries")
        if min(self.q_floor_std) <= 0:
            raise ValueError("q_floor_std must be positive")
        return self


class ProcessNet(nn.Module):
    """features (..., input_dim), enc (..., enc_dim) (broadcastable leading axes)
    → (Δψ (..., P), q_diag (..., P) ≥ floor)."""

    delta_scale: torch.Tensor  # buffers, registered in __init__
    q_scale: torch.Tensor
    q_floor_std: torch.Tensor

    def __init__(self, config: ProcessNetConfig = ProcessNetConfig()):
        super().__init__()
        self.config = config
        c = config
        self.mlp = _FeatureEncodingMLP(c.input_dim, c.enc_dim, c.hidden_dims, 2 * c.pose_dim)
        self.register_buffer("delta_scale", torch.tensor(c.delta_scale), persistent=False)
        self.register_buffer("q_scale", torch.tensor(c.q_scale), persistent=False)
        self.register_buffer("q_floor_std", torch.tensor(c.q_floor_std), persistent=False)

    def forward(
        self, features: torch.Tensor, enc: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        _check_features(features, "ProcessNet features", self.config.input_dim)
        _check_features(enc, "ProcessNet enc", self.config.enc_dim)
        out = self.mlp(features, enc)
        p = self.config.pose_dim
        dt = out.dtype
        delta = self.delta_scale.to(dt) * out[..., :p]
        std = self.q_floor_std.to(dt) + self.q_scale.to(dt) * F.softplus(out[..., p:])
        return delta, std.square()


# --------------------------------------------------------------------------------------------
class TacNetConfig(Config):
    """TacNet: 4 FC on (sigma-point features, enc) → (F_x, F_y) (N, world frame) and a
    contact logit. Forces = force_scale ⊙ out."""

    input_dim: int = 17
    enc_dim: int = 64
    hidden_dims: tuple[int, int, int] = (128, 128, 64)
    force_scale: float = 5.0


class TacNet(nn.Module):
    """features (..., input_dim), enc (..., enc_dim) (broadcastable leading axes)
    → (forces (..., 2), contact_logit (...))."""

    def __init__(self, config: TacNetConfig = TacNetConfig()):
        super().__init__()
        self.config = config
        c = config
        self.mlp = _FeatureEncodingMLP(c.input_dim, c.enc_dim, c.hidden_dims, 3)

    def forward(
        self, features: torch.Tensor, enc: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        _check_features(features, "TacNet features", self.config.input_dim)
        _check_features(enc, "TacNet enc", self.config.enc_dim)
        out = self.mlp(features, enc)
        return self.config.force_scale * out[..., :2], out[..., 2]


# --------------------------------------------------------------------------------------------
class ObsNoiseNetConfig(Config):
    """ObsNoiseNet: 2 layers on z = (z^V, z^T) → diagonal R.

    Input z / input_scale; √R = std_floor + std_scale ⊙ softplus(out), so R ≥ std_floor².
    Defaults for z = (x, y, θ, F_x, F_y) in m, m, rad, N, N.
    """

    obs_dim: int = 5
    hidden_dim: int = 64
    input_scale: tuple[float, ...] = (0.1, 0.1, 1.0, 5.0, 5.0)
    std_scale: tuple[float, ...] = (0.005, 0.005, 0.05, 0.5, 0.5)
    std_floor: tuple[float, ...] = (5e-4, 5e-4, 5e-3, 0.05, 0.05)

    @model_validator(mode="after")
    def _lengths(self) -> ObsNoiseNetConfig:
        for name in ("input_scale", "std_scale", "std_floor"):
            if len(getattr(self, name)) != self.obs_dim:
                raise ValueError(f"{name} needs obs_dim={self.obs_dim} entries")
        if min(self.std_floor) <= 0:
            raise ValueError("std_floor must be positive")
        return self


class ObsNoiseNet(nn.Module):
    """z (N, M) → r_diag (N, M) ≥ std_floor² (units of z²)."""

    input_scale: torch.Tensor  # buffers, registered in __init__
    std_scale: torch.Tensor
    std_floor: torch.Tensor

    def __init__(self, config: ObsNoiseNetConfig = ObsNoiseNetConfig()):
        super().__init__()
        self.config = config
        self.mlp = _mlp([config.obs_dim, config.hidden_dim, config.obs_dim])
        self.register_buffer("input_scale", torch.tensor(config.input_scale), persistent=False)
        self.register_buffer("std_scale", torch.tensor(config.std_scale), persistent=False)
        self.register_buffer("std_floor", torch.tensor(config.std_floor), persistent=False)

    def forward(self, z: torch.Tensor) -> torch.Tensor:
        _check_features(z, "ObsNoiseNet input", self.config.obs_dim)
        dt = z.dtype
        out = self.mlp(z / self.input_scale.to(dt))
        std = self.std_floor.to(dt) + self.std_scale.to(dt) * F.softplus(out)
        return std.square()


# --------------------------------------------------------------------------------------------
class VisNetConfig(Config):
    """VisNet: CNN (from scratch) + 3 FC on [RGB-D (4 ch), S_0 (1 ch)] → relative pose.

    position_scale: metres per unit of the Δx, Δy outputs. marker_channel: the input has one
    more channel, the expected orientation marker at the reference pose (for testbeds that
    paint it; `perception.visnet.visnet_inputs`).
    """

    in_channels: int = 5
    image_size: int = 64
    channels: tuple[int, ...] = (16, 32, 64, 64)
    kernel_sizes: tuple[int, ...] = (5, 3, 3, 3)
    strides: tuple[int, ...] = (2, 2, 2, 2)
    hidden_dims: tuple[int, int] = (128, 64)
    position_scale: float = 0.1
    marker_channel: bool = False


class VisNet(nn.Module):
    """Synthetic pose sensor: pose of the object relative to the first frame.

    Output (N, 4) = (Δx, Δy, sin Δθ, cos Δθ): Δx, Δy world displacement of the geometric
    frame since the first frame (m); (sin, cos) of the rotation since the first frame,
    normalised to the unit circle. `to_pose` turns it into (x, y, θ) given pose0.

    Orientation: the network never has to name an absolute orientation (ill-defined for
    symmetric shapes); it compares the current image with S_0. A shape with k-fold symmetry
    looks the same after Δθ and Δθ + 2π/k, so the training target is the representative of
    smallest magnitude (`pose_to_target(..., symmetry_order=k)`), which is the true rotation
    whenever |Δθ| < π/k (half the symmetry angle) — pushes rotate objects less than that per
    episode segment. (sin, cos) is continuous across ±π, and θ = θ0 + atan2(sin, cos) lies in
    (θ0 - π, θ0 + π]; the filter wraps every θ residual, so the ±π jump is harmless.
    For continuous symmetry (discs) vision cannot see rotation: give θ a large noise.

    Pretrained backbone hook: pass ``backbone`` (an nn.Module mapping (N, 5, H, W) to (N, F)
    features, e.g. VGG-19's first 10 layers behind a 5→3 channel 1×1 conv and global pooling)
    and ``backbone_dim = F``; it replaces the default conv stack, the 3 FC head is kept.
    """

    def __init__(
        self,
        config: VisNetConfig = VisNetConfig(),
        backbone: nn.Module | None = None,
        backbone_dim: int | None = None,
    ):
        super().__init__()
        self.config = config
        c = config
        if backbone is None:
            conv, _ = _conv_stack(c.in_channels, c.channels, c.kernel_sizes, c.strides)
            side = _conv_out_size(c.image_size, c.kernel_sizes, c.strides)
            self.backbone: nn.Module = nn.Sequential(conv, nn.Flatten(1))
            feat = c.channels[-1] * side * side
        else:
            if backbone_dim is None:
                raise ValueError("a custom VisNet backbone needs backbone_dim (its feature size)")
            self.backbone, feat = backbone, backbone_dim
        self.head = _mlp([feat, *c.hidden_dims, 4])

    def forward(self, rgbd: torch.Tensor, mask0: torch.Tensor) -> torch.Tensor:
        """rgbd (N, 4, H, W) (RGB in [0, 1], depth in m), mask0 (N, 1, H, W) → (N, 4)."""
        c = self.config
        _check_image(rgbd, "VisNet rgbd", c.in_channels - 1, c.image_size)
        _check_image(mask0, "VisNet mask0", 1, c.image_size)
        out = self.head(self.backbone(torch.cat([rgbd, mask0], dim=1)))
        sc = out[:, 2:]
        sc = sc / sc.norm(dim=-1, keepdim=True).clamp_min(1e-6)
        return torch.cat([c.position_scale * out[:, :2], sc], dim=-1)

    @staticmethod
    def to_pose(relative: torch.Tensor, pose0: torch.Tensor) -> torch.Tensor:
        """(Δx, Δy, sin Δθ, cos Δθ) (N, 4) and pose0 (N, 3) → pose (x, y, θ) (N, 3),
        θ ∈ (θ0 - π, θ0 + π]."""
        _check_features(relative, "relative pose", 4)
        _check_features(pose0, "pose0", 3)
        dth = torch.atan2(relative[..., 2], relative[..., 3])
        return torch.stack(
            [
                pose0[..., 0] + relative[..., 0],
                pose0[..., 1] + relative[..., 1],
                pose0[..., 2] + dth,
            ],
            dim=-1,
        )

    @staticmethod
    def pose_to_target(
        pose: torch.Tensor, pose0: torch.Tensor, symmetry_order: int = 1
    ) -> torch.Tensor:
        """Training target (N, 4) for pose (N, 3) given pose0 (N, 3).

        Δθ is wrapped to (-π, π] and, for a k-fold symmetric shape, reduced to the
        representative of smallest magnitude modulo 2π/k.
        """
        if symmetry_order < 1:
            raise ValueError(f"symmetry_order must be ≥ 1, got {symmetry_order}")
        period = 2.0 * math.pi / symmetry_order
        dth = wrap_angle(pose[..., 2] - pose0[..., 2])
        dth = dth - period * torch.round(dth / period)
        return torch.stack(
            [pose[..., 0] - pose0[..., 0], pose[..., 1] - pose0[..., 1], dth.sin(), dth.cos()],
            dim=-1,
        )


# --------------------------------------------------------------------------------------------
class PhysicsProcessNet(nn.Module):
    """The physics-structured ProcessNet: raw outputs out = qs(x_geom, enc) + gate · dyn(x_dyn,
    enc), then Δψ and Q exactly as `ProcessNet` (same config). x_geom carries no mass,
    friction or inertia, so quasi-static motion cannot depend on them; x_dyn adds the
    dimensionless groups in which μ and I_z/m enter motion, and the gate (∈ [0, 1], from the
    pad's acceleration) switches them on only in dynamic phases. Mass alone never enters.

    geom (..., G), dyn (..., G + K), gate (...), enc (..., E) → (Δψ (..., P), q_diag (..., P)).
    """

    delta_scale: torch.Tensor  # buffers, registered in __init__
    q_scale: torch.Tensor
    q_floor_std: torch.Tensor

    def __init__(self, config: ProcessNetConfig, geom_dim: int, dyn_dim: int):
        super().__init__()
        self.config = config
        c = config
        self.quasi_static = _FeatureEncodingMLP(geom_dim, c.enc_dim, c.hidden_dims, 2 * c.pose_dim)
        self.dynamic = _FeatureEncodingMLP(dyn_dim, c.enc_dim, c.hidden_dims, 2 * c.pose_dim)
        self.register_buffer("delta_scale", torch.tensor(c.delta_scale), persistent=False)
        self.register_buffer("q_scale", torch.tensor(c.q_scale), persistent=False)
        self.register_buffer("q_floor_std", torch.tensor(c.q_floor_std), persistent=False)

    def forward(
        self, geom: torch.Tensor, dyn: torch.Tensor, gate: torch.Tensor, enc: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor]:
        out = self.quasi_static(geom, enc) + gate.unsqueeze(-1) * self.dynamic(dyn, enc)
        p = self.config.pose_dim
        dt = out.dtype
        delta = self.delta_scale.to(dt) * out[..., :p]
        std = self.q_floor_std.to(dt) + self.q_scale.to(dt) * F.softplus(out[..., p:])
        return delta, std.square()


class PhysicsTacNet(nn.Module):
    """The physics-structured TacNet: the pad force in the push frame (along, across) is
    F = m (μ g G + J a) — Coulomb friction of the table scaled by a learned dimensionless
    G(x_geom) (geometry, contact, CoM; |G| = 1 for a rigid translation) plus the inertial
    force of the pad's acceleration a through a learned dimensionless 2 × 2 J(x_inertial)
    (the identity for a rigid translation; x_inertial adds I_z/m). Networks never see m or μ.

    geom (..., G), inertial (..., G + 1), enc (..., E) → (G (..., 2), J (..., 2, 2),
    contact logit (...)).
    """

    def __init__(self, config: TacNetConfig, geom_dim: int, inertial_dim: int):
        super().__init__()
        self.config = config
        c = config
        self.friction = _FeatureEncodingMLP(geom_dim, c.enc_dim, c.hidden_dims, 3)
        self.inertial = _FeatureEncodingMLP(inertial_dim, c.enc_dim, c.hidden_dims, 4)

    def forward(
        self, geom: torch.Tensor, inertial: torch.Tensor, enc: torch.Tensor
    ) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        f = self.friction(geom, enc)
        j = self.inertial(inertial, enc).unflatten(-1, (2, 2))
        eye = torch.eye(2, dtype=j.dtype, device=j.device)
        return f[..., :2], eye + j, f[..., 2]
