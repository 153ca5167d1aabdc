"""Typed configuration of the testbed (loadable from YAML)."""

from __future__ import annotations

import json
from typing import Literal

from pydantic import Field

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import TestbedVersionError
from pushtoknow.common.frozen_config import Config


class CameraConfig(Config):
    width: int = Field(64, gt=0)
    height: int = Field(64, gt=0)
    fovy_deg: float = Field(45.0, gt=0, lt=170)
    distance: float = Field(0.75, gt=0, description="camera height above the table (m)")
    outline_scale: int = Field(
        4,
        ge=1,
        le=16,
        description="S_0's object mask is also taken at this many times the images' resolution "
        "(a real RGB-D camera's full resolution; the images are what VisNet sees), and the "
        "object's outline is traced on it",
    )

    def model(self) -> CameraModel:
        return CameraModel(self.width, self.height, self.fovy_deg, (0.0, 0.0, self.distance))


class SupportConfig(Config):
    """Support model: the object is a planar rigid body (x, y, θ joints) resting on point supports.

    Each support point is a small body on a vertical slide joint, pressed on the table by a fixed
    share w_i of the weight; the shares are the ones closest to uniform whose centre is the CoM
    (a linear pressure, as a rigid body on an elastic foundation, lifted off where it would be
    negative). Each point's Coulomb friction is then μ·w_i·m·g while it slides, and nothing can
    tilt, rock or bounce: the planar motion depends on the pressure distribution, not on m or μ
    separately (quasi-static pushing), and a released object slides by Coulomb's law. See
    docs/PHYSICS.md for the measurements.
    """

    spacing: float = Field(0.016, gt=0, description="grid pitch of the support points (m)")
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
    contact_timeconst: float = Field(
        0.002,
        gt=0,
        description="time constant of the pad–object contact (s; MuJoCo uses at least two "
        "physics steps): a stiff pad lets go of a released object within ~2 ms",
    )


class TactileConfig(Config):
    rate_hz: float = Field(10.0, gt=0)
    force_noise_std: float = Field(0.05, ge=0, description="zero-mean Gaussian noise (N)")
    contact_threshold: float = Field(0.5, ge=0, le=1, description="share of window in contact")


class PhysicsConfig(Config):
    timestep: float = Field(0.004, gt=0, description="physics step (s)")
    dynamic_substeps: int = Field(
        4,
        ge=1,
        description="physics steps per `timestep` during a release push's dynamic phase "
        "(acceleration, release, slide): 1 ms steps keep the semi-implicit Euler lag of a "
        "slide (v·dt/2) below 2% of v²/(2μg)",
    )
    cone: Literal["pyramidal", "elliptic"] = "elliptic"
    solver: Literal["CG", "Newton"] = Field(
        "CG",
        description="constraint solver: CG is 4× faster than Newton on the ~40 support "
        "DOFs and agrees with it to 1e-6 m over a push",
    )
    impratio: float = Field(
        100.0, gt=0, description="friction-to-normal impedance ratio: stiff Coulomb friction"
    )
    table_friction: float = Field(0.0, ge=0, description="combined by max: object μ wins")


class PushConfig(Config):
    """Push timing and speed profiles.

    Constant pushes move the object about 10 cm (6 s at 20 mm/s after a 15 mm approach):
    pushing with a point contact is unstable (a 50 µm offset grows ~15-fold per metre pushed,
    as real pushing does), so shorter pushes keep centred pushes reproducible to the sensors'
    resolution. Release pushes stay within the limits assumed for a real arm's end effector:
    speed ≤ 1 m/s, acceleration ≤ 10 m/s² (a Franka Panda allows 1.7 m/s and 13 m/s²; a UR5e
    about 1 m/s and, for short moves, similar accelerations).
    """

    horizon: float = Field(6.0, gt=0, description="t_H (s)")
    speed: float = Field(0.02, gt=0, description="constant-profile speed (m/s)")
    approach_gap: float = Field(0.015, ge=0, description="pad starts this far outside (m)")
    release_peak_speed: float = Field(0.4, gt=0, description="release speed (m/s)")
    release_accel: float = Field(
        1.0, gt=0, description="m/s² from rest to the release speed (0.4 s, 4 tactile samples)"
    )
    release_decel: float = Field(
        10.0,
        gt=0,
        description="m/s² the pad brakes at; above μ·g, so the object leaves the pad and slides "
        "free (objects with μ ≥ release_decel/g follow the pad instead)",
    )

    def profile_speed(self, profile: str) -> float:
        """The characteristic speed (m/s) of a speed profile: the constant speed, or the
        release's peak."""
        return self.speed if profile == "constant" else self.release_peak_speed


TESTBED_VERSION = 2
"""Physics version of the testbed. 1: free-joint object on soft point supports (chaotic, not
quasi-static, see docs/PHYSICS.md); 2: planar object on loaded supports. Data and models record
the version they were simulated with; a simulator refuses any other."""


class SimConfig(Config):
    camera: CameraConfig = CameraConfig()
    support: SupportConfig = SupportConfig()
    pad: PadConfig = PadConfig()
    tactile: TactileConfig = TactileConfig()
    physics: PhysicsConfig = PhysicsConfig()
    push: PushConfig = PushConfig()
    testbed_version: int = Field(
        TESTBED_VERSION, description="physics version the data were simulated with"
    )
    workspace_half_extent: float = Field(0.03, ge=0, description="initial xy offset range (m)")
    render: bool = True
    orientation_marker: bool = Field(
        True,
        description="paint the +x half of the object's top face dark (1 mm decal, no mass, no "
        "contacts) so that vision sees θ of round and symmetric shapes",
    )


def stored_sim_config(raw: dict | str | None) -> SimConfig:
    """The SimConfig stored with a dataset or a model (dict or JSON string). Settings saved
    before `orientation_marker` existed were rendered without the marker; settings saved before
    `testbed_version` existed come from testbed version 1, with its physics defaults."""
    if raw is None:
        raw = {}
    data = json.loads(raw) if isinstance(raw, str) else dict(raw)
    data.setdefault("orientation_marker", False)
    if "testbed_version" not in data:
        data["testbed_version"] = 1
        for section, defaults in V1_DEFAULTS.items():
            data[section] = {**defaults, **data.get(section, {})}
    return SimConfig.model_validate(data)


# Defaults that changed with testbed version 2, for reading version-1 records faithfully.
V1_DEFAULTS: dict[str, dict] = {
    "push": {"horizon": 10.0, "release_accel": 0.5, "release_decel": 20.0},
    "support": {"spacing": 0.012},
    "physics": {"dynamic_substeps": 1, "impratio": 1.0, "solver": "Newton"},
    "pad": {"contact_timeconst": 0.02},
}


def check_testbed_version(config: SimConfig, what: str) -> None:
    """Raise TestbedVersionError unless `config` is of this testbed version; `what` names the
    data or model it came from."""
    if config.testbed_version != TESTBED_VERSION:
        raise TestbedVersionError(
            f"{what} are of testbed version {config.testbed_version}, but this pushtoknow "
            f"simulates version {TESTBED_VERSION} (docs/PHYSICS.md): regenerate the data or "
            "retrain the model"
        )
