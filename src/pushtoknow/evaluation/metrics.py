"""NRMSE, interval coverage and the prior-mean predictor (SPEC §3.7).

NRMSE = RMSE / (max − min of the parameter over the setup's catalogue); overall = the mean of the
five per-parameter values. Coverage = share of objects whose truth lies in the central Gaussian
interval mean ± z·std.
"""

from __future__ import annotations

import numpy as np
from scipy.stats import norm

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
    """NRMSE of μ·m (the quantity quasi-static force reveals, SPEC §3.8), normalised by the
    catalogue range of the product. pred_product (N,): the predicted μ·m when the predictor
    gives it directly (e.g. a Gaussian belief's E[μ·m] = μ̄·m̄ + Cov(μ, m)); else the product
    of pred's mass and friction columns."""
    lo = PARAM_RANGES["mass"][0] * PARAM_RANGES["friction"][0]
    hi = PARAM_RANGES["mass"][1] * PARAM_RANGES["friction"][1]
    p = pred[:, 0] * pred[:, 1] if pred_product is None else np.asarray(pred_product, float)
    t = truth[:, 0] * truth[:, 1]
    return float(np.sqrt(np.mean((p - t) ** 2)) / (hi - lo))


def coverage(mean: np.ndarray, std: np.ndarray, truth: np.ndarray, level: float = 0.9) -> dict:
    """Share of objects whose truth lies within mean ± z·std, z the two-sided `level` quantile."""
    z = norm.ppf(0.5 + level / 2)
    inside = np.abs(np.asarray(truth) - np.asarray(mean)) <= z * np.asarray(std)
    out = {k: float(v) for k, v in zip(PARAM_NAMES, inside.mean(0))}
    out["overall"] = float(inside.mean())
    return out


class PriorMeanPredictor:
    """Predicts the training objects' mean parameters for every object (the trivial baseline)."""

    def fit(self, params: np.ndarray) -> PriorMeanPredictor:
        params = np.asarray(params, float)
        self.mean_ = params.mean(0)
        self.std_ = params.std(0)
        return self

    def predict(self, n: int) -> tuple[np.ndarray, np.ndarray]:
        return np.tile(self.mean_, (n, 1)), np.tile(self.std_, (n, 1))
