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
POSE_NAMES: tuple[str, ...] = ("x", "y", "theta")

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


def _bounds() -> tuple[np.ndarray, np.ndarray]:
    lo = np.array([PARAM_RANGES[k][0] for k in PARAM_NAMES])
    hi = np.array([PARAM_RANGES[k][1] for k in PARAM_NAMES])
    return lo, hi


def normalise_params(phi):
    """SI (..., 5) → normalised (..., 5), each catalogue range mapped to [-1, 1].

    Works on numpy arrays and torch tensors alike.
    """
    lo, hi = _bounds()
    if not isinstance(phi, np.ndarray):  # torch tensor
        lo = phi.new_tensor(lo)
        hi = phi.new_tensor(hi)
    return 2.0 * (phi - lo) / (hi - lo) - 1.0


def denormalise_params(z):
    """Normalised (..., 5) → SI (..., 5). Inverse of `normalise_params`."""
    lo, hi = _bounds()
    if not isinstance(z, np.ndarray):
        lo = z.new_tensor(lo)
        hi = z.new_tensor(hi)
    return lo + (z + 1.0) * 0.5 * (hi - lo)


def param_scale() -> np.ndarray:
    """(5,) half-range of each parameter: d(SI)/d(normalised). Converts normalised std to SI."""
    lo, hi = _bounds()
    return 0.5 * (hi - lo)
