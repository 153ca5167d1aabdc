"""Active push selection (paper §III-D, docs/DESIGN.md §7): N-step look-ahead scores of candidate
pushes with the filter's prediction step, and the policy that pushes the best one.

A layer above `pushtoknow.filters` and below training/inference: plain tensors and the filter
interfaces only (no simulator).
"""

from pushtoknow.active.information_policy import (
    ACTIVE_POLICY_NAMES,
    ActiveConfig,
    ActivePolicy,
    CandidateSelector,
    ContextBuilder,
    look_ahead_steps,
)
from pushtoknow.active.scores import entropy_reduction, kl_information_gain, log_det
from pushtoknow.active.selection import (
    SCORES,
    draw_common_noise,
    expected_update_covariance,
    score_candidates,
)

__all__ = [
    "ACTIVE_POLICY_NAMES",
    "SCORES",
    "ActiveConfig",
    "ActivePolicy",
    "CandidateSelector",
    "ContextBuilder",
    "draw_common_noise",
    "entropy_reduction",
    "expected_update_covariance",
    "kl_information_gain",
    "log_det",
    "look_ahead_steps",
    "score_candidates",
]
