"""Inference on a novel object with a trained model (docs/DESIGN.md §9)."""

from pushtoknow.common.policies import POLICY_NAMES
from pushtoknow.inference.policies import PushPolicy, make_policy
from pushtoknow.inference.session import (
    InferenceConfig,
    InferenceResult,
    ObjectEstimator,
    PushEstimate,
    infer_object,
    infer_simulated,
)

__all__ = [
    "POLICY_NAMES",
    "InferenceConfig",
    "InferenceResult",
    "ObjectEstimator",
    "PushEstimate",
    "PushPolicy",
    "infer_object",
    "infer_simulated",
    "make_policy",
]
