"""The written-down free slide of a released object (`models.physics.free_slide_gap`): closed
forms, and the testbed's centred release pushes."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import GRAVITY
from pushtoknow.models.learned import PushContext, with_pad_track
from pushtoknow.models.physics import PhysicsDynamics, free_slide_gap
from pushtoknow.testbed import fidelity as fid
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.push import Push, release_point, release_points

PUSH = SimConfig().push


def _release(v=0.4, t_r=0.4, decel=10.0):
    return torch.tensor([[t_r, v, decel]])


def test_release_point_of_each_profile():
    release = Push((0.0, 0.0), 0.0, "release", PUSH.release_peak_speed)
    t_r, v_r, decel = release_point(release, PUSH)
    assert t_r == pytest.approx(PUSH.release_peak_speed / PUSH.release_accel)
    assert v_r == PUSH.release_peak_speed and decel == pytest.approx(PUSH.release_decel)
    assert release_point(Push((0.0, 0.0), 0.0, "constant", 0.02), PUSH) == (math.inf, 0.0, 0.0)


@given(
    v=st.floats(0.05, 1.0),
    mu=st.floats(0.1, 0.9),
    decel=st.floats(10.0, 40.0),
)
@settings(max_examples=50, deadline=None)
def test_gap_at_rest_is_the_difference_of_the_stopping_distances(v, mu, decel):
    gap = free_slide_gap(torch.tensor([10.0]), _release(v, 0.4, decel), torch.tensor([[mu]]))
    expected = v**2 / (2 * mu * GRAVITY) - v**2 / (2 * decel)
    assert float(gap) == pytest.approx(max(expected, 0.0), rel=1e-4, abs=1e-9)


def test_no_gap_before_the_release_for_a_constant_push_or_for_a_sticky_object():
    mu = torch.tensor([[0.5]])
    assert float(free_slide_gap(torch.tensor([0.39]), _release(), mu)) == 0.0
    never = torch.tensor([[math.inf, 0.0, 0.0]])
    assert float(free_slide_gap(torch.tensor([3.0]), never, mu)) == 0.0
    # μ g ≥ D: the object decelerates with the pad and stays on it
    assert float(free_slide_gap(torch.tensor([1.0]), _release(decel=4.0), mu)) == 0.0


def test_gap_grows_monotonically_and_lower_friction_slides_further():
    times = torch.linspace(0.0, 1.0, 101)
    mus = torch.tensor([[0.35, 0.5, 0.7]]).expand(101, 3)
    gap = free_slide_gap(times, _release().expand(101, 3), mus)
    assert (gap.diff(dim=0) >= -1e-9).all()
    assert (gap[-1, 0] > gap[-1, 1]) and (gap[-1, 1] > gap[-1, 2])


def test_slide_step_follows_the_push_direction_and_sums_to_the_gap():
    paths = torch.zeros(1, 12, 2)
    ctx = PushContext(
        mask0=torch.zeros(1, 1, 4, 4),
        pose0=torch.zeros(1, 3),
        contact_xy=torch.zeros(1, 2),
        direction=torch.tensor([math.pi / 2]),
        speed=torch.tensor([0.4]),
        camera=None,  # type: ignore[arg-type]
        release=_release(),
    )
    mu = torch.tensor([[0.4]])
    steps = [
        PhysicsDynamics.slide_step(with_pad_track(ctx, paths, t, 0.1), mu) for t in range(1, 12)
    ]
    total = torch.stack(steps).sum(0)[0, 0]
    gap = free_slide_gap(torch.tensor([1.1]), _release(), mu)
    assert float(total[0]) == pytest.approx(0.0, abs=1e-7)  # along +y only
    assert float(total[1]) == pytest.approx(float(gap), rel=1e-5)
    assert float(total[2]) == 0.0


def test_release_points_of_pushes():
    pushes = [Push((0, 0), 0.0, "constant", 0.02), Push((0, 0), 0.0, "release", 0.4)]
    r = release_points(pushes, PUSH)
    assert r.shape == (2, 3) and np.isinf(r[0, 0]) and r[1, 1] == pytest.approx(0.4)


@pytest.mark.parametrize(("mass", "mu"), [(0.2, 0.35), (1.2, 0.7)])
def test_gap_matches_the_testbeds_centred_release_push(mass, mu):
    """The object's lead over the pad, sample by sample, in a simulated centred release push."""
    rec = fid.push_through(fid.probe_object("rect1", mass, mu), 0.0, "release")
    u = rec.push.unit
    lead = (rec.pose[:, :2] - rec.pusher) @ u
    lead = lead - lead[int(PUSH.release_peak_speed / PUSH.release_accel * 10) - 1]
    times = torch.as_tensor(rec.time, dtype=torch.float32)
    release = torch.as_tensor(release_points([rec.push], PUSH), dtype=torch.float32)
    release = release.expand(len(times), 3)
    model = free_slide_gap(times, release, torch.full((len(times), 1), mu))[:, 0].numpy()
    after = rec.time >= PUSH.release_peak_speed / PUSH.release_accel
    assert np.abs(lead[after] - model[after]).max() < 1.5e-3  # m
    assert lead[-1] == pytest.approx(model[-1], abs=1e-3)
