"""Physics fidelity of the testbed (docs/PHYSICS.md): every test here fails on testbed v1."""

import math

import numpy as np
import pytest

from pushtoknow.common.errors import TestbedVersionError
from pushtoknow.common.params import CATALOGUE_GRID, GRAVITY
from pushtoknow.testbed import fidelity as fid
from pushtoknow.testbed.push import release_profile
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig, stored_sim_config

SENSOR_NOISE_N = SimConfig().tactile.force_noise_std


@pytest.mark.parametrize("shape", ["rect1", "hex", "ellip2", "tri1"])
def test_centred_push_is_reproducible_to_the_sensor_noise(shape):
    s = fid.start_pose_sensitivity(shape, 0.0)
    assert s.travel_mm > 50.0  # a real push
    assert s.force_rms_n <= SENSOR_NOISE_N
    assert s.final_mm <= 1.0
    assert s.final_deg <= 0.5


def test_off_centre_push_sensitivity_is_bounded():
    s = fid.start_pose_sensitivity("rect1", 0.02)
    assert abs(s.turn_deg) > 20.0  # it does turn
    assert s.force_rms_n <= SENSOR_NOISE_N
    assert s.final_mm <= 1.0 and s.final_deg <= 0.5


def test_quasi_static_path_does_not_depend_on_mass_or_friction():
    spread = fid.start_pose_sensitivity("rect1", 0.02)  # the chaotic spread of this push
    for varied, values in (("mass", (0.8, 0.2, 1.2)), ("friction", (0.5, 0.35, 0.7))):
        dep = fid.path_dependence(varied, values)
        assert dep.max_mm <= max(spread.final_mm, 0.1), varied
        assert dep.max_deg <= max(spread.final_deg, 0.1), varied
        # The force, in units of μ·m·g, has one shape whatever m and μ.
        assert dep.force_shape_diff < 0.03, varied


@pytest.mark.parametrize("mass", CATALOGUE_GRID["mass"])
def test_steady_force_is_mu_m_g_within_one_percent(mass):
    for mu in CATALOGUE_GRID["friction"]:
        s = fid.steady_force(mass, mu)
        assert s.ratio == pytest.approx(1.0, abs=0.01), (mass, mu)


def test_force_chatter_does_not_depend_on_friction():
    # Physics-rate force fluctuation while sliding steadily: a tenth of the sensor noise at
    # most, whatever μ (testbed v1: 0.23–1.4 N at μ = 0.35, 0.39–2.5 N at μ = 0.7).
    for mu in (0.35, 0.5, 0.7):
        assert fid.steady_force(0.8, mu).chatter_n < 0.1 * SENSOR_NOISE_N, mu


@pytest.mark.parametrize("mu", CATALOGUE_GRID["friction"])
def test_release_has_no_spike_no_flight_and_slides_by_coulomb(mu):
    light, heavy = fid.release_push(0.2, mu), fid.release_push(1.2, mu)
    for r in (light, heavy):
        assert r.peak_force_ratio < 1.05  # braking never pushes harder than accelerating
        assert r.onset_force_ratio < 1.5  # the pad starts touching: no impact
        assert r.min_support_load > 0.95 and r.flight_s == 0.0
        assert r.slide_ratio == pytest.approx(1.0, abs=0.05)  # v²/(2μg)
        assert r.creep_um < 5.0  # at rest means at rest
    assert light.slide_mm == pytest.approx(heavy.slide_mm, rel=0.005)  # independent of m


def test_release_profile_is_within_arm_limits():
    pc = SimConfig().push
    prof = release_profile(pc.release_peak_speed, pc.release_accel, pc.release_decel, pc.horizon)
    t, v = np.asarray(prof.times), np.asarray(prof.speeds)
    accel = np.abs(np.diff(v) / np.diff(t))
    assert v.max() <= 1.0  # m/s
    assert accel.max() <= 10.0 + 1e-9  # m/s²
    # ... and brakes faster than any catalogue object decelerates, so the object slides free.
    assert pc.release_decel > max(CATALOGUE_GRID["friction"]) * GRAVITY


@pytest.mark.parametrize(("mass", "mu"), [(0.2, 0.35), (0.5, 0.5), (1.2, 0.7)])
def test_release_record_at_10_hz_reveals_mass_and_friction(mass, mu):
    # The dynamic phases reach the sensors: the acceleration phase spans 4 tactile samples and
    # the slide ends in a rest pose that every later image shows.
    rec = fid.push_through(fid.probe_object("rect1", mass, mu), 0.0, "release")
    reading = fid.read_release(rec)
    assert reading.friction == pytest.approx(mu, rel=0.05)
    assert reading.mass == pytest.approx(mass, rel=0.10)


def test_simulator_refuses_another_testbed_version():
    old = stored_sim_config({"push": {"horizon": 10.0}})  # saved before versions existed
    assert old.testbed_version == 1
    assert old.push.release_decel == 20.0  # version 1's defaults are read back faithfully
    with pytest.raises(TestbedVersionError, match="version 1"):
        PushSimulator(fid.probe_object(), old)


def test_support_load_is_the_objects_weight_at_rest():
    sim = PushSimulator(fid.probe_object("tri1", 0.5, 0.5, (0.01, -0.01)))
    sim.reset((0.0, 0.0, 0.3))
    assert sim.support_load() == pytest.approx(1.0, abs=1e-3)
    assert math.isclose(sim.object_pose()[2], 0.3, abs_tol=1e-9)
