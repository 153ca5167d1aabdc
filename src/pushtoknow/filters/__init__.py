"""Differentiable Gaussian filters over s = (ψ, φ̃): dual (VT-DDF), joint (VT-JDF), vision-only.

The math lives in pure functions (`gaussian`, `sigma_points`, `ukf`, `liu_west`,
`constraints`); the filters are thin `nn.Module`s taking the models as constructor arguments.
"""

from pushtoknow.filters.base import BeliefFilter, FilterConfig, FilterNoise, UpdateInfo
from pushtoknow.filters.constraints import (
    BoxConstraint,
    ComInFootprintConstraint,
    CompositeConstraint,
    ParamPositivityConstraint,
    StateConstraint,
    default_object_constraints,
)
from pushtoknow.filters.dual import DualFilter, vision_only_filter
from pushtoknow.filters.gaussian import (
    CholeskyConfig,
    CovarianceError,
    condition_gaussian,
    gaussian_log_prob,
    kl_gaussian,
    safe_cholesky,
    weighted_covariance,
    weighted_mean,
    wrap_residual,
)
from pushtoknow.filters.interfaces import (
    DynamicsModel,
    ObservationModel,
    ObservationNoiseModel,
    PoseObservation,
)
from pushtoknow.filters.joint import JointFilter
from pushtoknow.filters.sigma_points import MerweScaledSigmaPoints, monte_carlo_points
from pushtoknow.filters.ukf import UKFUpdateResult, ukf_update

__all__ = [
    "BeliefFilter",
    "BoxConstraint",
    "CholeskyConfig",
    "ComInFootprintConstraint",
    "CompositeConstraint",
    "CovarianceError",
    "DualFilter",
    "DynamicsModel",
    "FilterConfig",
    "FilterNoise",
    "JointFilter",
    "MerweScaledSigmaPoints",
    "ObservationModel",
    "ObservationNoiseModel",
    "ParamPositivityConstraint",
    "PoseObservation",
    "StateConstraint",
    "UKFUpdateResult",
    "UpdateInfo",
    "condition_gaussian",
    "default_object_constraints",
    "gaussian_log_prob",
    "kl_gaussian",
    "monte_carlo_points",
    "safe_cholesky",
    "ukf_update",
    "vision_only_filter",
    "weighted_covariance",
    "weighted_mean",
    "wrap_residual",
]
