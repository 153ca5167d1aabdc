"""NRMSE, interval coverage, counts of impossible estimates and of estimates outside their own
interval, the prior-mean predictor and `MethodRun`, the estimates of one method that they are
computed on (docs/DESIGN.md §9).

NRMSE = RMSE / (max − min of the parameter over the setup's catalogue); overall = the mean of the
five per-parameter values. Coverage = share of objects whose truth lies in the central Gaussian
interval mean ± z·std.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.stats import norm
from shapely.geometry import Point

from pushtoknow.common.params import PARAM_NAMES, PARAM_RANGES


def param_ranges() -> np.ndarray:
    """(5,) max − min of each parameter over the catalogue, PARAM_NAMES order."""
    return np.array([PARAM_RANGES[k][1] - PARAM_RANGES[k][0] for k in PARAM_NAMES])


def nrmse(pred: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    """pred, truth: (N, 5) SI. Returns {param: NRMSE, ..., "overall": mean of the five}."""
    pred, truth = np.asarray(pred, float), np.asarray(truth, float)
    if pred.shape != truth.shape or pred.ndim != 2 or pred.shape[1] != len(PARAM_NAMES):
        raise ValueError(
            f"expected pred and truth of shape (N, 5), got {pred.shape}, {truth.shape}"
        )
    rmse = np.sqrt(np.mean((pred - truth) ** 2, axis=0))
    per = rmse / param_ranges()
    out = {k: float(v) for k, v in zip(PARAM_NAMES, per)}
    out["overall"] = float(per.mean())
    return out


def product_nrmse(
    pred: np.ndarray, truth: np.ndarray, pred_product: np.ndarray | None = None
) -> float:
    """NRMSE of μ·m (the quantity quasi-static force reveals, docs/DESIGN.md §10), normalised by the
    catalogue range of the product. pred_product (N,): the predicted μ·m when the predictor
    gives it directly (e.g. a Gaussian belief's E[μ·m] = μ̄·m̄ + Cov(μ, m)); else the product
    of pred's mass and friction columns."""
    lo = PARAM_RANGES["mass"][0] * PARAM_RANGES["friction"][0]
    hi = PARAM_RANGES["mass"][1] * PARAM_RANGES["friction"][1]
    p = pred[:, 0] * pred[:, 1] if pred_product is None else np.asarray(pred_product, float)
    t = truth[:, 0] * truth[:, 1]
    return float(np.sqrt(np.mean((p - t) ** 2)) / (hi - lo))


def gaussian_zscores(mean: np.ndarray, std: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(truth − mean) / std: z-scores of a method whose belief is Gaussian in SI units."""
    return (np.asarray(truth) - np.asarray(mean)) / np.maximum(np.asarray(std), 1e-300)


@dataclass
class MethodRun:
    """Estimates of one method on one set: mean, std (N, K+1, 5) SI after k = 0..K pushes,
    product (N, K+1) E[μ·m] or None (then m̄·μ̄), truth (N, 5), ids (N,); zscore
    (N, K+1, 5) of the truth where the belief is not Gaussian in SI (the filter's), else None
    (then (truth − mean) / std); lower, upper (N, K+1, 5) SI: the 90% interval each estimate
    reports (from the same distribution as its mean, docs/DESIGN.md §2), or None where the run
    has none (then `estimates_outside_interval` is not computed)."""

    mean: np.ndarray
    std: np.ndarray
    truth: np.ndarray
    ids: list[str]
    product: np.ndarray | None = None
    seconds_per_object: float | None = None
    zscore: np.ndarray | None = None
    profiles: list[list[str]] | None = None  # (N, K) speed profile of each push it chose
    lower: np.ndarray | None = None
    upper: np.ndarray | None = None

    def zscores(self, k: int) -> np.ndarray:
        """(N, 5) z-scores of the truth after push k."""
        if self.zscore is not None:
            return self.zscore[:, k]
        return gaussian_zscores(self.mean[:, k], self.std[:, k], self.truth)


def coverage(zscores: np.ndarray, level: float = 0.9) -> dict:
    """Share of objects whose truth lies in the method's equal-tailed `level` interval, from
    z-scores (N, P) of the truth in the space where the method's belief is Gaussian (SI for
    the forest and the prior, normalised parameters for the filter: `PushEstimate.zscore`)."""
    inside = np.abs(np.asarray(zscores)) <= norm.ppf(0.5 + level / 2)
    out = {k: float(v) for k, v in zip(PARAM_NAMES, inside.mean(0))}
    out["overall"] = float(inside.mean())
    return out


def impossible_estimates(mean: np.ndarray, footprints: list) -> int:
    """How many estimates (object, push) describe no possible object: m, μ or I_z not positive,
    the CoM outside the convex hull of the object's footprint (where no mass distribution over it
    puts its CoM; `Footprint.com_region`), or I_z above the most any mass distribution inside
    the footprint can have (m · max ‖p − c‖²). mean: (N, K, 5) SI; footprints: N
    `testbed.shapes.Footprint` (the true ones)."""
    idx = {k: PARAM_NAMES.index(k) for k in PARAM_NAMES}
    count = 0
    for est, fp in zip(np.asarray(mean, dtype=float), footprints, strict=True):
        for e in est:
            m, mu, iz = e[idx["mass"]], e[idx["friction"]], e[idx["inertia"]]
            com = (e[idx["com_x"]], e[idx["com_y"]])
            possible = (
                np.isfinite(e).all()
                and m > 0
                and mu > 0
                and iz > 0
                and fp.com_region().covers(Point(*com))
                and iz <= m * fp.max_radius_from(com) ** 2
            )
            count += not possible
    return count


OUTSIDE_INTERVAL_RTOL = 1e-9  # rounding of the interval's quantiles, relative to its bounds


def estimates_outside_interval(mean: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> int:
    """How many estimates (object, push) report a mean outside their own interval: some
    parameter's mean < lower or > upper, beyond a relative tolerance of
    `OUTSIDE_INTERVAL_RTOL` × the larger |bound| of that parameter's interval (so a mean at a
    bound, or rounded past it, is inside). Each estimate counts once however many of its
    parameters are outside; a non-finite mean or bound counts as outside (it lies in no
    interval). mean, lower, upper: (..., 5) SI, e.g. (N, K+1, 5); every estimate following
    docs/DESIGN.md §2 (one distribution per parameter, log-concave) gives 0."""
    mean, lower, upper = (np.asarray(a, dtype=float) for a in (mean, lower, upper))
    if not mean.shape == lower.shape == upper.shape or mean.shape[-1:] != (len(PARAM_NAMES),):
        raise ValueError(
            f"expected mean, lower and upper of one shape (..., {len(PARAM_NAMES)}), got "
            f"{mean.shape}, {lower.shape}, {upper.shape}"
        )
    with np.errstate(invalid="ignore"):
        tol = OUTSIDE_INTERVAL_RTOL * np.maximum(np.abs(lower), np.abs(upper))
        inside = (mean >= lower - tol) & (mean <= upper + tol)
    return int(np.count_nonzero(~inside.all(axis=-1)))


class PriorMeanPredictor:
    """Predicts the training objects' mean parameters for every object (the trivial baseline)."""

    def fit(self, params: np.ndarray) -> PriorMeanPredictor:
        params = np.asarray(params, float)
        self.mean_ = params.mean(0)
        self.std_ = params.std(0)
        return self

    def predict(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        return np.tile(self.mean_, (n, 1)), np.tile(self.std_, (n, 1))
