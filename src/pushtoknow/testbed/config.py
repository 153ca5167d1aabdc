"""Typed configuration of the testbed (loadable from YAML)."""

from __future__ import annotations

import json
from typing import Literal

from pydantic import Field

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.config import Config


class CameraConfig(Config):
    width: int = Field(64, gt=0)
    height: int = Field(64, gt=0)
    fovy_deg: float = Field(45.0, gt=0, lt=170)
    distance: float = Field(0.75, gt=0, description="camera height above the table (m)")

    def model(self) -> CameraModel:
        return CameraModel(self.width, self.height, self.fovy_deg, (0.0, 0.0, self.distance))


class SupportConfig(Config):
    """Support model: the object rests on a grid of small spheres filling its footprint.

    Measured (tests/testbed/test_physics.py): centred-push force within 0.1% of μ·m·g; the
    free-slide deceleration after a release within 3% of μ·g for μ ∈ {0.35, 0.5, 0.7}, m ∈ {0.3,
    1.2} kg (13 mm objects, pad at 6.5 mm, 0.5 m/s² ramp; a 1 m/s² ramp makes the object rock on
    the soft contacts and the error grows to 35%).

    A rigid prism on a plane gets MuJoCo contacts only at its corners, which concentrates the
    pressure there and changes how a pushed object turns (≈12° over a push). A uniform grid of
    point supports approximates a uniform pressure distribution; the free joint lets the object
    tilt microscopically so the soft contacts put the centre of pressure under the CoM.
    """

    spacing: float = Field(0.012, gt=0, description="grid pitch of the support points (m)")
    radius: float = Field(0.001, gt=0, description="support sphere radius (m)")
    edge_margin: float = Field(0.002, ge=0, description="support points keep this far inside (m)")


class PadConfig(Config):
    """Finger pad: a vertical cylinder driven kinematically in the table plane.

    friction = 0 (condim 1) by default: MuJoCo's pad friction acting on the vertical chatter of
    a sliding object biases the measured force by +8–22%; a frictionless pad keeps the tactile
    force equal to the support friction force on a centred push (tested within 5%). Set
    friction > 0 to model a grippy pad (condim 3).
    """

    radius: float = Field(0.005, gt=0)
    half_height: float = Field(0.0045, gt=0)
    z: float = Field(
        0.0065, gt=0, description="pad centre height (m), mid-height of a 13 mm object"
    )
    friction: float = Field(0.0, ge=0)
    mass: float = Field(50.0, gt=0, description="mass of the (kinematically overridden) pad body")


class TactileConfig(Config):
    rate_hz: float = Field(10.0, gt=0)
    force_noise_std: float = Field(0.05, ge=0, description="zero-mean Gaussian noise (N)")
    contact_threshold: float = Field(0.5, ge=0, le=1, description="share of window in contact")


class PhysicsConfig(Config):
    timestep: float = Field(
        0.004, gt=0, description="4 ms: force within 0.1% of μ·m·g at 48× real time (2 ms: 26×)"
    )
    cone: Literal["pyramidal", "elliptic"] = "elliptic"
    table_friction: float = Field(0.0, ge=0, description="combined by max: object μ wins")


class PushConfig(Config):
    horizon: float = Field(10.0, gt=0, description="t_H (s)")
    speed: float = Field(0.02, gt=0, description="constant-profile speed (m/s)")
    approach_gap: float = Field(0.015, ge=0, description="pad starts this far outside (m)")
    release_peak_speed: float = Field(0.4, gt=0)
    release_accel: float = Field(0.5, gt=0, description="m/s² up to the peak speed")
    release_decel: float = Field(20.0, gt=0, description="m/s², must exceed μ·g to let go")


class SimConfig(Config):
    camera: CameraConfig = CameraConfig()
    support: SupportConfig = SupportConfig()
    pad: PadConfig = PadConfig()
    tactile: TactileConfig = TactileConfig()
    physics: PhysicsConfig = PhysicsConfig()
    push: PushConfig = PushConfig()
    workspace_half_extent: float = Field(0.03, ge=0, description="initial xy offset range (m)")
    render: bool = True
    orientation_marker: bool = Field(
        True,
        description="paint the +x half of the object's top face dark (1 mm decal, no mass, no "
        "contacts) so that vision sees θ of round and symmetric shapes",
    )


def stored_sim_config(raw: dict | str | None) -> SimConfig:
    """The SimConfig stored with a dataset or a model (dict or JSON string). Settings saved
    before `orientation_marker` existed were rendered without the marker."""
    if raw is None:
        return SimConfig(orientation_marker=False)
    data = json.loads(raw) if isinstance(raw, str) else dict(raw)
    data.setdefault("orientation_marker", False)
    return SimConfig.model_validate(data)
