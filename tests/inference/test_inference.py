"""Inference on a novel object with the tiny trained model on the simulated testbed."""

import json

import numpy as np
import pytest
import torch
from shapely.geometry import Point

from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.inference import InferenceConfig, LearnedFilterEstimator, infer_object
from pushtoknow.inference.policies import make_policy
from pushtoknow.models.checkpoint import load_checkpoint
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import catalogue_split
from tiny_training import SIGMA_POINTS, SIM, tiny_run

OBJECT_ID = 117  # a held-out (test-split) catalogue object
PUSHES = 2
SAMPLES = 21  # 2 s pushes at 10 Hz, both ends


@pytest.fixture(scope="module")
def model(tmp_path_factory):
    return load_checkpoint(tiny_run(tmp_path_factory))


@pytest.fixture(scope="module")
def spec():
    assert OBJECT_ID in catalogue_split()[1]
    return load_object_spec(f"catalogue:{OBJECT_ID}")


class ViewRecorder(SimulatedExecutor):
    """The simulated executor, keeping every view it showed."""

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.views = []

    def observe(self):
        view = super().observe()
        self.views.append(view)
        return view


def infer(model, spec, policy="uniform", seed=0, pushes=PUSHES, profiles=("constant",)):
    ex = ViewRecorder(spec, SIM, seed=seed, recentre=True)
    try:
        ex.observe()  # as the CLI does: places the object, sets initial_pose
        cfg = InferenceConfig(
            estimator="vt-addf", pushes=pushes, policy=policy, candidates=4, profiles=profiles
        )
        seen = []
        result = infer_object(
            model,
            ex,
            cfg,
            seed,
            initial_pose=ex.initial_pose,
            truth=spec.params.as_array(),
            object_name=spec.name,
            on_push=seen.append,
            policy=make_policy(policy),
        )
    finally:
        ex.close()
    assert seen == result.estimates
    return result, ex


@pytest.fixture(scope="module")
def uniform_run(model, spec):
    return infer(model, spec, "uniform", seed=0)


def check_estimate(e, index, spec=None):
    assert e.index == index
    assert e.mean.shape == e.std.shape == e.mean_norm.shape == (5,)
    assert e.cov_norm.shape == (5, 5)
    for a in (e.mean, e.std, e.mean_norm, e.cov_norm):
        assert np.isfinite(a).all()
    assert (e.std > 0).all()
    np.testing.assert_allclose(e.cov_norm, e.cov_norm.T, atol=1e-6)
    # physically possible, whatever the (tiny, barely trained) model believes
    positive = [PARAM_NAMES.index(k) for k in ("mass", "friction", "inertia")]
    lo, hi = e.interval(0.9)
    assert (e.mean[positive] > 0).all() and (lo[positive] > 0).all() and (lo <= hi).all()
    assert ((lo <= e.mean) & (e.mean <= hi)).all()  # every estimate inside its own interval
    if spec is not None:  # the CoM lies in the hull of the footprint (seen at 2.4 mm per pixel)
        com = e.mean[[PARAM_NAMES.index("com_x"), PARAM_NAMES.index("com_y")]]
        assert spec.footprint.polygon.convex_hull.buffer(0.003).contains(Point(*com))


def test_infer_object_two_pushes(model, spec, uniform_run):
    result, _ = uniform_run
    check_estimate(result.prior, 0, spec)
    np.testing.assert_allclose(result.prior.mean_norm, model.prior.mean.numpy(), rtol=1e-6)
    # the prior is reported with the first view's footprint, which bounds it (`see_object`)
    assert result.prior.belief.outline is not None and result.prior.belief.com is not None
    assert len(result.estimates) == len(result.records) == len(result.poses) == PUSHES
    for k, (e, rec, poses) in enumerate(
        zip(result.estimates, result.records, result.poses, strict=True)
    ):
        check_estimate(e, k + 1, spec)
        assert e.push == rec.push and e.push.speed == model.info["push_speed"]
        assert len(rec.time) == SAMPLES and poses.shape == (SAMPLES, 3)
        assert np.isfinite(poses).all()
    np.testing.assert_array_equal(result.truth, spec.params.as_array())
    assert result.object_name == spec.name
    # The first push starts from the given initial pose (the true one in simulation).
    np.testing.assert_allclose(result.poses[0][0], result.records[0].pose[0], atol=1e-6)


def test_json_has_the_documented_keys(spec, uniform_run):
    result, _ = uniform_run
    report = json.loads(json.dumps(result.to_json()))  # plain JSON
    assert set(report) >= {"pushes", "truth", "prior", "object"}
    assert len(report["pushes"]) == PUSHES
    for p in [*report["pushes"], report["prior"]]:
        assert list(p["estimate"]) == list(PARAM_NAMES)
        assert list(PARAM_NAMES) == ["mass", "friction", "com_x", "com_y", "inertia"]
        for v in p["estimate"].values():
            assert set(v) == {"mean", "std", "interval90"} and v["std"] > 0
            assert v["interval90"][0] <= v["interval90"][1]
    assert set(report["pushes"][0]["push"]) == {"contact", "direction", "profile", "speed"}
    truth = spec.params
    assert report["truth"] == {
        "mass": truth.mass,
        "friction": truth.friction,
        "com_x": truth.com_x,
        "com_y": truth.com_y,
        "inertia": truth.inertia,
    }


def test_same_seed_gives_identical_json(model, spec, uniform_run):
    again, _ = infer(model, spec, "uniform", seed=0)
    assert json.dumps(again.to_json()) == json.dumps(uniform_run[0].to_json())
    other, _ = infer(model, spec, "uniform", seed=1, pushes=1)
    assert other.to_json()["pushes"][0] != uniform_run[0].to_json()["pushes"][0]


@pytest.mark.parametrize("policy", ["random", "active-entropy"])
def test_policies_run(model, spec, policy):
    result, _ = infer(model, spec, policy, seed=2)
    assert len(result.estimates) == PUSHES
    for k, e in enumerate(result.estimates):
        check_estimate(e, k + 1)


def test_the_configured_policy_is_made_with_the_models_testbed_settings(model, spec):
    """Without a policy object, infer_object makes the configured one (an active one too,
    with the model's testbed settings) and it chooses among the candidates."""
    ex = SimulatedExecutor(spec, SIM, seed=0, recentre=True)
    try:
        ex.observe()
        cfg = InferenceConfig(estimator="vt-addf", pushes=1, policy="active-entropy", candidates=3)
        res = infer_object(model, ex, cfg, 0, initial_pose=ex.initial_pose)
    finally:
        ex.close()
    assert len(res.estimates) == 1 and res.estimates[0].push is not None


def test_recentring_keeps_theta_and_reports_the_move(uniform_run):
    result, ex = uniform_run
    first, second = result.records
    # one view before inference (the CLI's), then one per push
    assert len(ex.views) == 1 + PUSHES
    assert ex.views[0].moved_by is None and ex.views[1].moved_by is None
    moved = np.asarray(ex.views[2].moved_by)
    np.testing.assert_allclose(moved, ex.initial_pose[:2] - first.pose[-1][:2], atol=1e-9)
    assert np.linalg.norm(moved) > 1e-3  # the first push moved the object
    # The second push starts where the first did, turned as the first push left it.
    np.testing.assert_allclose(second.pose[0][:2], ex.initial_pose[:2], atol=1e-3)
    dtheta = np.angle(np.exp(1j * (second.pose[0][2] - first.pose[-1][2])))
    assert abs(dtheta) < 1e-2


def test_estimator_start_belief(model):
    est = LearnedFilterEstimator(model, InferenceConfig(num_sigma_points=SIGMA_POINTS), seed=0)
    mean, cov = est.start_belief(np.array([0.01, -0.02, 0.3]))
    assert mean.shape == (1, 8) and cov.shape == (1, 8, 8)
    torch.testing.assert_close(mean[0, :3], torch.tensor([0.01, -0.02, 0.3]))
    torch.testing.assert_close(cov[0, 3:, 3:], model.prior.cov)
    assert torch.all(cov[0, :3, 3:] == 0)
    assert est.num_sigma_points == SIGMA_POINTS


def test_uniform_policy_cycles_through_the_speed_profiles(model, spec):
    """With profiles (constant, release) uniform alternates them, each at its testbed speed;
    the release push is executed with the release profile (the pad stops early)."""
    result, _ = infer(model, spec, "uniform", seed=0, profiles=("constant", "release"))
    pushes = [e.push for e in result.estimates]
    assert [p.profile for p in pushes] == ["constant", "release"]
    assert pushes[0].speed == SIM.push.speed and pushes[1].speed == SIM.push.release_peak_speed
    constant, release = result.records
    travel = lambda r: np.linalg.norm(r.pusher[-1] - r.pusher[0])  # noqa: E731
    pad_speed = lambda r: np.linalg.norm(np.diff(r.pusher, axis=0), axis=1).max() * 10  # noqa: E731
    assert pad_speed(constant) == pytest.approx(SIM.push.speed, rel=0.05)
    assert pad_speed(release) > 5 * SIM.push.speed and travel(release) > travel(constant)
    for k, e in enumerate(result.estimates):
        check_estimate(e, k + 1)


def test_policies_choose_among_candidates_of_both_profiles():
    from pushtoknow.inference.estimator import profile_speeds
    from pushtoknow.inference.policies import (
        PushDecision,
        PushPolicy,
        RandomPolicy,
        UniformPolicy,
        candidate_pushes,
    )
    from pushtoknow.testbed.executor import SimulatedExecutor

    class PicksRelease(PushPolicy):  # an active policy's part: the index it scores highest
        name = "picks-release"

        def choose(self, d):
            return d.candidates[[c.profile for c in d.candidates].index("release")]

    ex = SimulatedExecutor(load_object_spec("catalogue:117"), SIM, seed=0, recentre=True)
    try:
        view = ex.observe()
        speeds = profile_speeds(SIM)
        both = ("constant", "release")

        def decision(seed, profiles=both, k=0):
            rng = np.random.default_rng(seed)
            cands, cp = candidate_pushes(view, ex.camera, 6, rng, speeds, profiles)
            return PushDecision(k, 5, cands, cp, view, ex.camera, ex.initial_pose, rng,
                                profiles, speeds, None)  # fmt: skip

        d = decision(0)
        assert [c.profile for c in d.candidates] == ["constant", "release"] * 3
        push = PicksRelease().choose(d)
        assert push.profile == "release" and push.speed == speeds["release"]
        assert {RandomPolicy().choose(decision(s)).profile for s in range(12)} == set(both)
        only = RandomPolicy().choose(decision(0, ("constant",)))
        assert only.profile == "constant" and only.speed == speeds["constant"]
        # uniform cycles through the profiles push by push
        assert [UniformPolicy().choose(decision(0, k=k)).profile for k in range(4)] == [
            "constant", "release", "constant", "release",
        ]  # fmt: skip
    finally:
        ex.close()


def test_policies_are_made_by_name():
    from typing import get_args

    from pushtoknow.common.policy_names import POLICY_NAMES
    from pushtoknow.inference.policies import InformationPolicy, make_policy

    assert POLICY_NAMES == get_args(InferenceConfig.model_fields["policy"].annotation)
    for name in POLICY_NAMES:
        assert make_policy(name).name == name
    assert make_policy("active-entropy").score == "entropy"
    assert isinstance(make_policy("active-kl"), InformationPolicy)
    with pytest.raises(ValueError, match="uniform, random, active-kl, active-entropy"):
        make_policy("greedy")


def test_profiles_the_model_never_saw_are_refused(model, spec):
    import dataclasses

    constant_only = dataclasses.replace(model, info={**model.info, "profiles": ["constant"]})
    ex = SimulatedExecutor(spec, SIM, seed=0, recentre=True)
    try:
        cfg = InferenceConfig(estimator="vt-addf", pushes=1, profiles=("constant", "release"))
        with pytest.raises(ValueError, match="profiles release: the model was trained on"):
            infer_object(constant_only, ex, cfg, 0, initial_pose=ex.initial_pose)
    finally:
        ex.close()
    assert sorted(model.info["profiles"]) == ["constant", "release"]  # recorded by training


def test_each_push_keeps_the_evidence_of_its_count_among_its_profiles(model, spec, monkeypatch):
    """The estimator counts pushes per speed profile: constant, release, constant are the
    first constant, the first release and the second constant push."""
    from pushtoknow.models.checkpoint import InferenceSettings

    calls = []
    kept = InferenceSettings.kept_evidence

    def spy(self, profile, nth):
        calls.append((profile, nth))
        return kept(self, profile, nth)

    monkeypatch.setattr(InferenceSettings, "kept_evidence", spy)
    infer(model, spec, "uniform", seed=0, pushes=3, profiles=("constant", "release"))
    assert calls == [("constant", 1), ("release", 1), ("constant", 2)]


@pytest.mark.parametrize("ref", ["random:3:0", "catalogue:5"])
def test_a_testbed_object_is_estimated_under_the_prior_it_is_drawn_from(model, ref, monkeypatch):
    """infer_simulated's physics filter takes the random shapes' prior on a random shape (their
    I_z any m·k²), the catalogue's on a catalogue object (`prior.generator_prior`)."""
    from pushtoknow.identification.prior import CATALOGUE_PRIOR, RANDOM_SHAPE_PRIOR
    from pushtoknow.inference import session

    seen = []

    class Stop(Exception):
        pass

    def fake(model, config, seed, sim_config=None, prior=None):
        seen.append(prior)
        raise Stop

    monkeypatch.setattr(session, "make_estimator", fake)
    with pytest.raises(Stop):
        session.infer_simulated(model, ref, InferenceConfig(estimator="physics", pushes=1))
    assert seen == [RANDOM_SHAPE_PRIOR if ref.startswith("random") else CATALOGUE_PRIOR]
