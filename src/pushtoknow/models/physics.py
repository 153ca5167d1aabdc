"""Physics-structured learned models: how m, μ and I_z enter force and motion is written down,
the networks learn geometry, contact and the CoM's effect (the hybrid approach of Kloss,
Schaal and Bohg, IJRR 2022; README "The models").

* Force (`PhysicsObservation`): F = m (μ g G + J a) in the push frame, G and J dimensionless
  networks of geometry, contact and CoM (J also of I_z/m), a the pad's acceleration. Scaling
  m by k and μ by 1/k leaves a quasi-static force unchanged; mass is only separable from μ
  through the pad's acceleration.
* Motion (`PhysicsDynamics`): Δψ from a quasi-static network that never sees m, μ or I_z, plus
  a dynamic network gated by the pad's acceleration (exactly off while |a| ≤ STEADY_ACCEL at
  t and t-1, i.e. in steady pushes) that sees μ and I_z/m only as the
  dimensionless groups of sliding (a/μg, v²/2μgL, log I_z/(m L²)); m alone never enters.
* With `quasi_static: limit-surface` (`LimitSurface`, `models.contact`), the quasi-static
  part is written down too: the pad pushes the outline seen before the push through the ellipsoidal
  limit surface about the CoM, which gives the slider's step; the networks then learn only
  what that model leaves. (Its force, μ m g n / √(1 + ρ²), is left to the friction network:
  as a fixed term it made μ·m worse on validation objects, through the contact decision on
  sigma points a millimetre off.)

Features per sigma point (B, S, ·), with L = `EncodingConfig.length_scale` and the pad's
kinematics from `PushContext.pad_kinematics`:

* geometry (GEOM_DIM): (x - x0, y - y0)/L, sin, cos (θ - θ0), the normalised CoM (2), the
  deviation (δx/L, δy/L, δθ) from the encoding's pose, the pad in the point's object frame
  (position/L, push direction sin, cos), the pad's velocity over the step / SPEED_SCALE and
  its accelerations at t and t-1 / ACCEL_SCALE, all in the object frame;
* dynamic (GEOM_DIM + 5): geometry, normalised log μ, log I_z/(m L²) normalised, |a_t|/μg,
  |a_{t-1}|/μg, |v|²/(2 μ g L);
* inertial (GEOM_DIM + 1): geometry and log I_z/(m L²) normalised.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import torch
from torch import nn

from pushtoknow.common.errors import ShapeError
from pushtoknow.common.params import GRAVITY, PARAM_NAMES, PARAM_RANGES, denormalise_params
from pushtoknow.filters.interfaces import DynamicsModel, ObservationModel
from pushtoknow.models.contact import (
    LimitSurfacePush,
    free_slide,
    limit_surface_push,
    pressure_moment_arm,
    radius_of_gyration,
)
from pushtoknow.models.context import STEADY_ACCEL, PushContext
from pushtoknow.models.encoding import (
    POSE_DIM,
    SPEED_SCALE,
    ShapeActionEncoding,
    sigma_point_features,
)
from pushtoknow.models.networks import PhysicsProcessNet, PhysicsTacNet

ACCEL_SCALE = 1.0  # m/s², normalises the pad's acceleration features
GATE_ACCEL = 0.5  # m/s²: scale of the gate of the dynamic motion term (below)
CONTACT_REACH = 1e-3  # m: a pad this close to the outline seen counts as touching
CONTACT_SOFTNESS = 5e-4  # m: width of that decision (a traced outline is ~1 mm off)
GEOM_DIM = 19
DYN_DIM = GEOM_DIM + 5
INERTIAL_DIM = GEOM_DIM + 1
_M, _MU, _CX, _CY, _I = (
    PARAM_NAMES.index(k) for k in ("mass", "friction", "com_x", "com_y", "inertia")
)


def _ratio_normalisation(length_scale: float) -> tuple[float, float]:
    """(centre, half-width) of log I_z/(m L²) over the catalogue ranges."""
    (m_lo, m_hi), (i_lo, i_hi) = PARAM_RANGES["mass"], PARAM_RANGES["inertia"]
    lo = math.log(i_lo / (m_hi * length_scale**2))
    hi = math.log(i_hi / (m_lo * length_scale**2))
    return 0.5 * (lo + hi), 0.5 * (hi - lo)


def _in_frame(vec: torch.Tensor, angle: torch.Tensor) -> torch.Tensor:
    """World vectors (B, 2) expressed in frames rotated by angle (B, S) → (B, S, 2)."""
    c, s = angle.cos(), angle.sin()
    vx, vy = vec[:, None, 0], vec[:, None, 1]
    return torch.stack([c * vx + s * vy, -s * vx + c * vy], dim=-1)


@dataclass(frozen=True)
class PhysicsFeatures:
    """Inputs of the physics-structured networks for states (B, S, ·): geom (B, S, GEOM_DIM),
    dyn (B, S, DYN_DIM), inertial (B, S, INERTIAL_DIM), gate (B, S) ∈ [0, 1), mass (kg) and
    friction (B, S), com (B, S, 2) (object frame, m), accel_push (B, 2) the pad's
    acceleration at t in the push frame (m/s²)."""

    geom: torch.Tensor
    dyn: torch.Tensor
    inertial: torch.Tensor
    gate: torch.Tensor
    mass: torch.Tensor
    friction: torch.Tensor
    com: torch.Tensor
    accel_push: torch.Tensor


def physics_features(
    states: torch.Tensor,
    context: PushContext,
    anchor: torch.Tensor,
    length_scale: float,
    motion_params: bool = True,
) -> PhysicsFeatures:
    """Features of states (B, S, 3 + 5) (pose, normalised φ); anchor (B, S or 1, 3): the pose
    each encoding was computed at. The pose, deviation and pad-in-object-frame features are
    the black-box models' (`sigma_point_features`), without m, μ, I_z and the nominal speed.
    motion_params False: `dyn` carries the pad's kinematics alone (μ and I_z/m set to their
    catalogue centres, a/g and v²/(2gL) in place of a/(μg) and v²/(2μgL))."""
    dt = states.dtype
    th = states[..., 2]
    base = sigma_point_features(states, context.pose0, anchor, length_scale, context)
    k = states.shape[-1] - POSE_DIM  # base: pose (4), φ (k), deviation (3), pad (5, speed last)
    velocity, accel, accel_prev = (v.to(dt) for v in context.pad_kinematics())
    geom = torch.cat(
        [
            base[..., :4],
            states[..., 3 + _CX : 3 + _CY + 1],
            base[..., 4 + k : 4 + k + 3 + 4],
            _in_frame(velocity, th) / SPEED_SCALE,
            _in_frame(accel, th) / ACCEL_SCALE,
            _in_frame(accel_prev, th) / ACCEL_SCALE,
        ],
        dim=-1,
    )
    si = denormalise_params(states[..., 3:])
    mass, friction, inertia = si[..., _M], si[..., _MU], si[..., _I]
    centre, half = _ratio_normalisation(length_scale)
    ratio = ((torch.log(inertia / (mass * length_scale**2)) - centre) / half).unsqueeze(-1)
    mu_g = friction * GRAVITY
    mu_norm = states[..., 3 + _MU : 3 + _MU + 1]
    a_now = accel.norm(dim=-1).unsqueeze(1)  # (B, 1)
    a_prev = accel_prev.norm(dim=-1).unsqueeze(1)
    speed_sq = velocity.square().sum(-1).unsqueeze(1)
    motion_ratio = ratio
    if not motion_params:
        mu_g = torch.full_like(mu_g, GRAVITY)
        mu_norm = torch.zeros_like(mu_norm)
        motion_ratio = torch.zeros_like(ratio)
    dyn = torch.cat(
        [
            geom,
            mu_norm,
            motion_ratio,
            (a_now / mu_g).unsqueeze(-1),
            (a_prev / mu_g).unsqueeze(-1),
            (speed_sq / (2 * mu_g * length_scale)).unsqueeze(-1),
        ],
        dim=-1,
    )
    excess = torch.relu(a_now - STEADY_ACCEL) + torch.relu(a_prev - STEADY_ACCEL)
    gate = (1.0 - torch.exp(-excess / GATE_ACCEL)).expand_as(th)
    accel_push = _in_frame(accel, context.direction.to(dt)[:, None])[:, 0]
    return PhysicsFeatures(
        geom,
        dyn,
        torch.cat([geom, ratio], dim=-1),
        gate,
        mass,
        friction,
        si[..., _CX : _CY + 1],
        accel_push,
    )


class MomentArm(ABC):
    """How the limit surface's moment arm ℓ depends on the outline and the CoM, before the
    learned factor κ (`initial_ratio` is κ's starting value)."""

    name: str
    initial_ratio: float

    @abstractmethod
    def __call__(self, footprint: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
        """ℓ / κ (B, S), or (B, 1) when it does not depend on the CoM, in m, for footprint
        (B, V, 2) and CoMs com (B, S, 2), object frame."""


class GyrationArm(MomentArm):
    """ℓ / κ = the footprint's radius of gyration about its centroid, whatever the CoM (a
    disc's uniform-pressure ℓ is 0.94 of it)."""

    name = "gyration"
    initial_ratio = 0.9

    def __call__(self, footprint: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
        return radius_of_gyration(footprint)[:, None]


class PressureArm(MomentArm):
    """ℓ / κ = Σ w_i ‖p_i − c‖ under the support pressure closest to uniform centred at the
    CoM (`models.contact.pressure_moment_arm`): the arm moves with the CoM."""

    name = "pressure"
    initial_ratio = 1.0

    def __call__(self, footprint: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
        return pressure_moment_arm(footprint, com)


MOMENT_ARMS: dict[str, MomentArm] = {arm.name: arm for arm in (GyrationArm(), PressureArm())}


class LimitSurface(nn.Module):
    """Quasi-static pushing of the outline in `context.footprint` (`models.contact`) with a
    learned moment arm ℓ = κ · `moment_arm`(footprint, CoM); pad_radius (m)."""

    def __init__(self, pad_radius: float, moment_arm: MomentArm | None = None):
        super().__init__()
        self.pad_radius = float(pad_radius)
        self.moment_arm = moment_arm or GyrationArm()
        self.log_ratio = nn.Parameter(torch.tensor(math.log(self.moment_arm.initial_ratio)))

    def forward(
        self, pose: torch.Tensor, com: torch.Tensor, context: PushContext
    ) -> LimitSurfacePush:
        """The step that ends at sample t (the pad from the window's sample t-1 to t) of
        sliders at poses (B, S, 3) with CoMs com (B, S, 2) (object frame, m)."""
        if context.footprint is None or context.pad_window is None:
            raise ShapeError("limit-surface models need the footprint and the pad's track")
        fp = context.footprint.to(pose.dtype)
        window = context.pad_window.to(pose.dtype)
        arm = self.arm(fp, com)
        return limit_surface_push(
            pose,
            com,
            window[:, 1],
            window[:, 2],
            fp,
            self.pad_radius,
            arm,
            CONTACT_REACH,
            CONTACT_SOFTNESS,
        )

    def arm(self, footprint: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
        """ℓ = κ · `moment_arm`(footprint, com) (m), (B, S) or (B, 1)."""
        return self.log_ratio.exp().to(footprint.dtype) * self.moment_arm(footprint, com)

    def slide(self, states: torch.Tensor, f: PhysicsFeatures, context: PushContext) -> torch.Tensor:
        """(B, S, 3): the free slide (`models.contact.free_slide`) of sliders at states
        (B, S, 3 + 5) released by the pad at its window's sample t-1 with the release speed of
        `context.release`; μ, m and I_z of each sigma point from `f`."""
        if context.footprint is None or context.pad_window is None or context.release is None:
            raise ShapeError("the free slide needs the footprint, the pad's track and release")
        pose = states[..., :POSE_DIM]
        fp = context.footprint.to(pose.dtype)
        arm = self.arm(fp, f.com)
        inertia = denormalise_params(states[..., POSE_DIM:])[..., _I]
        return free_slide(
            pose,
            f.com,
            context.pad_window.to(pose.dtype)[:, 1],
            context.direction.to(pose.dtype),
            context.release[:, 1].to(pose.dtype),
            f.friction * GRAVITY,
            inertia / (f.mass * arm.square()),
            fp,
            self.pad_radius,
            arm,
            CONTACT_REACH,
            CONTACT_SOFTNESS,
        )


class PhysicsDynamics(DynamicsModel):
    """(Δψ, Q) from `PhysicsProcessNet` on the physics features of each sigma point, plus the
    limit surface's quasi-static step of the pad over the step when there is one."""

    def __init__(
        self,
        encoding: ShapeActionEncoding,
        process_net: PhysicsProcessNet,
        limit_surface: LimitSurface | None = None,
        free_slide: bool = False,
        motion_params: bool = True,
    ):
        super().__init__()
        self.encoding = encoding
        self.process_net = process_net
        self.limit_surface = limit_surface
        self.free_slide = free_slide
        self.motion_params = motion_params

    def forward(
        self, states: torch.Tensor, context: PushContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        enc, anchor = self.encoding(states[..., :POSE_DIM], context)
        length = self.encoding.config.length_scale
        f = physics_features(states, context, anchor, length, self.motion_params)
        delta, q = self.process_net(f.geom, f.dyn, f.gate, enc)
        if self.limit_surface is not None:
            pushed = self.limit_surface(states[..., :POSE_DIM], f.com, context).twist
            released = self.release_step(context) if self.free_slide else None
            if released is not None and bool(released.any()):
                # the release step: the pad stops, the object slides to rest without it
                slide = self.limit_surface.slide(states, f, context)
                pushed = torch.where(released[:, None, None], slide, pushed)
            delta = delta + pushed
        return delta, q

    @staticmethod
    def release_step(context: PushContext) -> torch.Tensor:
        """(B,) bool: the step that ends at `context.time` is the one whose start the pad's
        release falls on, (t − 1)·dt ≤ t_r < t·dt (`PushContext.release`)."""
        if context.release is None or context.time is None:
            raise ShapeError("free-slide models need the pushes' release points and the time")
        t_r = context.release[:, 0].to(context.time.dtype)
        start = context.time - context.step_dt
        return (t_r >= start - 1e-6) & (t_r < context.time - 1e-6)


class PhysicsObservation(ObservationModel):
    """h(s) = (x, y, θ, F_x, F_y) with F = m (μ g G + J a) rotated from the push frame to the
    world (`PhysicsTacNet`)."""

    def __init__(self, encoding: ShapeActionEncoding, tac_net: PhysicsTacNet):
        super().__init__()
        self.encoding = encoding
        self.tac_net = tac_net
        self.include_contact = False
        self.obs_dim = POSE_DIM + 2
        self.angle_indices = (2,)

    def tactile(
        self, states: torch.Tensor, context: PushContext
    ) -> tuple[torch.Tensor, torch.Tensor]:
        """Forces (B, S, 2) in N (world) and contact logits (B, S) for states (B, S, D)."""
        enc, anchor = self.encoding(states[..., :POSE_DIM], context)
        f = physics_features(states, context, anchor, self.encoding.config.length_scale)
        g, j, logit = self.tac_net(f.geom, f.inertial, enc)
        pd = context.direction.to(states.dtype)[:, None]
        a = f.accel_push.unsqueeze(1).unsqueeze(-1)  # (B, 1, 2, 1)
        push_frame = f.mass.unsqueeze(-1) * (
            (f.friction * GRAVITY).unsqueeze(-1) * g + (j @ a).squeeze(-1)
        )
        c, s = pd.cos(), pd.sin()
        along, across = push_frame[..., 0], push_frame[..., 1]
        world = torch.stack([c * along - s * across, s * along + c * across], dim=-1)
        return world, logit

    def forward(self, states: torch.Tensor, context: PushContext) -> torch.Tensor:
        forces, _ = self.tactile(states, context)
        return torch.cat([states[..., :POSE_DIM], forces], dim=-1)
