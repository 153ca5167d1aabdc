"""The free slide of a released object (`models.contact.free_slide`): closed forms, the release
points of the push profiles, and the testbed's release pushes, centred and off-centre."""

import dataclasses
import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import GRAVITY, ObjectParams
from pushtoknow.models.contact import free_slide, radius_of_gyration
from pushtoknow.models.context import PushContext, with_pad_track
from pushtoknow.models.physics import (
    CONTACT_REACH,
    CONTACT_SOFTNESS,
    GyrationArm,
    PhysicsDynamics,
)
from pushtoknow.testbed import fidelity as fid
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push, release_point, release_points
from pushtoknow.testbed.sim_config import SimConfig

F64 = torch.float64
PUSH = SimConfig().push
HALF = 0.04  # m: half side of the square below
SQUARE = torch.tensor([[[-HALF, -HALF], [HALF, -HALF], [HALF, HALF], [-HALF, HALF]]], dtype=F64)


def _slide(com=(0.0, 0.0), pad_y=0.0, speed=0.4, mu=0.5, k=1.0, pad_x=-HALF - 0.005):
    """The free slide of the square at the origin released by a pad moving along +x."""
    ell = GyrationArm.initial_ratio * radius_of_gyration(SQUARE)
    return free_slide(
        torch.zeros(1, 1, 3, dtype=F64),
        torch.tensor([[com]], dtype=F64),
        torch.tensor([[pad_x, pad_y]], dtype=F64),
        torch.zeros(1, dtype=F64),
        torch.tensor([speed], dtype=F64),
        torch.tensor([[mu * GRAVITY]], dtype=F64),
        torch.tensor([[k]], dtype=F64),
        SQUARE,
        0.005,
        ell,
        CONTACT_REACH,
        CONTACT_SOFTNESS,
    )[0, 0]


def test_release_point_of_each_profile():
    release = Push((0.0, 0.0), 0.0, "release", PUSH.release_peak_speed)
    t_r, v_r, decel = release_point(release, PUSH)
    assert t_r == pytest.approx(PUSH.release_peak_speed / PUSH.release_accel)
    assert v_r == PUSH.release_peak_speed and decel == pytest.approx(PUSH.release_decel)
    assert release_point(Push((0.0, 0.0), 0.0, "constant", 0.02), PUSH) == (math.inf, 0.0, 0.0)
    r = release_points([Push((0, 0), 0.0, "constant", 0.02), release], PUSH)
    assert r.shape == (2, 3) and np.isinf(r[0, 0]) and r[1, 1] == pytest.approx(0.4)


@given(speed=st.floats(0.05, 1.0), mu=st.floats(0.1, 0.9), k=st.floats(0.3, 3.0))
@settings(max_examples=30, deadline=None)
def test_a_centred_release_slides_v2_over_2_mu_g_straight_ahead(speed, mu, k):
    out = _slide(speed=speed, mu=mu, k=k)
    assert float(out[0]) == pytest.approx(speed**2 / (2 * mu * GRAVITY), rel=1e-3)
    assert abs(float(out[1])) < 1e-9 and abs(float(out[2])) < 1e-9


def test_an_off_centre_release_turns_more_with_more_inertia_and_a_free_pad_does_nothing():
    light, heavy = _slide(pad_y=0.02, k=0.5), _slide(pad_y=0.02, k=2.0)
    assert float(light[2]) < 0 and float(heavy[2]) < float(light[2])  # pushed below the CoM
    assert float(light[0]) < 0.4**2 / (2 * 0.5 * GRAVITY)  # part of the push went into the turn
    far = _slide(pad_x=-HALF - 0.02)  # the pad is 15 mm off the outline: it was not pushing
    assert torch.equal(far, torch.zeros(3, dtype=F64))


def test_the_slide_replaces_the_pads_push_in_the_release_step_only():
    paths = torch.zeros(1, 12, 2)
    ctx = PushContext(
        mask0=torch.zeros(1, 1, 4, 4),
        pose0=torch.zeros(1, 3),
        contact_xy=torch.zeros(1, 2),
        direction=torch.zeros(1),
        speed=torch.tensor([0.4]),
        camera=None,  # type: ignore[arg-type]
        release=torch.tensor([[0.4, 0.4, 10.0]]),
    )
    steps = [
        bool(PhysicsDynamics.release_step(with_pad_track(ctx, paths, t, 0.1))) for t in range(1, 12)
    ]
    assert steps == [t == 5 for t in range(1, 12)]  # the step from sample 4 (0.4 s) to 5
    never = dataclasses.replace(ctx, release=torch.tensor([[math.inf, 0.0, 0.0]]))
    assert not any(
        bool(PhysicsDynamics.release_step(with_pad_track(never, paths, t, 0.1)))
        for t in range(1, 12)
    )


@pytest.mark.parametrize("offset", [0.0, 0.01])
@pytest.mark.parametrize("inertia_scale", [0.6, 1.5])
def test_the_slide_matches_the_testbeds_release_pushes(offset, inertia_scale):
    """From the pose at the release (sample 4) to rest, in a simulated release push of rect1
    on the line `offset` from its centre."""
    params = ObjectParams(0.8, 0.5, 0.0, 0.0, inertia_scale * fid.uniform_inertia("rect1", 0.8))
    spec = ObjectSpec(shape="rect1", params=params)
    rec = fid.push_through(spec, offset, "release")
    k_r = int(round(PUSH.release_peak_speed / PUSH.release_accel * SimConfig().tactile.rate_hz))
    fp = torch.tensor(np.asarray(spec.footprint.polygon.exterior.coords)[:-1], dtype=F64)[None]
    ell = GyrationArm.initial_ratio * radius_of_gyration(fp)
    out = free_slide(
        torch.tensor(rec.pose[k_r], dtype=F64)[None, None],
        torch.zeros(1, 1, 2, dtype=F64),
        torch.tensor(rec.pusher[k_r], dtype=F64)[None],
        torch.zeros(1, dtype=F64),
        torch.tensor([PUSH.release_peak_speed], dtype=F64),
        torch.tensor([[params.friction * GRAVITY]], dtype=F64),
        torch.tensor([[params.inertia / (params.mass * float(ell) ** 2)]], dtype=F64),
        fp,
        0.005,
        ell,
        CONTACT_REACH,
        CONTACT_SOFTNESS,
    )[0, 0].numpy()
    recorded = rec.pose[-1] - rec.pose[k_r]
    assert np.linalg.norm(out[:2] - recorded[:2]) < 1.5e-3  # m, of a 14–17 mm slide
    assert abs(math.degrees(out[2] - recorded[2])) < 1.2  # of up to 4° of turn
