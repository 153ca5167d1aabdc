"""`PushSimulator.set_params`: another object of the same outline in a compiled scene."""

import dataclasses

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import ObjectParams
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.random_shapes import random_object_at
from pushtoknow.testbed.scene import mass_layout
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

CONFIG = SimConfig(render=False)
SPEC = random_object_at(101, 0)


def _push(profile: str) -> Push:
    x_min = float(SPEC.footprint.polygon.bounds[0])
    return Push((x_min, 0.0), 0.0, profile, 0.02 if profile == "constant" else 0.4)


def _run(sim: PushSimulator, push: Push, start=None):
    sim.reset((0.01, -0.02, 0.3))
    return sim.execute(push, np.random.default_rng(0), start=start)


def _scaled(p: ObjectParams, mass: float, friction: float, inertia: float) -> ObjectParams:
    return dataclasses.replace(
        p, mass=p.mass * mass, friction=p.friction * friction, inertia=p.inertia * inertia
    )


@settings(max_examples=4, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(
    mass=st.floats(0.6, 1.5),
    friction=st.floats(0.6, 1.5),
    inertia=st.floats(0.9, 1.1),
    profile=st.sampled_from(["constant", "release"]),
)
def test_set_params_replays_bit_identically_to_a_fresh_build(mass, friction, inertia, profile):
    """The same CoM keeps the same supports: the compiled scene given new m, μ, I_z replays
    exactly as a scene built for them."""
    params = _scaled(SPEC.params, mass, friction, inertia)
    fresh = PushSimulator(dataclasses.replace(SPEC, params=params), CONFIG)
    want = _run(fresh, _push(profile))
    reused = PushSimulator(SPEC, CONFIG)
    _run(reused, _push(profile))  # dirty its data first
    assert reused.set_params(params)
    got = _run(reused, _push(profile), start=want.pusher[0])
    np.testing.assert_array_equal(got.pose, want.pose)
    np.testing.assert_array_equal(got.force_clean, want.force_clean)
    assert reused.spec.params == params


def test_set_params_refuses_a_com_that_needs_other_supports_and_changes_nothing():
    p = SPEC.params
    sim = PushSimulator(SPEC, CONFIG)
    before = sim.model.body_mass.copy(), sim.model.geom_friction.copy()
    far = None
    for dx in np.linspace(-0.01, 0.01, 21):  # a CoM whose loads lift other supports off
        q = dataclasses.replace(p, com_x=p.com_x + dx, friction=0.9)
        try:
            layout = mass_layout(dataclasses.replace(SPEC, params=q), CONFIG)
        except ValueError:
            continue
        if len(layout.points) != len(mass_layout(SPEC, CONFIG).points):
            far = q
            break
    assert far is not None, "a CoM 1 cm off lifts other supports off on this object"
    assert not sim.set_params(far)
    np.testing.assert_array_equal(sim.model.body_mass, before[0])
    np.testing.assert_array_equal(sim.model.geom_friction, before[1])
    assert sim.spec == SPEC
