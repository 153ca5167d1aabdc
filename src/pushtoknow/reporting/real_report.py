"""The real-data report (`RealReport`, made by `evaluation.real_object.estimate_real_object`, with
its `RealIdentification`) and its tables: the estimates after each push beside the truth, the
normalised errors, and the notes, as markdown."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.reporting.tables import markdown_table as md
from pushtoknow.reporting.units import format_value as _fmt
from pushtoknow.reporting.units import labelled


@dataclass(frozen=True)
class RealIdentification:
    """`evaluation.real_object.identify_real`: the physics-based fits of the first k real pushes,
    k = 1…K, SI; `to_json()` gives its entry of the `estimate-real` JSON."""

    # after each k: {param: {mean, std, interval}, "mu_m": {mean, std, interval},
    # "unidentified" (parameters left at their prior width), "reduced_chi2", "seconds",
    # "rollouts"}
    per_push: list[dict]
    rate_hz: float  # the replay rate: the recorded clock
    noise_std: dict  # the last fit's noise per channel, estimated from its misfit
    model: str  # the replay, in words
    notes: list[str]  # the last fit's

    def to_json(self) -> dict:
        return {f.name: getattr(self, f.name) for f in fields(self)}


@dataclass(frozen=True)
class RealReport:
    """What `evaluation.real_object.estimate_real_object` found on one real object, SI throughout;
    `to_json()` gives the JSON `estimate-real` prints (the fields in order). An error is
    |estimate − truth| / (catalogue max − min) per parameter (None without a truth), with
    "overall" the mean over the parameters with a truth; a μ·m error is normalised by the
    catalogue's range of μ·m. Rows "forest" and "prior_mean" are there only with forest data,
    rows "identify" only when the identification ran."""

    object: str  # "surface:shape"
    data_dir: str
    model: str  # checkpoint or run directory
    forest_data: str | None
    seed: int
    # {"imported_here", "dir" (None: a temporary import), "as_speed_m_per_s" (None: not
    # rescaled), and when imported here "source", "files"} (`prepare_real_data`)
    conversion: dict
    # per push: {"file", "speed_m_per_s" (as labelled), "file_speed_m_per_s", "time_scale",
    # "samples", "displacement_m", "rotation_deg", "pure_translation", "mu_contact_phase",
    # "filter_pose_error_end": {"xy_mm", "theta_deg"}}
    pushes: list[dict]
    truth: dict[str, float | None]  # {param: value}; friction None when no push qualifies
    truth_source: dict[str, str]  # {param: where its truth comes from}
    friction_reference: dict  # `evaluation.real_object.friction_reference`'s
    # {"variant", "sigma_points", "prior": {param: {mean, std}}, "per_push": [the same after
    # each push]}
    filter: dict
    # {"per_push": [{param: {mean, std}} after each push], "training_pushes", "trees"}
    forest: dict | None
    identify: RealIdentification | None
    prior_mean: dict[str, float] | None  # {param: mean over the forest data's objects}
    # {"filter": [{param: error, "overall"} after each push], "filter_prior": {…},
    # "forest": […], "prior_mean": {…}, "identify": […]}
    errors: dict
    # {"truth", "filter_prior": {mean, std}, "filter": [{mean, std} after each push],
    # "errors": {"filter", "forest", "prior_mean", "identify"}, "forest": [after each push],
    # "prior_mean", "identify": [{mean, std, interval} after each push]}
    mu_m: dict
    ranges: dict[str, list[float]]  # {param: [lo, hi]} of the catalogue
    notes: list[str]  # caveats
    seconds: float  # wall time

    def to_json(self) -> dict:
        d = {f.name: getattr(self, f.name) for f in fields(self)}
        if self.identify is not None:
            d["identify"] = self.identify.to_json()
        return d


def table_rows(report: RealReport) -> tuple[list[str], list[list[str]]]:
    """Header and rows (strings) of the estimates table: parameter (unit), truth, filter prior,
    filter after each push (mean ± std), forest after the last push, physics-based
    identification from all pushes (when it ran), prior mean."""
    n = len(report.filter["per_push"])
    header = ["parameter", "truth", "filter prior"]
    header += [f"filter after push {k + 1}" for k in range(n)]
    forest = report.forest
    if forest is not None:
        header.append(f"forest ({n} pushes)")
    ident = report.identify
    if ident is not None:
        header.append(f"identify ({n} pushes)")
    if report.prior_mean is not None:
        header.append("prior mean")
    rows = []
    for p in PARAM_NAMES:
        fp = report.filter["prior"][p]
        row = [labelled(p), _fmt(report.truth[p], p)]
        row.append(_fmt(fp["mean"], p, fp["std"]))
        for e in report.filter["per_push"]:
            row.append(_fmt(e[p]["mean"], p, e[p]["std"]))
        if forest is not None:
            f = forest["per_push"][-1][p]
            row.append(_fmt(f["mean"], p, f["std"]))
        if ident is not None:
            i = ident.per_push[-1][p]
            row.append(_fmt(i["mean"], p, i["std"]))
        if report.prior_mean is not None:
            row.append(_fmt(report.prior_mean[p], p))
        rows.append(row)
    mm = report.mu_m
    row = ["μ·m (kg)", _fmt(mm["truth"], "mu_m")]
    row.append(_fmt(mm["filter_prior"]["mean"], "mu_m", mm["filter_prior"]["std"]))
    row += [_fmt(e["mean"], "mu_m", e["std"]) for e in mm["filter"]]
    if forest is not None:
        row.append(_fmt(mm["forest"][-1], "mu_m"))
    if ident is not None:
        row.append(_fmt(mm["identify"][-1]["mean"], "mu_m", mm["identify"][-1]["std"]))
    if report.prior_mean is not None:
        row.append(_fmt(mm["prior_mean"], "mu_m"))
    rows.append(row)
    return header, rows


def error_rows(report: RealReport) -> tuple[list[str], list[list[str]]]:
    """Header and rows of the normalised errors |estimate − truth| / catalogue range."""
    header = ["predictor", *PARAM_NAMES, "overall", "μ·m"]
    er, mm = report.errors, report.mu_m["errors"]

    def fmt(d: dict, prod) -> list[str]:
        cells = [("—" if d[k] is None else f"{d[k]:.3f}") for k in (*PARAM_NAMES, "overall")]
        return [*cells, "—" if prod is None else f"{prod:.3f}"]

    n = len(er["filter"])
    rows = [["prior mean", *fmt(er["prior_mean"], mm["prior_mean"])]] if "prior_mean" in er else []
    rows += [[f"filter, push {k + 1}", *fmt(er["filter"][k], mm["filter"][k])] for k in range(n)]
    if "forest" in er:
        rows += [
            [f"forest, push {k + 1}", *fmt(er["forest"][k], mm["forest"][k])] for k in range(n)
        ]
    if "identify" in er:
        rows += [
            [f"identify, push {k + 1}", *fmt(er["identify"][k], mm["identify"][k])]
            for k in range(n)
        ]
    return header, rows


def markdown_table(report: RealReport, title: str | None = None) -> str:
    """The estimates and error tables of a report as GitHub markdown, with the notes."""
    lines = [f"### {title}", ""] if title else []
    lines += md(*table_rows(report))
    lines += ["", "Normalised error |estimate − truth| / (catalogue max − min):", ""]
    lines += md(*error_rows(report))
    lines += [""]
    push_lines = [
        f"- push {k + 1}: `{p['file']}`, {p['samples']} samples at {p['speed_m_per_s']} m/s "
        f"(time scale {p['time_scale']:g}), moved {p['displacement_m'] * 100:.1f} cm, "
        f"turned {p['rotation_deg']:+.1f}°{' (pure translation)' if p['pure_translation'] else ''}"
        f"; filter pose error at the end {p['filter_pose_error_end']['xy_mm']:.1f} mm / "
        f"{p['filter_pose_error_end']['theta_deg']:.1f}°"
        for k, p in enumerate(report.pushes)
    ]
    ident = report.identify
    if ident is not None:
        last = ident.per_push[-1]
        noise = ident.noise_std
        push_lines.append(
            f"- identify: {ident.model}; replayed at {ident.rate_hz:g} Hz (the recorded "
            f"clock); noise from the misfit: force {noise['force_N']:.2f} N, position "
            f"{noise['position_m'] * 1e3:.1f} mm, angle {math.degrees(noise['angle_rad']):.1f}°; "
            f"not identified (prior width kept): {', '.join(last['unidentified']) or 'none'}; "
            f"{last['rollouts']} rollouts in {last['seconds']:.0f} s"
        )
    lines += push_lines + [""] + [f"- {n}" for n in report.notes] + [""]
    return "\n".join(lines)
