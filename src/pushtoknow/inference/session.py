"""Inference on an object (docs/DESIGN.md §9): K pushes, each chosen by a policy and executed,
the parameter belief carried from push to push by an `Estimator`.

Per push k: the executor shows the object at rest; the estimator gives the pose at the push's
start (perception); candidate pushes are sampled among the affordances of S_0 and the policy
picks one (active policies through the estimator's scoring hook); the executor runs it; the
estimator updates its belief; the estimate is reported.

Random streams: the candidates and the policy draw from the run's generator (seeded by `seed`);
each estimator seeds its own.
"""

from __future__ import annotations

import time

import numpy as np

from pushtoknow.common.errors import UntrainedProfileError
from pushtoknow.inference.estimator import (
    Estimator,
    InferenceConfig,
    InferenceResult,
    profile_speeds,
)
from pushtoknow.inference.learned_filter import LearnedFilterEstimator
from pushtoknow.inference.policies import (
    PushDecision,
    PushPolicy,
    candidate_pushes,
    make_policy,
)
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.executor import PushExecutor, SimulatedExecutor
from pushtoknow.testbed.objects import ObjectSpec


def make_estimator(
    model: TrainedModel,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    sim_config: SimConfig | None = None,
) -> Estimator:
    """The estimator `config.estimator` names, on `model` (the learned filter; the physics
    filter uses its perception), for pushes run with `sim_config` (default: the model's)."""
    sim = sim_config or model.sim_config
    if config.estimator == "physics":
        from pushtoknow.inference.physics_filter import PhysicsFilterEstimator

        return PhysicsFilterEstimator(model, config, seed, sim)
    return LearnedFilterEstimator(model, config, seed, sim)


def check_profiles(model: TrainedModel, config: InferenceConfig) -> None:
    """Refuse speed profiles the learned filter never saw in training: its estimates on them
    are extrapolation (a constant-push model's CoM error more than doubles on release pushes,
    with 90% coverage near 0.7). The physics filter simulates any profile."""
    if config.estimator != LearnedFilterEstimator.name:
        return
    trained = model.info.get("profiles")
    unseen = sorted(set(config.profiles) - set(trained or config.profiles))
    if unseen:
        raise UntrainedProfileError(
            f"profiles {', '.join(unseen)}: the model was trained on {', '.join(trained)} "
            "pushes only; train it on data with those profiles (pushtoknow simulate --profiles)"
        )


def infer_object(
    model: TrainedModel,
    executor: PushExecutor,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    initial_pose: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    object_name: str = "",
    on_push=None,
    policy: PushPolicy | None = None,
    sim_config: SimConfig | None = None,
    estimator: Estimator | None = None,
) -> InferenceResult:
    """K pushes on the executor's object; `on_push(estimate)` after each push.

    `policy` chooses each push (default: `make_policy(config.policy)`); `estimator` carries
    the belief (default: `make_estimator(model, config, seed, sim_config)`, closed at the end);
    `sim_config`: the testbed settings the executor runs pushes with (default: the model's)."""
    check_profiles(model, config)
    if policy is None:
        policy = make_policy(config.policy, config.active_horizon_fraction)
    own = estimator is None
    est = estimator or make_estimator(model, config, seed, sim_config)
    rng = np.random.default_rng(seed)  # candidates and policy
    speeds = profile_speeds(sim_config or model.sim_config)
    camera = model.camera
    result = InferenceResult(est.estimate(0), [], truth, object_name=object_name)
    result.estimator = est.name
    try:
        for k in range(config.pushes):
            view = executor.observe()
            pose0 = est.start_pose(view, initial_pose)
            cands, contacts = candidate_pushes(
                view, camera, config.candidates, rng, speeds, config.profiles
            )

            def information(score, horizon_fraction, cands=cands, view=view, pose0=pose0):
                return est.information(cands, view, pose0, score, horizon_fraction)

            decision = PushDecision(
                k,
                config.pushes,
                cands,
                contacts,
                view,
                camera,
                pose0,
                rng,
                config.profiles,
                speeds,
                information,
            )
            push = policy.choose(decision)
            rec = executor.execute(push)
            t0 = time.perf_counter()
            result.poses.append(est.update(rec, view, pose0))
            result.seconds.append(time.perf_counter() - t0)
            result.records.append(rec)
            e = est.estimate(k + 1, push)
            result.estimates.append(e)
            if on_push is not None:
                on_push(e)
    finally:
        if own:
            est.close()
    return result


def infer_simulated(
    model: TrainedModel,
    spec: ObjectSpec,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    with_truth: bool = True,
    on_push=None,
    policy: PushPolicy | None = None,
    estimator: Estimator | None = None,
) -> InferenceResult:
    """`infer_object` on the testbed: `spec` simulated with the model's testbed settings,
    recentred under the camera, seeded by `seed`, the first push starting from its true pose
    (so the CoM and I_z compare with the truth, reported when `with_truth`); `estimator` as
    `infer_object`'s."""
    executor = SimulatedExecutor(spec, model.sim_config, seed=seed, recentre=True)
    try:
        return infer_object(
            model,
            executor,
            config,
            seed,
            initial_pose=executor.initial_pose,
            truth=spec.params.as_array() if with_truth else None,
            object_name=(spec.name or "") if with_truth else "",
            on_push=on_push,
            policy=policy,
            estimator=estimator,
        )
    finally:
        executor.close()
