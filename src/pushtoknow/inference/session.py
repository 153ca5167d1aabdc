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
from collections.abc import Sequence

import numpy as np

from pushtoknow.common.errors import UntrainedProfileError
from pushtoknow.common.random import stream, stream_seed
from pushtoknow.identification.prior import PriorRanges, generator_prior
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
from pushtoknow.testbed.executor import PushExecutor, SimulatedExecutor, View
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig


def make_estimator(
    model: TrainedModel,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    sim_config: SimConfig | None = None,
    prior: PriorRanges | None = None,
) -> Estimator:
    """The estimator `config.estimator` names, on `model` (the learned filter; the physics
    filter uses its perception), for pushes run with `sim_config` (default: the model's);
    `prior`: the physics filter's prior ranges (None: the catalogue's)."""
    sim = sim_config or model.sim_config
    if config.estimator == "physics":
        from pushtoknow.identification.recursive import PhysicsFilterConfig
        from pushtoknow.inference.physics_filter import PhysicsFilterEstimator

        physics = None if prior is None else PhysicsFilterConfig(prior=prior)
        return PhysicsFilterEstimator(model, config, seed, sim, filter_config=physics)
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
    prior: PriorRanges | None = None,
) -> InferenceResult:
    """K pushes on the executor's object; `on_push(estimate)` after each push.

    `policy` chooses each push (default: `make_policy(config.policy)`); `estimator` carries
    the belief (default: `make_estimator(model, config, seed, sim_config, prior)`, closed at
    the end);
    `sim_config`: the testbed settings the executor runs pushes with (default: the model's).
    Raises ArgumentTypeError / ArgumentValueError naming a wrong argument."""
    from pushtoknow.common.arguments import (
        check_callable,
        check_instance,
        check_seed,
        check_vector,
    )

    check_instance(model, TrainedModel, "model", hint="load one with pushtoknow.load_model()")
    check_instance(executor, PushExecutor, "executor")
    check_instance(config, InferenceConfig, "config", hint="build one: InferenceConfig(**settings)")
    check_seed(seed)
    check_vector(initial_pose, 3, "initial_pose")
    check_vector(truth, 5, "truth", finite=False)
    check_instance(object_name, str, "object_name")
    check_callable(on_push, "on_push")
    check_instance(
        policy, PushPolicy, "policy", optional=True,
        hint="to choose one by name, set InferenceConfig(policy=...)",
    )  # fmt: skip
    check_instance(sim_config, SimConfig, "sim_config", optional=True)
    check_instance(estimator, Estimator, "estimator", optional=True)
    check_instance(prior, PriorRanges, "prior", optional=True)
    check_profiles(model, config)
    if policy is None:
        policy = make_policy(config.policy, config.active_horizon_fraction)
    own = estimator is None
    seed_est = stream_seed(seed, "estimator")
    est = estimator or make_estimator(model, config, seed_est, sim_config, prior)
    rng = stream(seed, "policy")  # candidates and the policy's choices
    speeds = profile_speeds(sim_config or model.sim_config)
    camera = model.camera
    try:
        for k in range(config.pushes):
            view = executor.observe()
            pose0 = est.start_pose(view, initial_pose)
            if k == 0:  # the prior is reported with the object seen (`Estimator.see_object`)
                est.see_object(view, pose0)
                result = InferenceResult(est.estimate(0), [], truth, object_name=object_name)
                result.estimator = est.name
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
            _update(est, result, executor.execute(push), view, pose0, on_push)
        result.add_seen(est)
    finally:
        if own:
            est.close()
    return result


def _update(
    est: Estimator,
    result: InferenceResult,
    rec: PushRecord,
    view: View | None,
    pose0: np.ndarray,
    on_push,
) -> None:
    """The belief after the executed push `rec` (timed), its estimate appended to `result`."""
    t0 = time.perf_counter()
    result.poses.append(est.update(rec, view, pose0))
    result.seconds.append(time.perf_counter() - t0)
    result.replays.append(est.replays())
    result.records.append(rec)
    e = est.estimate(len(result.estimates) + 1, rec.push)
    result.estimates.append(e)
    if on_push is not None:
        on_push(e)


def infer_simulated(
    model: TrainedModel,
    spec: ObjectSpec | str,
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
    `infer_object`'s, by default under the ranges the testbed draws `spec` from
    (`identification.prior.generator_prior`). `spec` may be a reference ("catalogue:117",
    "random:7:0", a spec file).
    Raises ArgumentTypeError / ArgumentValueError naming a wrong argument."""
    from pathlib import Path

    from pushtoknow.common.arguments import check_instance, check_seed
    from pushtoknow.testbed.object_refs import load_object_spec

    check_instance(model, TrainedModel, "model", hint="load one with pushtoknow.load_model()")
    if isinstance(spec, (str, Path)):
        spec = load_object_spec(spec)
    check_instance(spec, ObjectSpec, "spec", hint="or a reference such as 'catalogue:117'")
    check_seed(seed)
    check_instance(with_truth, bool, "with_truth")
    sim_seed = stream_seed(seed, "simulator")
    executor = SimulatedExecutor(spec, model.sim_config, seed=sim_seed, recentre=True)
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
            prior=generator_prior(spec.name),
        )
    finally:
        executor.close()


def infer_recorded(
    model: TrainedModel,
    records: Sequence[PushRecord],
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    truth: np.ndarray | None = None,
    object_name: str = "",
    on_push=None,
    estimator: Estimator | None = None,
    sim_config: SimConfig | None = None,
) -> InferenceResult:
    """The estimator over recorded pushes, in their order (a recording cannot be re-pushed:
    nothing is chosen, `config.pushes` and the policy are unused). Each push starts at its
    recorded (tracked) pose; a record without images (tracked poses only) needs an estimator
    that does without them (`PhysicsFilterEstimator` given the recording's outline).
    `sim_config`: the settings the pushes were recorded with (default: the model's)."""
    own = estimator is None
    est = estimator or make_estimator(model, config, stream_seed(seed, "estimator"), sim_config)
    try:
        if records and records[0].rgb is not None:  # the prior with the object seen
            est.see_object(View.before(records[0]), np.asarray(records[0].pose[0], float))
        result = InferenceResult(est.estimate(0), [], truth, object_name=object_name)
        result.estimator = est.name
        for rec in records:
            view = View.before(rec) if rec.rgb is not None else None
            _update(est, result, rec, view, np.asarray(rec.pose[0], dtype=np.float64), on_push)
        result.add_seen(est)
    finally:
        if own:
            est.close()
    return result
