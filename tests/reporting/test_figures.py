import csv
from types import SimpleNamespace

import matplotlib.image as mpimg
import numpy as np
import pytest
from scipy.stats import norm

from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.evaluation.metrics import coverage, gaussian_zscores
from pushtoknow.reporting.figures import (
    CALIBRATION_LEVELS,
    calibration_coverage,
    plot_calibration,
    plot_estimates_vs_push,
    plot_learning_curves,
    plot_learning_efficiency,
    plot_nrmse_vs_pushes,
    read_curve,
)

DPI = 50  # small PNGs: fast to write and read back


def assert_png(path, figsize, dpi=DPI):
    assert path.exists() and path.stat().st_size > 0
    img = mpimg.imread(path)
    assert img.shape[:2] == (round(figsize[1] * dpi), round(figsize[0] * dpi))
    assert img.std() > 0  # something was drawn


def belief(K=3, P=5, seed=0):
    """A shrinking belief around a truth: (K+1, P) mean and std in SI, truth (P,)."""
    rng = np.random.default_rng(seed)
    truth = np.array([0.5, 0.5, 0.01, -0.01, 1.0e-3])[:P]
    scale = np.array([0.3, 0.1, 0.015, 0.015, 3e-4])[:P]
    shrink = 1.0 / (1 + np.arange(K + 1))[:, None]
    std = scale * shrink
    mean = truth + std * rng.normal(size=(K + 1, P))
    return mean, std, truth


def test_estimates_vs_push_single_and_overlay(tmp_path):
    mean, std, truth = belief()
    out = plot_estimates_vs_push(mean, std, truth, tmp_path / "a.png", title="x", dpi=DPI)
    assert_png(out, (3.2 * 5, 3.0))
    # several methods overlaid, no truth, custom size
    m2, s2, _ = belief(seed=1)
    out = plot_estimates_vs_push(
        {"vt-addf": mean, "v-ddf": m2},
        {"vt-addf": std, "v-ddf": s2},
        None,
        tmp_path / "b.png",
        figsize=(10, 2.5),
        dpi=DPI,
    )
    assert_png(out, (10, 2.5))


def test_estimates_vs_push_bad_input(tmp_path):
    mean, std, truth = belief()
    with pytest.raises(ValueError, match="same"):
        plot_estimates_vs_push(mean, std[:-1], truth, tmp_path / "x.png")
    with pytest.raises(ValueError, match="truth"):
        plot_estimates_vs_push(mean, std, truth[:4], tmp_path / "x.png")
    with pytest.raises(ValueError, match="names"):
        plot_estimates_vs_push(mean, std, truth, tmp_path / "x.png", names=["a", "b"])
    with pytest.raises(ValueError, match="empty"):
        plot_estimates_vs_push(np.zeros((0, 5)), np.zeros((0, 5)), None, tmp_path / "x.png")
    with pytest.raises(ValueError, match="negative"):
        plot_estimates_vs_push(mean, -std, truth, tmp_path / "x.png")
    with pytest.raises(ValueError, match="labels"):
        plot_estimates_vs_push({"a": mean}, {"b": std}, truth, tmp_path / "x.png")
    assert not (tmp_path / "x.png").exists()


def test_viz_plot_estimates_delegates(tmp_path):
    from pushtoknow.viz import plot_estimates

    mean, std, truth = belief(K=2)
    rows = [SimpleNamespace(index=i, mean=m, std=s) for i, (m, s) in enumerate(zip(mean, std))]
    result = SimpleNamespace(prior=rows[0], estimates=rows[1:], truth=truth)
    plot_estimates(result, tmp_path / "e.png", title="obj")
    import matplotlib.pyplot as plt

    assert plt.get_fignums() == []  # nothing left open
    assert mpimg.imread(tmp_path / "e.png").shape[:2] == (330, 1760)  # (3.2·5, 3) in at 110 dpi


def write_log(path):
    """A CsvLog-like file: the first row has no train_loss (blank), one row has 'nan'."""
    rows = [
        {"step": 0, "val_loss": 3.0, "train_loss": ""},
        {"step": 50, "val_loss": 2.0, "train_loss": 5.0},
        {"step": 100, "val_loss": "", "train_loss": 4.0},
        {"step": 150, "val_loss": "nan", "train_loss": 3.5},
        {"step": 200, "val_loss": 1.5, "train_loss": 3.0},
    ]
    with open(path, "w", newline="") as f:
        w = csv.DictWriter(f, ["step", "val_loss", "train_loss"])
        w.writeheader()
        w.writerows(rows)
    return path


def test_read_curve(tmp_path):
    log = write_log(tmp_path / "end_to_end.csv")
    assert read_curve(log, y="val_loss") == [(0.0, 3.0), (50.0, 2.0), (200.0, 1.5)]
    assert read_curve(log, y="train_loss") == [(50, 5.0), (100, 4.0), (150, 3.5), (200, 3.0)]
    with pytest.raises(ValueError, match="no column 'val_param_nll'"):
        read_curve(log, y="val_param_nll")


def test_learning_curves(tmp_path):
    log = write_log(tmp_path / "log.csv")
    curves = {
        "vt-addf": read_curve(log, y="val_loss"),
        "vt-jdf": [(0, 3.5), (100, 2.5), (200, 2.2)],
        "v-ddf": [(200, 2.9), (0, 3.2)],  # unsorted is fine
    }
    out = plot_learning_curves(
        curves, tmp_path / "fig4a.png", "val NLL", "Fig. 4a", yscale="log", dpi=DPI
    )
    assert_png(out, (5.0, 3.4))
    with pytest.raises(ValueError, match="curves: empty"):
        plot_learning_curves({}, tmp_path / "x.png")
    with pytest.raises(ValueError, match=r"curves\['v-ddf'\]: empty"):
        plot_learning_curves({"v-ddf": []}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="2 numbers"):
        plot_learning_curves({"v-ddf": [(0, 1, 2)]}, tmp_path / "x.png")


def test_learning_efficiency(tmp_path):
    results = {
        "uniform": [(100, 1.0, 0.1), (200, 0.8, 0.1), (400, 0.7, 0.05)],
        "random": [(100, 0.9, 0.2), (200, 0.75, 0.1), (400, 0.65, 0.05)],
        "active-50": [(100, 0.8, 0.1), (200, 0.6, 0.05), (400, 0.55, 0.0)],
    }
    out = plot_learning_efficiency(
        results, tmp_path / "fig4b.png", xscale="log", figsize=(4, 3), dpi=DPI
    )
    assert_png(out, (4, 3))
    with pytest.raises(ValueError, match="results: empty"):
        plot_learning_efficiency({}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="3 numbers"):
        plot_learning_efficiency({"uniform": [(100, 1.0)]}, tmp_path / "x.png")
    with pytest.raises(ValueError, match="negative std"):
        plot_learning_efficiency({"uniform": [(100, 1.0, -0.1)]}, tmp_path / "x.png")


def test_nrmse_vs_pushes(tmp_path):
    def series(start):
        return [(k, start / (1 + k), 0.02) for k in range(6)]

    params = [*PARAM_NAMES, "overall"]
    results = {
        "active": {p: series(0.4) for p in params},
        "uniform": {p: series(0.45) for p in params},
        "baseline": {"mass": series(0.3)},  # only one parameter: drawn in that panel only
    }
    prior = dict.fromkeys(params, 0.39)
    out = plot_nrmse_vs_pushes(results, tmp_path / "nrmse.png", prior_nrmse=prior, dpi=DPI)
    assert_png(out, (3.0 * 6, 3.0))
    out = plot_nrmse_vs_pushes(results, tmp_path / "mass.png", params=["mass"], dpi=DPI)
    assert_png(out, (3.0, 3.0))
    with pytest.raises(ValueError, match="results: empty"):
        plot_nrmse_vs_pushes({}, tmp_path / "x.png")
    with pytest.raises(ValueError, match=r"no method has results for \['weight'\]"):
        plot_nrmse_vs_pushes(results, tmp_path / "x.png", params=["weight"])
    with pytest.raises(ValueError, match=r"results\['active'\]\['mass'\]: empty"):
        plot_nrmse_vs_pushes({"active": {"mass": []}}, tmp_path / "x.png")


def constructed(N=20, seed=0):
    """Truth at known multiples of std: column 0 at the central-interval quantiles
    z((i + ½)/N), so exactly j of N objects lie inside the level-j/N interval (perfect
    calibration on the 0.05 grid); column 1 at 3σ (never inside up to p = 0.95, z = 1.96);
    column 2 exactly at the mean (always inside); columns 3, 4 at 1σ (inside iff z_p ≥ 1, i.e.
    p ≥ 0.6827). Signs random: the interval is two-sided."""
    rng = np.random.default_rng(seed)
    q = (np.arange(N) + 0.5) / N
    k = np.stack([norm.ppf(0.5 + q / 2), np.full(N, 3.0), np.zeros(N), np.ones(N), np.ones(N)], 1)
    k *= rng.choice([-1.0, 1.0], size=k.shape)
    mean = rng.normal(size=(N, 5))
    std = rng.uniform(0.1, 2.0, size=(N, 5))
    return mean, std, mean + k * std


def test_calibration_coverage_exact(tmp_path):
    mean, std, truth = constructed()
    z = gaussian_zscores(mean, std, truth)
    cov = plot_calibration(z, tmp_path / "cal.png", title="t", dpi=DPI)
    assert_png(tmp_path / "cal.png", (5.4, 4.0))
    p = np.array(CALIBRATION_LEVELS)
    assert cov["levels"] == pytest.approx(p)
    assert cov["objects"] == 20
    obs = cov["observed"]
    assert obs["mass"] == pytest.approx(p)  # j / 20 at p = j / 20
    assert obs["friction"] == [0.0] * len(p)
    assert obs["com_x"] == [1.0] * len(p)
    one_sigma = (p >= 0.6827).astype(float)
    assert obs["com_y"] == pytest.approx(one_sigma)
    assert obs["inertia"] == pytest.approx(one_sigma)
    assert obs["overall"] == pytest.approx((p + 0 + 1 + 2 * one_sigma) / 5)
    assert cov["miscalibration"]["mass"] == pytest.approx(0.0, abs=1e-12)
    assert cov["miscalibration"]["com_x"] == pytest.approx(np.mean(1 - p))
    # JSON-ready plain floats
    assert all(type(v) is float for v in obs["mass"])


def test_calibration_agrees_with_metrics_coverage():
    rng = np.random.default_rng(3)
    mean, std = rng.normal(size=(200, 5)), rng.uniform(0.5, 1.5, size=(200, 5))
    truth = mean + rng.normal(size=(200, 5))
    z = gaussian_zscores(mean, std, truth)
    cov = calibration_coverage(z, levels=[0.9])
    ref = coverage(z, level=0.9)
    for name in [*PARAM_NAMES, "overall"]:
        assert cov["observed"][name][0] == pytest.approx(ref[name])


def test_calibration_bad_input(tmp_path):
    z = gaussian_zscores(*constructed())
    with pytest.raises(ValueError, match="expected shape"):
        plot_calibration(z[0], tmp_path / "x.png")
    with pytest.raises(ValueError, match="names"):
        plot_calibration(z, tmp_path / "x.png", names=["mass"])
    with pytest.raises(ValueError, match="zscores: empty"):
        plot_calibration(np.zeros((0, 5)), tmp_path / "x.png")
    with pytest.raises(ValueError, match="zscores: NaN"):
        plot_calibration(np.full_like(z, np.nan), tmp_path / "x.png")
    with pytest.raises(ValueError, match="levels"):
        calibration_coverage(z, levels=[0.5, 1.0])
    assert not (tmp_path / "x.png").exists()
