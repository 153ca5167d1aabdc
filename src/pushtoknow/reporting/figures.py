"""The paper's figures from plain data (docs/DESIGN.md §9): Fig. 4 (learning curves, learning
efficiency),
Fig. 5 (estimates versus push number), NRMSE versus number of pushes and a calibration plot.

Every function takes numbers (numpy arrays, lists of tuples, dicts), writes one PNG and keeps no
matplotlib state: figures are built with `matplotlib.figure.Figure` on an Agg canvas, never with
pyplot, so nothing is left open and no backend is switched. The PNG's size in pixels is exactly
figsize × dpi (no tight bounding box), which the tests rely on.

Parameters are in SI at this boundary (kg, -, m, m, kg·m²); the plots show c_x, c_y in mm and I_z
in g·m² as the paper does (`DISPLAY`).
"""

from __future__ import annotations

import csv
import math
from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
from matplotlib.backends.backend_agg import FigureCanvasAgg
from matplotlib.figure import Figure
from matplotlib.patches import Patch
from scipy.stats import norm

from pushtoknow.common.params import PARAM_NAMES, PARAM_RANGES
from pushtoknow.reporting.units import DISPLAY_UNITS

AXIS_NAMES = {"mass": "mass m", "friction": "friction μ", "com_x": "c_x", "com_y": "c_y",
              "inertia": "I_z"}  # fmt: skip
# name → (factor from SI to the plotted unit, axis label), units from `DISPLAY_UNITS`
DISPLAY: dict[str, tuple[float, str]] = {
    **{
        n: (DISPLAY_UNITS[n][0], f"{a} ({DISPLAY_UNITS[n][1]})" if DISPLAY_UNITS[n][1] else a)
        for n, a in AXIS_NAMES.items()
    },
    "overall": (1.0, "overall"),
}
CALIBRATION_LEVELS: tuple[float, ...] = tuple(round(0.05 * i, 2) for i in range(1, 20))
DPI = 110


def display(name: str) -> tuple[float, str]:
    """(factor SI → plotted unit, axis label) of a parameter; unknown names: (1, name)."""
    return DISPLAY.get(name, (1.0, name))


# ----------------------------------------------------------------------------------------------
# helpers


def _figure(figsize: tuple[float, float], dpi: int) -> Figure:
    fig = Figure(figsize=figsize, dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    return fig


def _save(fig: Figure, path: Path | str, dpi: int) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi, format="png")
    return path


def _colour(i: int) -> str:
    return f"C{i % 10}"


def _rows(what: str, rows, width: int) -> np.ndarray:
    """A non-empty sequence of `width`-tuples of finite numbers → (n, width) float array."""
    try:
        a = np.asarray(rows, dtype=float)
    except (TypeError, ValueError) as e:
        raise ValueError(f"{what}: expected a sequence of {width}-tuples of numbers ({e})") from e
    if a.size == 0:
        raise ValueError(f"{what}: empty")
    if a.ndim != 2 or a.shape[1] != width:
        raise ValueError(f"{what}: expected rows of {width} numbers, got shape {a.shape}")
    if not np.isfinite(a).all():
        raise ValueError(f"{what}: non-finite values")
    return a[np.argsort(a[:, 0], kind="stable")]


def _non_empty(what: str, d: Mapping) -> None:
    if not isinstance(d, Mapping):
        raise ValueError(f"{what}: expected a dict, got {type(d).__name__}")
    if len(d) == 0:
        raise ValueError(f"{what}: empty (no series to plot)")


def _names(names: Sequence[str] | None, width: int, what: str) -> tuple[str, ...]:
    names = tuple(PARAM_NAMES if names is None else names)
    if len(names) != width:
        raise ValueError(f"{what}: {width} columns but {len(names)} names {names}")
    return names


# ----------------------------------------------------------------------------------------------
# Fig. 5: estimates versus push number


def plot_estimates_vs_push(
    per_push_mean: np.ndarray | Mapping[str, np.ndarray],
    per_push_std: np.ndarray | Mapping[str, np.ndarray],
    truth: np.ndarray | None,
    path: Path | str,
    names: Sequence[str] | None = None,
    title: str = "",
    *,
    clip_to_catalogue: bool = True,
    figsize: tuple[float, float] | None = None,
    dpi: int = DPI,
) -> Path:
    """The paper's Fig. 5: one panel per parameter, the belief mean with ±1σ and ±2σ bands versus
    push number 0..K (0 = the prior), the truth as a dashed line when given.

    per_push_mean, per_push_std: (K+1, P) in SI, row k = the belief after push k; or a dict
    {label: (K+1, P) array} (same keys in both) to overlay several methods (e.g. the ablations).
    truth: (P,) SI or None. names: the P parameter names (default PARAM_NAMES); c_x, c_y are drawn
    in mm and I_z in g·m². clip_to_catalogue: limit the y axis to the catalogue range (padded by
    10%, widened to show every mean and the truth) so a wide prior band does not flatten the plot.
    figsize defaults to (3.2·P, 3.0) inches. Returns the path written.
    """
    if isinstance(per_push_mean, Mapping) != isinstance(per_push_std, Mapping):
        raise ValueError("per_push_mean and per_push_std: both arrays or both dicts")
    means = per_push_mean if isinstance(per_push_mean, Mapping) else {"estimate": per_push_mean}
    stds = per_push_std if isinstance(per_push_std, Mapping) else {"estimate": per_push_std}
    _non_empty("per_push_mean", means)
    if set(means) != set(stds):
        raise ValueError(
            f"per_push_mean and per_push_std: different labels {set(means) ^ set(stds)}"
        )
    series = {}
    for label in means:
        m = np.asarray(means[label], dtype=float)
        s = np.asarray(stds[label], dtype=float)
        if m.ndim == 1:
            m = m[None]
        if s.ndim == 1:
            s = s[None]
        if m.size == 0:
            raise ValueError(f"per_push_mean[{label!r}]: empty")
        if m.ndim != 2 or m.shape != s.shape:
            raise ValueError(
                f"per_push_mean[{label!r}] {m.shape} and per_push_std {s.shape}: "
                "expected the same (K+1, P) shape"
            )
        if (s < 0).any():
            raise ValueError(f"per_push_std[{label!r}]: negative standard deviations")
        series[label] = (m, s)
    widths = {m.shape[1] for m, _ in series.values()}
    if len(widths) != 1:
        raise ValueError(f"per_push_mean: series with different numbers of parameters {widths}")
    P = widths.pop()
    names = _names(names, P, "per_push_mean")
    if truth is not None:
        truth = np.asarray(truth, dtype=float).reshape(-1)
        if truth.shape != (P,):
            raise ValueError(f"truth: expected {P} values, got shape {truth.shape}")

    fig = _figure(figsize or (3.2 * P, 3.0), dpi)
    axes = fig.subplots(1, P, squeeze=False)[0]
    several = len(series) > 1
    for j, (ax, name) in enumerate(zip(axes, names, strict=True)):
        f, label = display(name)
        shown = []
        for i, (lab, (m, s)) in enumerate(series.items()):
            k = np.arange(len(m))
            mu, sd = f * m[:, j], f * s[:, j]
            c = _colour(i)
            ax.fill_between(k, mu - 2 * sd, mu + 2 * sd, color=c, alpha=0.12, lw=0)
            ax.fill_between(k, mu - sd, mu + sd, color=c, alpha=0.28, lw=0)
            ax.plot(k, mu, "o-", color=c, ms=3, lw=1.2, label=lab if several else "mean")
            shown.append(mu)
        if truth is not None:
            ax.axhline(f * truth[j], color="k", ls="--", lw=1, label="truth")
            shown.append(np.array([f * truth[j]]))
        if clip_to_catalogue and name in PARAM_RANGES:
            lo, hi = (f * v for v in PARAM_RANGES[name])
            pad = 0.1 * (hi - lo)
            allv = np.concatenate(shown)
            ax.set_ylim(min(lo - pad, allv.min() - pad), max(hi + pad, allv.max() + pad))
        K = max(len(m) for m, _ in series.values())
        ax.set_xticks(np.arange(K))
        ax.set_xlabel("push (0 = prior)")
        ax.set_title(label, fontsize=9)
        ax.grid(alpha=0.3)
    h, lab = axes[0].get_legend_handles_labels()
    if not several:
        h += [Patch(color="C0", alpha=0.4), Patch(color="C0", alpha=0.15)]
        lab += ["±1σ", "±2σ"]
    axes[0].legend(h, lab, fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path, dpi)


def _finish_curves(fig, ax, xlabel: str, ylabel: str, title: str, path, dpi: int) -> Path:
    """Labels, grid, legend and title of a one-panel curve plot; writes it."""
    ax.set_xlabel(xlabel)
    ax.set_ylabel(ylabel)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8)
    if title:
        ax.set_title(title, fontsize=10)
    return _save(fig, path, dpi)


# ----------------------------------------------------------------------------------------------
# Fig. 4a: learning curves


def read_curve(
    csv_path: Path | str, x: str = "step", y: str = "val_param_rmse_mean"
) -> list[tuple[float, float]]:
    """One (x, y) column pair of a training log (`training.pipeline.CsvLog` CSV, e.g.
    end_to_end.csv: step, val_param_rmse_mean, val_param_nll, train_loss, ...; supervised.csv:
    step, train_loss, val_loss, ...) as [(x, y), ...] in file order. Rows where either value is
    blank or not a finite number are skipped (CsvLog leaves columns blank in rows that lack
    them). Raises ValueError naming a missing column."""
    csv_path = Path(csv_path)
    with open(csv_path, newline="") as f:
        reader = csv.DictReader(f)
        cols = reader.fieldnames or []
        for c in (x, y):
            if c not in cols:
                raise ValueError(f"{csv_path.name}: no column {c!r} (columns: {', '.join(cols)})")
        out = []
        for row in reader:
            try:
                xv, yv = float(row[x]), float(row[y])
            except (TypeError, ValueError):  # blank (or None in a short row)
                continue
            if math.isfinite(xv) and math.isfinite(yv):
                out.append((xv, yv))
    return out


def plot_learning_curves(
    curves: Mapping[str, Sequence[tuple[float, float]]],
    path: Path | str,
    ylabel: str = "validation loss",
    title: str = "",
    *,
    xlabel: str = "training step",
    yscale: str = "linear",
    figsize: tuple[float, float] = (5.0, 3.4),
    dpi: int = DPI,
) -> Path:
    """The paper's Fig. 4a: a validation metric versus training step for several variants.

    curves: {variant (e.g. "vt-addf", "vt-jdf", "v-ddf"): [(step, value), ...]} (see `read_curve`);
    points are sorted by step. yscale: any matplotlib scale ("linear", "log", "symlog"); the NLL
    losses span orders of magnitude early in training. Returns the path written."""
    _non_empty("curves", curves)
    data = {k: _rows(f"curves[{k!r}]", v, 2) for k, v in curves.items()}
    fig = _figure(figsize, dpi)
    ax = fig.add_subplot()
    for i, (label, a) in enumerate(data.items()):
        ax.plot(
            a[:, 0],
            a[:, 1],
            "-",
            marker="." if len(a) < 40 else None,
            color=_colour(i),
            lw=1.3,
            label=label,
        )
    ax.set_yscale(yscale)
    return _finish_curves(fig, ax, xlabel, ylabel, title, path, dpi)


# ----------------------------------------------------------------------------------------------
# Fig. 4b: learning efficiency


def plot_learning_efficiency(
    results: Mapping[str, Sequence[tuple[float, float, float]]],
    path: Path | str,
    ylabel: str = "validation loss",
    title: str = "",
    *,
    xlabel: str = "training pushes",
    xscale: str = "linear",
    figsize: tuple[float, float] = (5.0, 3.4),
    dpi: int = DPI,
) -> Path:
    """The paper's Fig. 4b: a validation metric versus the number of training pushes, one line per
    data-collection policy (uniform, random, active-20/50/70 ...), error bars ±1 std over seeds.

    results: {policy: [(num_pushes, mean, std), ...]}; std ≥ 0. Returns the path written."""
    _non_empty("results", results)
    data = {k: _rows(f"results[{k!r}]", v, 3) for k, v in results.items()}
    for k, a in data.items():
        if (a[:, 2] < 0).any():
            raise ValueError(f"results[{k!r}]: negative std")
    fig = _figure(figsize, dpi)
    ax = fig.add_subplot()
    for i, (label, a) in enumerate(data.items()):
        ax.errorbar(
            a[:, 0],
            a[:, 1],
            yerr=a[:, 2],
            fmt="o-",
            ms=4,
            lw=1.3,
            capsize=3,
            color=_colour(i),
            label=label,
        )
    ax.set_xscale(xscale)
    return _finish_curves(fig, ax, xlabel, ylabel, title, path, dpi)


# ----------------------------------------------------------------------------------------------
# NRMSE versus number of pushes


def plot_nrmse_vs_pushes(
    results: Mapping[str, Mapping[str, Sequence[tuple[float, float, float]]]],
    path: Path | str,
    params: Sequence[str] | None = None,
    prior_nrmse: Mapping[str, float] | None = None,
    title: str = "",
    *,
    figsize: tuple[float, float] | None = None,
    dpi: int = DPI,
) -> Path:
    """NRMSE after K = 0, 1, ... pushes, one panel per parameter, one line per method or push
    policy, error bars ±1 std (over folds or seeds).

    results: {method: {param: [(k, nrmse_mean, nrmse_std), ...]}}; param is a PARAM_NAMES entry or
    "overall". params: the panels, in order (default: PARAM_NAMES then "overall", those present in
    any method); a method lacking a panel's parameter is left out of that panel. prior_nrmse:
    {param: NRMSE of the prior-mean predictor}, drawn as a dashed horizontal line. NRMSE is
    unitless (normalised by the catalogue range). figsize defaults to (3.0·panels, 3.0).
    Returns the path written."""
    _non_empty("results", results)
    for method, per in results.items():
        _non_empty(f"results[{method!r}]", per)
    present = [p for per in results.values() for p in per]
    if params is None:
        params = [p for p in (*PARAM_NAMES, "overall") if p in present]
        params += [p for p in dict.fromkeys(present) if p not in params]
    params = list(params)
    if not params:
        raise ValueError("params: empty (no panel to draw)")
    missing = [p for p in params if p not in present]
    if missing:
        raise ValueError(f"params: no method has results for {missing}")
    if prior_nrmse is not None:
        prior_nrmse = {k: float(v) for k, v in prior_nrmse.items()}
    data = {
        (m, p): _rows(f"results[{m!r}][{p!r}]", per[p], 3)
        for m, per in results.items()
        for p in params
        if p in per
    }
    fig = _figure(figsize or (3.0 * len(params), 3.0), dpi)
    axes = fig.subplots(1, len(params), squeeze=False)[0]
    n = len(results)
    for ax, p in zip(axes, params, strict=True):
        for i, m in enumerate(results):
            if (m, p) not in data:
                continue
            a = data[(m, p)]
            dodge = 0.06 * (i - (n - 1) / 2)  # keep the error bars of methods apart
            ax.errorbar(
                a[:, 0] + dodge,
                a[:, 1],
                yerr=a[:, 2],
                fmt="o-",
                ms=3,
                lw=1.2,
                capsize=2,
                color=_colour(i),
                label=m,
            )
        if prior_nrmse is not None and p in prior_nrmse:
            ax.axhline(prior_nrmse[p], color="0.4", ls="--", lw=1, label="prior mean")
        ax.set_title(display(p)[1].split(" (")[0], fontsize=9)  # NRMSE is unitless
        ax.set_xlabel("pushes K")
        ax.xaxis.get_major_locator().set_params(integer=True)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("NRMSE")
    axes[0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    return _save(fig, path, dpi)


# ----------------------------------------------------------------------------------------------
# calibration


def calibration_coverage(
    zscores: np.ndarray,
    names: Sequence[str] | None = None,
    levels: Sequence[float] = CALIBRATION_LEVELS,
) -> dict:
    """Observed coverage of the central intervals at each nominal level p: the share of objects
    whose truth's z-score (in the space where the belief is Gaussian: `metrics.coverage`) has
    |z| ≤ Φ⁻¹(½ + p/2).

    zscores: (N, P); names: the P parameter names (default PARAM_NAMES). levels: nominal levels
    in (0, 1). Returns {"levels": [p, ...], "observed": {name: [share per level], ...,
    "overall": [share over all N·P values]}, "miscalibration": {name: mean |observed − p| over
    the levels, ..., "overall"}, "objects": N} — plain floats, ready for JSON."""
    zscores = np.asarray(zscores, dtype=float)
    if zscores.size == 0:
        raise ValueError("zscores: empty")
    if zscores.ndim != 2:
        raise ValueError(f"zscores: expected shape (N, P), got {zscores.shape}")
    if np.isnan(zscores).any():
        raise ValueError("zscores: NaN values")
    names = _names(names, zscores.shape[1], "zscores")
    p = np.asarray(levels, dtype=float).reshape(-1)
    if p.size == 0:
        raise ValueError("levels: empty")
    if ((p <= 0) | (p >= 1)).any():
        raise ValueError(f"levels: must lie in (0, 1), got {p.tolist()}")
    z = norm.ppf(0.5 + p / 2)  # (L,)
    inside = np.abs(zscores)[None] <= z[:, None, None]  # (L, N, P)
    per = inside.mean(axis=1)  # (L, P)
    overall = inside.mean(axis=(1, 2))  # (L,)
    observed = {n: per[:, j].tolist() for j, n in enumerate(names)}
    observed["overall"] = overall.tolist()
    mis = {n: float(np.mean(np.abs(np.asarray(v) - p))) for n, v in observed.items()}
    return {
        "levels": p.tolist(),
        "observed": observed,
        "miscalibration": mis,
        "objects": int(zscores.shape[0]),
    }


def plot_calibration(
    zscores: np.ndarray,
    path: Path | str,
    names: Sequence[str] | None = None,
    title: str = "",
    *,
    levels: Sequence[float] = CALIBRATION_LEVELS,
    figsize: tuple[float, float] = (5.4, 4.0),
    dpi: int = DPI,
) -> dict:
    """Reliability plot of the posterior's intervals: observed coverage versus nominal level p
    (0.05 … 0.95 by default) per parameter and overall, with the diagonal (perfect
    calibration; below it = overconfident, above = underconfident).

    zscores: (N, P) of the truth, one row per object; names: the P parameter names (default
    PARAM_NAMES). Returns `calibration_coverage(...)` for the caller's JSON."""
    cov = calibration_coverage(zscores, names, levels)
    p = np.asarray(cov["levels"])
    fig = _figure(figsize, dpi)
    ax = fig.add_subplot()
    ax.plot([0, 1], [0, 1], color="0.5", ls=":", lw=1, label="ideal")
    for i, (n, v) in enumerate(cov["observed"].items()):
        if n == "overall":
            ax.plot(p, v, "k-", lw=2, label="overall")
        else:
            ax.plot(p, v, "o-", ms=3, lw=1, color=_colour(i), label=display(n)[1].split(" (")[0])
    ax.set_xlim(0, 1)
    ax.set_ylim(-0.02, 1.02)
    ax.set_aspect("equal")
    ax.set_xlabel("nominal central interval level p")
    ax.set_ylabel(f"observed coverage ({cov['objects']} objects)")
    ax.grid(alpha=0.3)
    fig.legend(fontsize=7, loc="outside right upper")
    if title:
        ax.set_title(title, fontsize=10)
    _save(fig, path, dpi)
    return cov
