"""Learned implementations of the filter interfaces, and the builders of the models and filters.

The black-box models of the paper (`LearnedDynamics`, `LearnedObservation`: m, μ and I_z enter
ProcessNet and TacNet as inputs like any feature) and the observation noise are here; the
physics-structured models are in `models.physics`; `build_learned_models` and `build_filter`
make either. What the models read about a push is a `models.context.PushContext`; how they see
a sigma point (the shape-action encoding of the mask and action map, and the features) is
`models.encoding`.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import torch
from pydantic import Field, model_validator
from torch import nn

from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.errors import ShapeError
from pushtoknow.common.frozen_config import Config
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
from pushtoknow.models import physics
from pushtoknow.models.context import PushContext
from pushtoknow.models.encoding import (
    NUM_POSE_FEATURES,
    POSE_DIM,
    EncodingConfig,
    ShapeActionEncoding,
    sigma_point_features,
)
from pushtoknow.models.networks import (
    EncoderConfig,
    ObsNoiseNet,
    ObsNoiseNetConfig,
    PhysicsProcessNet,
    PhysicsTacNet,
    ProcessNet,
    ProcessNetConfig,
    ShapeActionEncoderNet,
    TacNet,
    TacNetConfig,
)

PAD_RADIUS = 0.005  # m: the testbed's pad (kept equal to `PadConfig.radius` by a test)


FilterKind = Literal["dual", "joint", "vision_only"]


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
