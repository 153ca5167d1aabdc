"""The mujoco.sysid baseline (`identification.sysid_baseline`): its model of the scene against
the testbed's replay, its support loads against the testbed's, a fit of one short noiseless
push from a perturbed start, and one-line errors for bad input."""

import json

import numpy as np
import pytest

from pushtoknow.common.errors import IdentificationError
from pushtoknow.common.params import ObjectParams
from pushtoknow.identification.replay import PushTrack, ReplayScene, simulate_track
from pushtoknow.identification.sysid_baseline import (
    SupportLayout,
    sysid_fit,
    sysid_residuals,
)
from pushtoknow.testbed.objects import ObjectSpec, resolve_shape
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.scene import support_loads, support_points
from pushtoknow.testbed.sim import PushSimulator
from pushtoknow.testbed.sim_config import SimConfig

# 2 s pushes, no images; the pad starts 3 mm off the object so it pushes for 1.85 s (37 mm)
SHORT = SimConfig(render=False).model_copy(
    update={
        "push": SimConfig().push.model_copy(update={"horizon": 2.0, "approach_gap": 0.003}),
    }
)
PHI = np.array([0.5, 0.5, 0.01, -0.006, 1.0e-3])
SPEC = ObjectSpec("rect1", ObjectParams.from_array(PHI), name="tiny")
SCENE = ReplayScene(resolve_shape(SPEC.shape), SPEC.height, SHORT)


def _track(profile: str = "constant") -> PushTrack:
    """One push on rect1's left edge, 15 mm off its centre line (it turns the object), with the
    testbed's noiseless force and pose from `simulate_track`."""
    sim = PushSimulator(SPEC, SHORT)
    try:
        pose0 = sim.reset((0.01, -0.01, 0.3))
        c, s = np.cos(0.3), np.sin(0.3)
        x, y = -0.045, 0.015  # object frame
        cp = (0.01 + c * x - s * y, -0.01 + s * x + c * y)
        push = Push(cp, 0.3, profile, 0.02 if profile == "constant" else 0.4)
        start = sim.pad_start(push)
    finally:
        sim.close()
    skeleton = PushTrack(push, start, pose0, np.zeros((21, 2)), np.zeros((21, 3)))
    out = simulate_track(SCENE, PHI, skeleton)
    return PushTrack(push, start, pose0, out[:, :2], out[:, 2:])


@pytest.fixture(scope="module")
def track() -> PushTrack:
    return _track()


def test_sysid_model_reproduces_the_testbed_replay(track):
    """At the true φ, sysid's model (servo-driven pad, fixed support superset with the
    testbed's loads, windowed contact force) reproduces the testbed's replay to a small
    fraction of the noise."""
    (r,) = sysid_residuals(SCENE, [track], PHI)
    assert r.shape == (20, 5)
    assert np.abs(track.force).max() > 1.0  # the pad pushed
    assert np.sqrt(np.mean(r**2, axis=0)).max() < 0.1, np.sqrt(np.mean(r**2, axis=0))
    # a wrong CoM (what a uniform load distribution would give) is far off in noise units
    (wrong,) = sysid_residuals(SCENE, [track], PHI * np.array([1, 1, 0, 0, 1]))
    assert np.sqrt(np.mean(wrong**2)) > 1.0


@pytest.mark.parametrize("com", [(0.01, -0.006), (0.0415, 0.0415), (-0.0415, 0.0415)])
def test_support_loads_are_the_testbeds(com):
    """The fixed superset carries exactly the loads `build_mjcf` gives that CoM, on the points
    it would build, and nothing on the others."""
    fp, sup = SPEC.footprint, SHORT.support
    layout = SupportLayout.of(fp, SHORT)
    pts = support_points(fp, sup.spacing, sup.edge_margin, com)
    want = support_loads(pts, com)
    w = layout.loads(com)
    np.testing.assert_allclose(layout.points[: len(pts)], pts)
    np.testing.assert_allclose(w[: len(pts)], np.where(want > 1e-9, want, 0.0), atol=1e-12)
    assert not w[len(pts) :].any()
    np.testing.assert_allclose(w @ layout.points, com, atol=1e-5)


def test_corner_com_uses_the_outline_vertices():
    """A CoM in a corner the grid and ring cut off needs the outline's vertices (the third case
    above); the testbed adds them, and so does the superset."""
    fp, sup = SPEC.footprint, SHORT.support
    layout = SupportLayout.of(fp, SHORT)
    corner = (-0.0415, 0.0415)
    assert len(support_points(fp, sup.spacing, sup.edge_margin, corner)) > layout.n_base
    assert len(layout.points) > layout.n_base
    assert layout.loads(corner)[layout.n_base :].any()


def test_fit_recovers_mu_m_and_com_from_a_perturbed_start(track):
    start = np.array([0.8, 0.45, 0.0, 0.0, 1.5e-3])  # μ·m 0.36 for 0.25, CoM 12 mm off
    fit = sysid_fit(SCENE, [track], start, max_iterations=15, threads=1)
    mu_m = PHI[0] * PHI[1]
    assert abs(fit.mu_m / mu_m - 1) < 0.03, fit.mu_m
    assert np.linalg.norm(fit.estimate[2:4] - PHI[2:4]) < 1e-3, fit.estimate
    assert fit.objective < 0.01 * fit.objective_start
    assert fit.evaluations > 5 and fit.rollouts == fit.evaluations  # one push
    assert fit.iterations >= 1 and fit.status.startswith("Terminated")
    assert fit.std_norm is not None and fit.std_norm.shape == (5,)
    report = json.loads(json.dumps(fit.to_json(), allow_nan=False))
    assert report["pushes"] == 1 and set(report["parameters"]) == {
        "mass", "friction", "com_x", "com_y", "inertia"
    }  # fmt: skip
    com = report["parameters"]["com_x"]
    if com["interval90"] is not None:
        assert com["interval90"][0] <= com["estimate"] <= com["interval90"][1]


@pytest.mark.parametrize(
    "tracks, phi, match",
    [
        ([], PHI, "no pushes"),
        ("force", PHI, r"force must be \(T, 2\)"),
        ("short", PHI, "T ≥ 2"),
        ("nan", PHI, "non-finite"),
        ("ok", [-0.5, 0.5, 0.0, 0.0, 1e-3], "m, μ, I_z > 0"),
        ("ok", [0.5, 0.5, 0.0], "5 finite values"),
    ],
)
def test_bad_input_is_a_one_line_error(track, tracks, phi, match):
    bad = {
        "force": [PushTrack(track.push, track.start, track.pose0, track.pose, track.pose)],
        "short": [PushTrack(track.push, track.start, track.pose0, track.force[:1], track.pose)],
        "nan": [PushTrack(track.push, track.start, track.pose0, track.force * np.nan, track.pose)],
        "ok": [track],
    }
    with pytest.raises(IdentificationError, match=match) as info:
        sysid_fit(SCENE, bad[tracks] if isinstance(tracks, str) else tracks, phi)
    assert "\n" not in str(info.value)


def test_a_scene_that_is_not_a_replay_scene_is_refused(track):
    with pytest.raises(IdentificationError, match="ReplayScene") as info:
        sysid_fit({"shape": "rect1"}, [track], PHI)
    assert "\n" not in str(info.value)
