"""Learned implementations of the filter interfaces: geometry (mask warp, action map) + networks.

State s = (x, y, θ, φ̃) (B, C, 8): pose of the geometric frame (m, m, rad), normalised
parameters. Per sigma point the models build

* the encoder input [Ŝ, M]: S_0 warped to the sigma point's pose (`geometry.warp`) and the
  action map of the push (`geometry.action_maps`), optionally cropped around the object;
* features (x - x0, y - y0) / L, sin(θ - θ0), cos(θ - θ0), φ̃, the deviation
  (δx / L, δy / L, δθ) of the point's pose from the pose the encoding was computed at, and the
  pad in the point's object frame: its position / L, the push direction (sin, cos) and the
  speed / `speed_scale` (12 + param_dim values, L = `length_scale`). The pad's pose is known
  exactly from the robot's kinematics; giving it explicitly spares the networks from reading
  millimetres off a 9 mm/pixel action map.

Encoder modes (`EncodingConfig.mode`):
* "per_sigma" (the paper): one encoding per sigma point; the deviation features are zero.
* "mean": one encoding per object and call, at the mean pose of the points passed in; each
  point's offset from that pose goes to ProcessNet/TacNet through the deviation features.
  ~70× fewer conv evaluations per filter step (3 instead of ~207 at C = 100).
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal, overload

import torch
import torch.nn.functional as F
from pydantic import Field, model_validator
from torch import nn

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.camera import CameraModel
from pushtoknow.common.config import Config
from pushtoknow.common.errors import ShapeError
from pushtoknow.filters.base import FilterConfig
from pushtoknow.filters.constraints import StateConstraint, default_object_constraints
from pushtoknow.filters.dual import DualFilter
from pushtoknow.filters.interfaces import (
    DynamicsModel,
    ObservationModel,
    ObservationNoiseModel,
    PoseObservation,
)
from pushtoknow.filters.joint import JointFilter
from pushtoknow.filters.shapes import expect_shape
from pushtoknow.geometry.action_maps import ActionMapConfig, action_map
from pushtoknow.geometry.warp import warp_affine_theta, warp_mask
from pushtoknow.models.networks import (
    EncoderConfig,
    ObsNoiseNet,
    ObsNoiseNetConfig,
    ProcessNet,
    ProcessNetConfig,
    ShapeActionEncoderNet,
    TacNet,
    TacNetConfig,
)

POSE_DIM = 3
NUM_POSE_FEATURES = 12  # (x - x0)/L, (y - y0)/L, sin, cos, δx/L, δy/L, δθ, pad (5)
SPEED_SCALE = 0.1  # m/s, normalises the push speed feature
PAD_RADIUS = 0.005  # m: the testbed's pad (kept equal to `PadConfig.radius` by a test)
STEADY_ACCEL = 0.05  # m/s²: pad accelerations below this are a steady push (tracking noise)


FilterKind = Literal["dual", "joint", "vision_only"]


@overload
def _map_field(t: torch.Tensor, fn: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor: ...
@overload
def _map_field(
    t: torch.Tensor | None, fn: Callable[[torch.Tensor], torch.Tensor]
) -> torch.Tensor | None: ...
def _map_field(t, fn):
    """fn applied to a context field, which may be None."""
    return None if t is None else fn(t)


@dataclass(frozen=True)
class PushContext:
    """Per-batch inputs of the learned models for one push (opaque to the filter).

    mask0 (B, 1, H, W): S_0 in [0, 1] from the first frame; pose0 (B, 3): pose at the first
    frame (m, m, rad); contact_xy (B, 2): where the action map is centred (m, world; the push's
    contact point, or the pusher's current position if the caller moves it along the push);
    direction (B,): push direction (rad, world); speed (B,): push speed (m/s); camera: the
    camera model of the images; footprint (B, V, 2) or None: footprint polygon (m, object
    frame), used by `ComInFootprintConstraint`; pad_window (B, 4, 2) or None: the pad's
    positions at samples t-2, t-1, t, t+1 around the step that ends at t (m, world; the
    robot's kinematics, see `with_pad_track`), step_dt the time between samples (s): the
    physics-structured models read the pad's velocity and acceleration from them;
    release (B, 3) or None: when each push's pad starts to stop, its speed then and its
    deceleration (`testbed.push.release_point`; t_r = inf for a push that never stops), and
    time (B,) or None: the time of sample t since the push began (s), for the free slide of
    a released object (`models.physics.free_slide_gap`).
    """

    mask0: torch.Tensor
    pose0: torch.Tensor
    contact_xy: torch.Tensor
    direction: torch.Tensor
    speed: torch.Tensor
    camera: CameraModel
    footprint: torch.Tensor | None = None
    pad_window: torch.Tensor | None = None
    step_dt: float = 0.1
    release: torch.Tensor | None = None
    time: torch.Tensor | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def action_map(self, config: ActionMapConfig, dtype: torch.dtype) -> torch.Tensor:
        """M_t (B, 1, H, W) of this push (`geometry.action_maps.action_map`). Cached per
        (config, dtype) unless a push tensor requires grad."""
        key = (config, dtype)
        needs_grad = any(t.requires_grad for t in (self.contact_xy, self.direction, self.speed))
        if needs_grad or key not in self._cache:
            amap = action_map(
                self.contact_xy.to(dtype),
                self.direction.to(dtype),
                self.speed.to(dtype),
                self.camera,
                config,
            )
            if needs_grad:
                return amap
            self._cache[key] = amap
        return self._cache[key]

    def validate(self, batch: int) -> None:
        """Raise `ShapeError` unless every tensor has batch size `batch` and its shape above."""
        cam = self.camera
        expect_shape(
            self.mask0,
            "context.mask0",
            [("B", batch), ("1", 1), ("H", cam.height), ("W", cam.width)],
        )
        expect_shape(self.pose0, "context.pose0", [("B", batch), ("3", 3)])
        expect_shape(self.contact_xy, "context.contact_xy", [("B", batch), ("2", 2)])
        expect_shape(self.direction, "context.direction", [("B", batch)])
        expect_shape(self.speed, "context.speed", [("B", batch)])
        if self.footprint is not None:
            expect_shape(self.footprint, "context.footprint", [("B", batch), ("V", None), ("2", 2)])
        if self.pad_window is not None:
            expect_shape(self.pad_window, "context.pad_window", [("B", batch), ("4", 4), ("2", 2)])
        if self.release is not None:
            expect_shape(self.release, "context.release", [("B", batch), ("3", 3)])
        if self.time is not None:
            expect_shape(self.time, "context.time", [("B", batch)])

    def pad_kinematics(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The pad's velocity over the step (B, 2) (m/s, backward difference t-1 → t) and its
        accelerations at t and at t-1 (B, 2) (m/s², centred differences), world frame."""
        if self.pad_window is None:
            raise ShapeError("this model needs the pad's track: build contexts with with_pad_track")
        w, dt = self.pad_window, self.step_dt
        velocity = (w[:, 2] - w[:, 1]) / dt
        accel = (w[:, 3] - 2 * w[:, 2] + w[:, 1]) / dt**2
        accel_prev = (w[:, 2] - 2 * w[:, 1] + w[:, 0]) / dt**2
        return velocity, accel, accel_prev

    def pad_accelerating(self) -> torch.Tensor:
        """(B,) bool: the pad's acceleration at t or t-1 exceeds `STEADY_ACCEL` (the step is
        part of a push's dynamic phase)."""
        _, accel, accel_prev = self.pad_kinematics()
        return (accel.norm(dim=-1) > STEADY_ACCEL) | (accel_prev.norm(dim=-1) > STEADY_ACCEL)

    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None):
        """A copy with every tensor moved to dtype/device."""

        def mv(t):
            return _map_field(t, lambda x: x.to(device=device, dtype=dtype))

        return PushContext(
            mv(self.mask0),
            mv(self.pose0),
            mv(self.contact_xy),
            mv(self.direction),
            mv(self.speed),
            self.camera,
            mv(self.footprint),
            mv(self.pad_window),
            self.step_dt,
            mv(self.release),
            mv(self.time),
        )


def pad_windows(paths: torch.Tensor, t: torch.Tensor | int) -> torch.Tensor:
    """Pad positions at samples t-2, t-1, t, t+1 (B, 4, 2) from pad paths (B, T, 2) (m) and
    sample indices t (B,) or one int. Beyond either end the path is extended at constant
    velocity (a recorded push ends while the pad still moves at its push speed)."""
    b, n, _ = paths.shape
    before = 2 * paths[:, :1] - paths[:, 1:2]
    first = torch.cat([2 * before - paths[:, :1], before], dim=1)
    last = 2 * paths[:, -1:] - paths[:, -2:-1]
    ext = torch.cat([first, paths, last], dim=1)  # sample s at index s + 2
    t = torch.as_tensor(t, device=paths.device).long().expand(b)
    if int(t.min()) < 0 or int(t.max()) >= n:
        raise IndexError(f"sample index outside the path of {n} samples")
    idx = t[:, None] + torch.arange(4, device=paths.device)  # s - 2 .. s + 1, shifted by 2
    return ext.gather(1, idx[..., None].expand(b, 4, 2))


def with_pad_track(
    context: PushContext, paths: torch.Tensor, t: torch.Tensor | int, step_dt: float
) -> PushContext:
    """`context` for the step that ends at sample t of pad paths (B, T, 2) (m, world): the pad
    at its position at t, its window for the pad's velocity and acceleration, and the time
    t · step_dt."""
    b = paths.shape[0]
    t_b = torch.as_tensor(t, device=paths.device).long().expand(b)
    return dataclasses.replace(
        context,
        contact_xy=paths[torch.arange(b, device=paths.device), t_b],
        pad_window=pad_windows(paths, t_b),
        step_dt=float(step_dt),
        time=t_b.to(paths.dtype) * float(step_dt),
    )


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
            ctx = _repeat_context(context, s)
            imgs = self.images(flat, ctx, amap.repeat_interleave(s, dim=0))
            return self.encoder(imgs).view(b, s, -1), pose
        anchor = pose.mean(dim=1)  # (B, 3)
        enc = self.encoder(self.images(anchor, context, amap))
        return enc.unsqueeze(1), anchor.unsqueeze(1)


def _repeat_context(context: PushContext, times: int) -> PushContext:
    def rep(t):
        return _map_field(t, lambda x: x.repeat_interleave(times, dim=0))

    return PushContext(
        rep(context.mask0),
        rep(context.pose0),
        rep(context.contact_xy),
        rep(context.direction),
        rep(context.speed),
        context.camera,
        rep(context.footprint),
        rep(context.pad_window),
        context.step_dt,
        rep(context.release),
        rep(context.time),
    )


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


class LearnedDynamics(DynamicsModel):
    """(Δψ, Q) = ProcessNet(features(χ), enc(χ)) per sigma point (docs/DESIGN.md §6 step 2)."""

    def __init__(self, encoding: ShapeActionEncoding, process_net: ProcessNet):
        super().__init__()
        self.encoding = encoding
        self.process_net = process_net

    def forward(
        self, states: torch.Tensor, context: PushContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        enc, anchor = self.encoding(states[..., :POSE_DIM], context)
        feats = sigma_point_features(
            states, context.pose0, anchor, self.encoding.config.length_scale, context
        )
        return self.process_net(feats, enc)


class LearnedObservation(ObservationModel):
    """h(s) = (x, y, θ, F_x, F_y[, p_contact]) with forces from TacNet (docs/DESIGN.md §6 step 3).

    include_contact appends sigmoid(contact logit) as an observation of contact ∈ {0, 1}
    (treated as Gaussian by the filter; off by default, the logit is then a training target).
    """

    def __init__(
        self, encoding: ShapeActionEncoding, tac_net: TacNet, include_contact: bool = False
    ):
        super().__init__()
        self.encoding = encoding
        self.tac_net = tac_net
        self.include_contact = include_contact
        self.obs_dim = POSE_DIM + 2 + int(include_contact)
        self.angle_indices = (2,)

    def tactile(
        self, states: torch.Tensor, context: PushContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """TacNet outputs for states (B, S, D): forces (B, S, 2) in N, contact logits (B, S)."""
        enc, anchor = self.encoding(states[..., :POSE_DIM], context)
        feats = sigma_point_features(
            states, context.pose0, anchor, self.encoding.config.length_scale, context
        )
        return self.tac_net(feats, enc)

    def forward(self, states: torch.Tensor, context: PushContext) -> torch.Tensor:
        forces, logit = self.tactile(states, context)
        parts = [states[..., :POSE_DIM], forces]
        if self.include_contact:
            parts.append(torch.sigmoid(logit).unsqueeze(-1))
        return torch.cat(parts, dim=-1)


class LearnedObservationNoise(ObservationNoiseModel):
    """R = ObsNoiseNet(z) with the pose part of z taken relative to pose0 (θ residual wrapped),
    so the noise does not depend on where the object is on the table."""

    def __init__(self, net: ObsNoiseNet):
        super().__init__()
        self.net = net
        self.obs_dim = net.config.obs_dim

    def forward(self, observation: torch.Tensor, context: PushContext) -> torch.Tensor:
        pose0 = context.pose0.to(observation.dtype)
        rel = torch.cat(
            [
                observation[:, :2] - pose0[:, :2],
                wrap_angle(observation[:, 2:3] - pose0[:, 2:3]),
                observation[:, 3:],
            ],
            dim=-1,
        )
        return self.net(rel)


class ScaledObservationNoise(ObservationNoiseModel):
    """R = scale · R_base(z): the observation noise of a trained model inflated by a factor
    calibrated on validation data. 60 updates per push treat model errors that persist over
    the push as independent; inflating R (`training.pipeline` calibrates it) keeps the
    parameter belief from becoming overconfident. The few samples of a push's dynamic phase
    (`PushContext.pad_accelerating`), whose errors persist far less, may take their own
    `dynamic_scale` (None: `scale`)."""

    def __init__(
        self, base: ObservationNoiseModel, scale: float, dynamic_scale: float | None = None
    ):
        super().__init__()
        for name, v in (("noise scale", scale), ("dynamic noise scale", dynamic_scale)):
            if v is not None and not v > 0:
                raise ValueError(f"{name} must be positive, got {v}")
        self.base = base
        self.scale = float(scale)
        self.dynamic_scale = None if dynamic_scale is None else float(dynamic_scale)
        self.obs_dim = base.obs_dim

    def forward(self, observation: torch.Tensor, context: PushContext) -> torch.Tensor:
        r = self.base(observation, context)
        if self.dynamic_scale is None or self.dynamic_scale == self.scale:
            return self.scale * r
        if context.pad_window is None:
            raise ShapeError("a dynamic noise scale needs the pad's track (with_pad_track)")
        dynamic = context.pad_accelerating().unsqueeze(-1)
        return torch.where(dynamic, self.dynamic_scale, self.scale).to(r) * r


# --------------------------------------------------------------------------------------------
class LearnedModelsConfig(Config):
    """Sizes of the learned models; the defaults are the paper-sized networks for 64 px images
    and 5 parameters.

    structure: "black-box" (the paper: m, μ, I_z enter ProcessNet and TacNet as inputs like
    any feature) or "physics" (`models.physics`: how they enter force and motion is written
    down; the networks' hidden sizes and output scales are those of `process` and `tac`).
    quasi_static (physics structure only): "network" (a network learns quasi-static motion
    and force from geometry, contact and the CoM) or "limit-surface" (`models.contact`: the
    pad pushes the outline seen before the push through the ellipsoidal limit surface about the CoM,
    and the networks learn what that leaves); pad_radius: the pad's radius (m) for it.
    """

    structure: Literal["black-box", "physics"] = "black-box"
    quasi_static: Literal["network", "limit-surface"] = "network"
    pad_radius: float = Field(PAD_RADIUS, gt=0)
    param_dim: int = 5
    encoding: EncodingConfig = EncodingConfig()
    encoder: EncoderConfig = EncoderConfig(image_size=32)
    process: ProcessNetConfig = ProcessNetConfig()
    tac: TacNetConfig = TacNetConfig()
    obs_noise: ObsNoiseNetConfig = ObsNoiseNetConfig()
    include_contact: bool = False
    free_slide: bool = Field(
        False,
        description="limit-surface motion only: a released object's slide to rest through the "
        "limit surface is written down (`models.contact.free_slide`)",
    )
    moment_arm: Literal["gyration", "pressure"] = Field(
        "gyration",
        description="limit-surface motion only: the moment arm ℓ is κ × the footprint's radius "
        "of gyration (gyration) or κ × the mean distance from the CoM under the support "
        "pressure centred at it (pressure; `models.contact.pressure_moment_arm`)",
    )
    dynamic_motion_params: bool = Field(
        True,
        description="physics structure only: the dynamic motion network sees μ and I_z/m "
        "through its dimensionless groups (true) or the pad's kinematics alone (false: m, μ "
        "and I_z then enter motion only where it is written down, the free slide)",
    )

    @property
    def label(self) -> str:
        """The structure as reports name it: "black-box", "physics" or
        "physics-limit-surface", with "-free-slide" when the free slide is written down and
        "-kinematic-dynamic" when the dynamic motion network does not see the parameters."""
        label: str = self.structure
        if self.quasi_static != "network":
            label = f"{label}-{self.quasi_static}"
        if self.moment_arm != "gyration":
            label = f"{label}-{self.moment_arm}-arm"
        if self.free_slide:
            label = f"{label}-free-slide"
        return label if self.dynamic_motion_params else f"{label}-kinematic-dynamic"

    @model_validator(mode="after")
    def _consistent(self) -> LearnedModelsConfig:
        feat = NUM_POSE_FEATURES + self.param_dim
        for name, net in (("process", self.process), ("tac", self.tac)):
            if net.input_dim != feat:
                raise ValueError(f"{name}.input_dim must be 12 + param_dim = {feat}")
            if net.enc_dim != self.encoder.out_dim:
                raise ValueError(f"{name}.enc_dim must equal encoder.out_dim")
        crop = self.encoding.crop_size
        if self.quasi_static != "network" and self.structure != "physics":
            raise ValueError("quasi_static: limit-surface needs structure: physics")
        if self.moment_arm != "gyration" and self.quasi_static != "limit-surface":
            raise ValueError("moment_arm: pressure needs quasi_static: limit-surface")
        if self.free_slide and self.quasi_static != "limit-surface":
            raise ValueError("free_slide needs quasi_static: limit-surface")
        if not self.dynamic_motion_params and self.structure != "physics":
            raise ValueError("dynamic_motion_params: false needs structure: physics")
        if crop is not None and crop != self.encoder.image_size:
            raise ValueError(f"encoder.image_size must equal encoding.crop_size={crop}")
        return self


@dataclass
class LearnedModels:
    """The learned models sharing one ShapeActionEncoderNet."""

    dynamics: DynamicsModel
    observation: ObservationModel
    observation_noise: ObservationNoiseModel

    def modules(self) -> nn.ModuleList:
        return nn.ModuleList([self.dynamics, self.observation, self.observation_noise])


def build_learned_models(
    config: LearnedModelsConfig = LearnedModelsConfig(), vision_only: bool = False
) -> LearnedModels:
    """Networks + geometry wired into the filter interfaces. vision_only: z = (x, y, θ) with a
    3-D ObsNoiseNet (the first three entries of config.obs_noise's per-dimension scales)."""
    encoding = ShapeActionEncoding(ShapeActionEncoderNet(config.encoder), config.encoding)
    if config.structure == "physics":
        return _physics_models(config, encoding, vision_only)
    dynamics = LearnedDynamics(encoding, ProcessNet(config.process))
    if vision_only:
        c = config.obs_noise
        noise_cfg = ObsNoiseNetConfig(
            obs_dim=POSE_DIM,
            hidden_dim=c.hidden_dim,
            input_scale=c.input_scale[:POSE_DIM],
            std_scale=c.std_scale[:POSE_DIM],
            std_floor=c.std_floor[:POSE_DIM],
        )
        observation: ObservationModel = PoseObservation(POSE_DIM, (2,))
    else:
        noise_cfg = config.obs_noise
        observation = LearnedObservation(encoding, TacNet(config.tac), config.include_contact)
    if noise_cfg.obs_dim != observation.obs_dim:
        raise ShapeError(
            f"obs_noise.obs_dim={noise_cfg.obs_dim} but the observation has "
            f"{observation.obs_dim} components"
        )
    return LearnedModels(dynamics, observation, LearnedObservationNoise(ObsNoiseNet(noise_cfg)))


def _physics_models(
    config: LearnedModelsConfig, encoding: ShapeActionEncoding, vision_only: bool
) -> LearnedModels:
    from pushtoknow.models import physics  # builds on this module's context and encoding
    from pushtoknow.models.networks import PhysicsProcessNet, PhysicsTacNet

    if vision_only or config.include_contact or config.param_dim != 5:
        raise ValueError(
            "physics-structured models need tactile observations without the contact "
            "component and the five parameters"
        )
    process = PhysicsProcessNet(config.process, physics.GEOM_DIM, physics.DYN_DIM)
    tac = PhysicsTacNet(config.tac, physics.GEOM_DIM, physics.INERTIAL_DIM)
    limit_surface = None
    if config.quasi_static == "limit-surface":
        limit_surface = physics.LimitSurface(
            config.pad_radius, physics.MOMENT_ARMS[config.moment_arm]
        )
    return LearnedModels(
        physics.PhysicsDynamics(
            encoding, process, limit_surface, config.free_slide, config.dynamic_motion_params
        ),
        physics.PhysicsObservation(encoding, tac),
        LearnedObservationNoise(ObsNoiseNet(config.obs_noise)),
    )


def build_filter(
    kind: FilterKind = "dual",
    models: LearnedModels | None = None,
    models_config: LearnedModelsConfig = LearnedModelsConfig(),
    filter_config: FilterConfig = FilterConfig(),
    constraint: StateConstraint | None = None,
    with_footprint: bool = True,
) -> DualFilter | JointFilter:
    """VT-DDF ("dual"), VT-JDF ("joint") or V-DDF ("vision_only") on learned models.

    constraint defaults to m, μ, I_z > 0 and (with_footprint) CoM inside context.footprint.
    """
    if models is None:
        models = build_learned_models(models_config, vision_only=(kind == "vision_only"))
    if constraint is None:
        constraint = default_object_constraints(filter_config.pose_dim, with_footprint)
    cls = JointFilter if kind == "joint" else DualFilter
    return cls(
        models.dynamics, models.observation, models.observation_noise, filter_config, constraint
    )
