"""Inference on an object (docs/DESIGN.md §9): an `Estimator` (the learned dual filter or the
physics filter) carries the parameter belief push to push; a policy chooses the pushes."""

from pushtoknow.common.estimators import ESTIMATOR_NAMES
from pushtoknow.common.policy_names import POLICY_NAMES
from pushtoknow.inference.estimator import (
    Estimator,
    InferenceConfig,
    InferenceResult,
    PushEstimate,
)
from pushtoknow.inference.learned_filter import LearnedFilterEstimator
from pushtoknow.inference.policies import PushPolicy, make_policy
from pushtoknow.inference.session import infer_object, infer_simulated, make_estimator

__all__ = [
    "ESTIMATOR_NAMES",
    "POLICY_NAMES",
    "Estimator",
    "InferenceConfig",
    "InferenceResult",
    "LearnedFilterEstimator",
    "PushEstimate",
    "PushPolicy",
    "infer_object",
    "infer_simulated",
    "make_estimator",
    "make_policy",
]
