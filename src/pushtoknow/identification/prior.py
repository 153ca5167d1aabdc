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

import numpy as np

from pushtoknow.common.params import (
    LOG_PARAMS,
    PARAM_NAMES,
    PARAM_RANGES,
    normalise_param,
    space_scale,
)


def _log_uniform_moments(a: float, b: float) -> tuple[float, float]:
    """Mean and variance of log x for x ~ U(a, b), 0 < a < b."""

    def f1(x):
        return x * np.log(x) - x

    def f2(x):
        return x * (np.log(x) ** 2 - 2 * np.log(x) + 2)

    m1 = (f1(b) - f1(a)) / (b - a)
    m2 = (f2(b) - f2(a)) / (b - a)
    return float(m1), float(m2 - m1 * m1)


def prior_moments() -> tuple[np.ndarray, np.ndarray]:
    """Mean (5,) and covariance (5, 5) over the normalised parameters of φ uniform over the
    catalogue ranges (independent parameters)."""
    scale = space_scale()
    mean = np.zeros(len(PARAM_NAMES))
    var = np.zeros(len(PARAM_NAMES))
    for i, k in enumerate(PARAM_NAMES):
        a, b = PARAM_RANGES[k]
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
