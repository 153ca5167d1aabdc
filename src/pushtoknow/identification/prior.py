"""The prior over φ and the coordinates the fit searches in.

Prior: every parameter uniform over its catalogue range (`common.params.PARAM_RANGES`, the
range the continuous sampler draws novel objects from), summarised by its Gaussian moments in
the normalised space of `common.params.normalise_params` (log space for m, μ and I_z), the space
the filters work in. It enters the fit as a Gaussian term, so directions the pushes do not
reveal keep its width.

Fit coordinates u (5,), a linear map of the normalised z: u_0 ∝ log(μ·m) (what force reveals
under quasi-static pushing), u_1 = z_m (m at fixed μ·m, what only dynamic content reveals),
then z_cx, z_cy, z_Iz. The μ·m ridge of the misfit is axis-aligned there, so finite
differences, damping and step tolerances act on the identified and the weakly identified
direction separately.
"""

from __future__ import annotations

from typing import Annotated

import numpy as np
from pydantic import AfterValidator, Field
from scipy.stats import truncnorm

from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import (
    LOG_PARAMS,
    PARAM_NAMES,
    PARAM_RANGES,
    denormalise_params,
    normalise_param,
    space_scale,
)
from pushtoknow.testbed.objects import FRICTION_LIMIT, MAX_MASS
from pushtoknow.testbed.random_shapes import is_random_shape


def _log_uniform_moments(a: float, b: float) -> tuple[float, float]:
    """Mean and variance of log x for x ~ U(a, b), 0 < a < b."""

    def f1(x):
        return x * np.log(x) - x

    def f2(x):
        return x * (np.log(x) ** 2 - 2 * np.log(x) + 2)

    m1 = (f1(b) - f1(a)) / (b - a)
    m2 = (f2(b) - f2(a)) / (b - a)
    return float(m1), float(m2 - m1 * m1)


def _range(name: str, lo_min: float, hi_max: float):
    """A validator of a (low, high) prior range of `name` within [lo_min, hi_max]."""

    def check(v: tuple[float, float]) -> tuple[float, float]:
        lo, hi = v
        if not (lo_min <= lo < hi <= hi_max):
            raise ValueError(
                f"prior {name} range {lo:g}–{hi:g} must satisfy {lo_min:g} ≤ low < high ≤ "
                f"{hi_max:g}"
            )
        return float(lo), float(hi)

    return check


class PriorRanges(Config):
    """Where the prior puts m, μ and I_z: each uniform over its (low, high) range (kg, –,
    kg·m²); the CoM is uniform over the footprint (`footprint_prior`) or, with no footprint,
    over the catalogue's range. The default: the testbed catalogue's ranges
    (`common.params.PARAM_RANGES`), which catalogue and novel objects are drawn from;
    `RANDOM_SHAPE_PRIOR` the random-shape objects'; `EVERYDAY_PRIOR` covers everyday objects
    and surfaces (real recordings)."""

    mass: Annotated[tuple[float, float], AfterValidator(_range("mass", 1e-3, MAX_MASS))] = (
        PARAM_RANGES["mass"]
    )
    friction: Annotated[
        tuple[float, float], AfterValidator(_range("friction", 1e-3, FRICTION_LIMIT))
    ] = PARAM_RANGES["friction"]
    inertia: Annotated[tuple[float, float], AfterValidator(_range("inertia", 1e-8, 10.0))] = (
        PARAM_RANGES["inertia"]
    )
    inertia_follows_footprint: bool = Field(
        False,
        description="once the footprint is seen, I_z is its plate's (m·k², `footprint_prior`) "
        "and the I_z range only describes it before (objects whose I_z follows their shape, "
        "as the random shapes'); False: the range bounds I_z after that too (catalogue and "
        "novel objects draw I_z from it whatever their size)",
    )

    def range_of(self, name: str) -> tuple[float, float]:
        """The (low, high) range of parameter `name` (`common.params.PARAM_NAMES`)."""
        return (
            getattr(self, name) if name in ("mass", "friction", "inertia") else PARAM_RANGES[name]
        )

    def label(self) -> str:
        """One line: 'm 0.05–5 kg, μ 0.05–1.2, I_z 1e-05–0.05 kg·m²'."""
        (m0, m1), (f0, f1), (i0, i1) = self.mass, self.friction, self.inertia
        shape = " (then the footprint's plate)" if self.inertia_follows_footprint else ""
        return f"m {m0:g}–{m1:g} kg, μ {f0:g}–{f1:g}, I_z {i0:g}–{i1:g} kg·m²{shape}"


CATALOGUE_PRIOR = PriorRanges()
# everyday objects and surfaces: 50 g–5 kg; μ from PTFE-like (0.05) to rubber (1.2); I_z from a
# 50 g, 3 cm puck to a 5 kg, 30 cm plate before the outline is seen, then the outline's plate
EVERYDAY_PRIOR = PriorRanges(
    mass=(0.05, 5.0), friction=(0.05, 1.2), inertia=(5e-6, 0.08), inertia_follows_footprint=True
)
# the random-shape objects' (`testbed.random_shapes`): the catalogue's ranges, but I_z m·k² for a
# radius of gyration near the footprint's plate once that is seen, inside the catalogue's I_z
# range or not
RANDOM_SHAPE_PRIOR = PriorRanges(inertia_follows_footprint=True)


def generator_prior(name: str | None) -> PriorRanges:
    """The ranges the testbed draws the object called `name` (`ObjectSpec.name`) from: the
    random shapes' (`RANDOM_SHAPE_PRIOR`) or the catalogue's (catalogue and novel objects, spec
    files)."""
    return RANDOM_SHAPE_PRIOR if is_random_shape(name) else CATALOGUE_PRIOR


def prior_moments(ranges: PriorRanges = CATALOGUE_PRIOR) -> tuple[np.ndarray, np.ndarray]:
    """Mean (5,) and covariance (5, 5) over the normalised parameters of φ uniform over
    `ranges` (independent parameters)."""
    scale = space_scale()
    mean = np.zeros(len(PARAM_NAMES))
    var = np.zeros(len(PARAM_NAMES))
    for i, k in enumerate(PARAM_NAMES):
        a, b = ranges.range_of(k)
        if k in LOG_PARAMS:
            m, v = _log_uniform_moments(a, b)
            mean[i] = normalise_param(k, float(np.exp(m)))
        else:
            m, v = 0.5 * (a + b), (b - a) ** 2 / 12.0
            mean[i] = normalise_param(k, m)
        var[i] = v / scale[i] ** 2
    return mean, np.diag(var)


def fit_transform() -> np.ndarray:
    """T (5, 5) with u = T z: u_0 = (s_m z_m + s_μ z_μ) / (s_m + s_μ) (log μ·m up to an offset,
    in units of its half-range), u_1 = z_m, u_2..4 = z_cx, z_cy, z_Iz."""
    s = space_scale()
    i_m, i_mu = PARAM_NAMES.index("mass"), PARAM_NAMES.index("friction")
    t = np.eye(len(PARAM_NAMES))
    t[i_m] = 0.0
    t[i_mu] = 0.0
    t[0, i_m] = s[i_m] / (s[i_m] + s[i_mu])
    t[0, i_mu] = s[i_mu] / (s[i_m] + s[i_mu])
    t[1, i_m] = 1.0
    return t


FIT_NAMES: tuple[str, ...] = ("log(mu*m)", "log m at fixed mu*m", "com_x", "com_y", "log I_z")


GYRATION_SPREAD = 0.3  # std of log(k / k_uniform): 90% of objects within ×0.6–1.6 of a plate


def polygon_moments(vertices: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Centroid (2,) and covariance (2, 2) of the uniform distribution over a simple polygon
    (V, 2) (m, m²), by the shoelace formulas."""
    p = np.asarray(vertices, dtype=np.float64)
    q = np.roll(p, -1, axis=0)
    cross = p[:, 0] * q[:, 1] - q[:, 0] * p[:, 1]
    area = 0.5 * cross.sum()
    c = ((p + q) * cross[:, None]).sum(axis=0) / (6.0 * area)
    sxx = (cross * (p[:, 0] ** 2 + p[:, 0] * q[:, 0] + q[:, 0] ** 2)).sum() / (12.0 * area)
    syy = (cross * (p[:, 1] ** 2 + p[:, 1] * q[:, 1] + q[:, 1] ** 2)).sum() / (12.0 * area)
    sxy = (
        cross
        * (p[:, 0] * q[:, 1] + 2 * p[:, 0] * p[:, 1] + 2 * q[:, 0] * q[:, 1] + q[:, 0] * p[:, 1])
    ).sum() / (24.0 * area)
    cov = np.array([[sxx - c[0] ** 2, sxy - c[0] * c[1]], [sxy - c[0] * c[1], syy - c[1] ** 2]])
    return c, cov


INERTIA_NODES = 64  # Gauss–Legendre nodes over the mass range in `inertia_moments`


def inertia_moments(
    mass_range: tuple[float, float],
    inertia_range: tuple[float, float],
    gyration_radius: float,
) -> tuple[float, float, float]:
    """E[log I_z], var(log I_z) and cov(log m, log I_z) for m uniform over `mass_range` (kg)
    and log I_z given m normal about log m + 2 log k (k = `gyration_radius`, m; std
    2·`GYRATION_SPREAD`) restricted to `inertia_range` (kg·m²): a plate-like object's inertia,
    within the range the prior allows. Where the range is wide, E[log I_z] = E[log m] + 2 log k
    and the slope on log m is 1; where it is narrow (the catalogue's), I_z keeps inside it
    whatever m is, and log m moves log I_z less."""
    nodes, weights = np.polynomial.legendre.leggauss(INERTIA_NODES)
    lo, hi = mass_range
    log_m = np.log(0.5 * (hi - lo) * nodes + 0.5 * (hi + lo))  # m uniform: nodes in m
    w = weights / weights.sum()
    centre = log_m + 2.0 * np.log(gyration_radius)
    sd = 2.0 * GYRATION_SPREAD
    with np.errstate(divide="ignore"):  # a range from 0: no lower bound
        a, b = (np.log(inertia_range[0]) - centre) / sd, (np.log(inertia_range[1]) - centre) / sd
    mean_c, var_c = truncnorm.stats(a, b, loc=centre, scale=sd, moments="mv")
    mean_iz = float(w @ mean_c)
    var_iz = float(w @ (var_c + mean_c**2)) - mean_iz**2
    cov_m_iz = float(w @ (log_m * mean_c)) - float(w @ log_m) * mean_iz
    return mean_iz, var_iz, cov_m_iz


def footprint_prior(
    com_region: np.ndarray, gyration_radius: float, ranges: PriorRanges = CATALOGUE_PRIOR
) -> tuple[np.ndarray, np.ndarray]:
    """Mean (5,) and covariance (5, 5) over the normalised parameters of an object whose
    footprint is seen: m and μ as `prior_moments(ranges)`; the CoM uniform over `com_region` (V, 2),
    the footprint's convex hull less the testbed's margin (where any mass distribution puts
    it); log I_z given m about log m + 2 log k, k the footprint's uniform-plate radius of
    gyration `gyration_radius` (m), within the prior's I_z range (`inertia_moments`) unless
    `ranges.inertia_follows_footprint`.
    Normalised values of a CoM or I_z beyond the catalogue ranges lie beyond ±1."""
    mean, cov = prior_moments(ranges)
    scale = space_scale()
    i_m, i_cx, i_iz = (
        PARAM_NAMES.index("mass"),
        PARAM_NAMES.index("com_x"),
        PARAM_NAMES.index("inertia"),
    )
    c, c_cov = polygon_moments(com_region)
    s_c = scale[i_cx : i_cx + 2]
    mean[i_cx : i_cx + 2] = [normalise_param("com_x", c[0]), normalise_param("com_y", c[1])]
    cov[i_cx : i_cx + 2, i_cx : i_cx + 2] = c_cov / np.outer(s_c, s_c)
    if ranges.inertia_follows_footprint:  # the plate relation unbounded, in closed form
        var_log_m = cov[i_m, i_m] * scale[i_m] ** 2
        mean_iz = float(np.log(denormalise_params(mean)[i_m])) + 2.0 * np.log(gyration_radius)
        var_iz, cov_m_iz = var_log_m + (2.0 * GYRATION_SPREAD) ** 2, var_log_m
    else:
        mean_iz, var_iz, cov_m_iz = inertia_moments(ranges.mass, ranges.inertia, gyration_radius)
    mean[i_iz] = normalise_param("inertia", float(np.exp(mean_iz)))
    cov[i_iz, i_iz] = var_iz / scale[i_iz] ** 2
    cov[i_iz, i_m] = cov[i_m, i_iz] = cov_m_iz / (scale[i_iz] * scale[i_m])
    return mean, cov
