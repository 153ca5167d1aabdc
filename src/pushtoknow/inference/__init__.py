"""Inference on a novel object with a trained model (docs/DESIGN.md §9)."""

from pushtoknow.inference.session import (
    POLICIES,
    InferenceConfig,
    InferenceResult,
    ObjectEstimator,
    PushEstimate,
    infer_object,
)

__all__ = [
    "POLICIES",
    "InferenceConfig",
    "InferenceResult",
    "ObjectEstimator",
    "PushEstimate",
    "infer_object",
]
