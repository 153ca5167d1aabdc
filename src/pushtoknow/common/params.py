"""Object parameters φ = (m, μ, c_x, c_y, I_z) in SI, their catalogue ranges and normalisation.

Inside networks and filters parameters are normalised by the affine map of each catalogue range
to [-1, 1]; at every public boundary they are in SI (kg, -, m, m, kg·m²).
"""

from __future__ import annotations

from dataclasses import asdict, dataclass

import numpy as np

PARAM_NAMES: tuple[str, ...] = ("mass", "friction", "com_x", "com_y", "inertia")
PARAM_UNITS: dict[str, str] = {
    "mass": "kg",
    "friction": "-",
    "com_x": "m",
    "com_y": "m",
    "inertia": "kg·m²",
}

# Paper Table I grid (SI). I_z in kg·m² (the paper prints g·m²).
CATALOGUE_GRID: dict[str, tuple[float, ...]] = {
    "mass": (0.2, 0.5, 0.8, 1.2),
    "friction": (0.35, 0.5, 0.7),
    "com_x": (-0.02, -0.015, 0.0, 0.015, 0.02),
    "com_y": (-0.02, -0.01, 0.0, 0.02, 0.03),
    "inertia": (0.5e-3, 0.9e-3, 1.15e-3, 1.5e-3),
}
# Range of each parameter over the catalogue: the NRMSE denominator and the normalisation range.
PARAM_RANGES: dict[str, tuple[float, float]] = {
    k: (min(v), max(v)) for k, v in CATALOGUE_GRID.items()
}
GRAVITY = 9.81  # m/s²
# The fewest Monte-Carlo sigma points C a filter run over pushes works with: each prediction
# whitens its state (D = 8) and process-noise (P = 3) draws jointly, which needs C > D + P
# (`filters.base.BeliefFilter.prepare_noise`); with fewer, the sample covariance loses a little
# rank at each of a push's ~60 steps until it is no longer positive definite.
MIN_SIGMA_POINTS = 12


@dataclass(frozen=True)
class ObjectParams:
    """Physical parameters of an object, SI units."""

    mass: float  # kg
    friction: float  # object–table Coulomb coefficient
    com_x: float  # m, object frame (origin at the footprint centroid)
    com_y: float  # m
    inertia: float  # kg·m², about the vertical axis through the CoM

    def as_array(self) -> np.ndarray:
        """(5,) float64 in PARAM_NAMES order."""
        return np.array([getattr(self, k) for k in PARAM_NAMES], dtype=np.float64)

    @classmethod
    def from_array(cls, a: np.ndarray) -> ObjectParams:
        a = np.asarray(a, dtype=np.float64).reshape(-1)
        if a.shape != (5,):
            raise ValueError(f"expected 5 parameters {PARAM_NAMES}, got shape {a.shape}")
        return cls(*map(float, a))

    def to_dict(self) -> dict[str, float]:
        return asdict(self)


# How each parameter is filtered: m, μ and I_z in log space (positive by construction, and
# μ·m is linear there: log μ + log m), the CoM linearly (README, "The filters").
LOG_PARAMS: frozenset[str] = frozenset({"mass", "friction", "inertia"})
_IS_LOG = np.array([k in LOG_PARAMS for k in PARAM_NAMES])


def _bounds() -> tuple[np.ndarray, np.ndarray]:
    """(5,) catalogue bounds in the filtering space (log for LOG_PARAMS)."""
    lo = np.array([PARAM_RANGES[k][0] for k in PARAM_NAMES])
    hi = np.array([PARAM_RANGES[k][1] for k in PARAM_NAMES])
    return (
        np.where(_IS_LOG, np.log(np.where(_IS_LOG, lo, 1.0)), lo),
        np.where(_IS_LOG, np.log(np.where(_IS_LOG, hi, 1.0)), hi),
    )


def _affine(like) -> tuple:
    """(offset, scale, is_log) with filtering-space value = offset + scale · normalised."""
    lo, hi = _bounds()
    offset, scale, is_log = 0.5 * (lo + hi), 0.5 * (hi - lo), _IS_LOG
    if not isinstance(like, np.ndarray):  # torch tensor
        import torch

        offset, scale = like.new_tensor(offset), like.new_tensor(scale)
        is_log = torch.as_tensor(is_log, device=like.device)
    return offset, scale, is_log


def normalise_params(phi):
    """SI (..., 5) → normalised (..., 5): each catalogue range mapped to [-1, 1], m, μ and I_z
    through their logarithm. Works on numpy arrays and torch tensors alike."""
    offset, scale, is_log = _affine(phi)
    if isinstance(phi, np.ndarray):
        space = np.where(is_log, np.log(np.where(is_log, phi, 1.0)), phi)
    else:
        import torch

        space = torch.where(is_log, torch.log(torch.where(is_log, phi, torch.ones_like(phi))), phi)
    return (space - offset) / scale


def denormalise_params(z):
    """Normalised (..., 5) → SI (..., 5), the inverse of `normalise_params`: m, μ and I_z are
    positive for every finite z."""
    offset, scale, is_log = _affine(z)
    space = offset + scale * z
    if isinstance(z, np.ndarray):
        return np.where(is_log, np.exp(np.where(is_log, space, 0.0)), space)
    import torch

    safe = torch.where(is_log, space, torch.zeros_like(space))
    return torch.where(is_log, torch.exp(safe), space)


def space_scale() -> np.ndarray:
    """(5,) d(filtering-space value)/d(normalised): the half-width of each catalogue range in
    the space the parameter is filtered in (log for m, μ, I_z)."""
    return _affine(np.zeros(len(PARAM_NAMES)))[1]


def linear_param_affine(name: str) -> tuple[float, float]:
    """(offset, scale) with SI = offset + scale · normalised, for a parameter filtered
    linearly (the CoM coordinates)."""
    if name in LOG_PARAMS:
        raise ValueError(f"{name} is filtered in log space, not linearly")
    offset, scale, _ = _affine(np.zeros(len(PARAM_NAMES)))
    i = PARAM_NAMES.index(name)
    return float(offset[i]), float(scale[i])


def normalise_param(name: str, value: float) -> float:
    """One parameter value in SI → its normalised coordinate."""
    phi = np.array([PARAM_RANGES[k][0] for k in PARAM_NAMES], dtype=np.float64)
    phi[PARAM_NAMES.index(name)] = value
    return float(normalise_params(phi)[PARAM_NAMES.index(name)])


def si_moments(mean_norm: np.ndarray, cov_norm: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """SI mean and std (5,) of a Gaussian belief N(mean_norm (5,), cov_norm (5, 5)) over the
    normalised parameters: log-normal moments for m, μ and I_z, affine ones for the CoM."""
    offset, scale, is_log = _affine(np.asarray(mean_norm, dtype=np.float64))
    m = offset + scale * np.asarray(mean_norm, dtype=np.float64)
    v = scale**2 * np.clip(np.diagonal(np.asarray(cov_norm, dtype=np.float64)), 0.0, None)
    log_mean = np.exp(np.where(is_log, m + 0.5 * v, 0.0))
    mean = np.where(is_log, log_mean, m)
    std = np.where(is_log, log_mean * np.sqrt(np.expm1(np.where(is_log, v, 0.0))), np.sqrt(v))
    return mean, std


def product_moments(mean_norm: np.ndarray, cov_norm: np.ndarray) -> tuple[float, float]:
    """Mean and std of μ·m (kg) under a Gaussian belief over the normalised parameters:
    log μ + log m is Gaussian, so μ·m is log-normal."""
    offset, scale, _ = _affine(np.asarray(mean_norm, dtype=np.float64))
    i, j = PARAM_NAMES.index("mass"), PARAM_NAMES.index("friction")
    w = np.zeros(len(PARAM_NAMES))
    w[[i, j]] = scale[[i, j]]
    mu = float(offset[i] + offset[j] + w @ np.asarray(mean_norm, dtype=np.float64))
    var = max(float(w @ np.asarray(cov_norm, dtype=np.float64) @ w), 0.0)
    mean = float(np.exp(mu + 0.5 * var))
    return mean, mean * float(np.sqrt(np.expm1(var)))
