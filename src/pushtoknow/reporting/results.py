"""docs/RESULTS.md from the results of `run_evaluation` (plus optional real-data results):
tables of NRMSE (mean ± std over folds) and coverage per method and object set, the paper's
numbers beside ours, NRMSE after each push per method, figures, the machine, commands and seeds,
and an interpretation in the light of the testbed's physics (docs/PHYSICS.md). Every number in
it comes from the results."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.reporting.tables import markdown_table

if TYPE_CHECKING:
    from pushtoknow.collection.efficiency import EfficiencyResults

# The paper's Sim-Robotac NRMSE (Table III).
PAPER_NRMSE = {
    "VT-ADDF (paper)": {
        "mass": 0.21,
        "friction": 0.14,
        "com_x": 0.09,
        "com_y": 0.13,
        "inertia": 0.15,
        "overall": 0.14,
    },
    "baseline (paper)": {
        "mass": 0.14,
        "friction": 0.16,
        "com_x": 0.18,
        "com_y": 0.14,
        "inertia": 0.20,
    },
}
COLUMNS = [*PARAM_NAMES, "overall"]
SET_TITLES = (
    ("heldout", "Held-out catalogue objects"),
    ("novel", "Novel objects"),
    ("random", "Random-shape objects"),
)
HEADERS = ["m", "μ", "c_x", "c_y", "I_z", "overall"]


def shown_path(path: str) -> str:
    """`path` as a report shows it: relative to the working directory when inside it (a
    report names no folder of the machine that made it), else its last two parts."""
    p = Path(path)
    try:
        return str(p.resolve().relative_to(Path.cwd().resolve()))
    except ValueError:
        return str(Path(*p.parts[-2:]))


def _cell(mean: float, std: float | None = None) -> str:
    return f"{mean:.3f}" if std is None else f"{mean:.3f} ± {std:.3f}"


def method_table(methods: dict, order: list[str] | None = None) -> str:
    """Markdown table: NRMSE per parameter and overall (mean ± std over folds), μ·m, coverage,
    impossible estimates and estimates whose mean lies outside their own 90% interval (each of
    all N·(K+1); "–" where the run recorded no intervals), share of release pushes chosen,
    seconds per object."""
    header = ["method", *HEADERS, "μ·m", "cov 68%", "cov 90%", "impossible", "outside interval"]
    header += ["release pushes"]
    rows = []
    for name in order or list(methods):
        m = methods[name]
        sec = m.get("seconds_per_object")
        bad = m.get("impossible_estimates")
        outside = m.get("outside_interval")
        share = m.get("profile_share")
        rows.append(
            [
                name,
                *(_cell(m["nrmse"][k], m["nrmse_std"][k]) for k in COLUMNS),
                _cell(m["mu_m"], m["mu_m_std"]),
                f"{m['coverage68']:.2f}",
                f"{m['coverage90']:.2f}",
                "" if bad is None else f"{bad}/{m['estimates']}",
                "–" if outside is None else f"{outside}/{m['estimates']}",
                "" if not share else f"{share.get('release', 0.0):.0%}",
                "" if sec is None else f"{sec:.1f}",
            ]
        )
    return "\n".join(markdown_table([*header, "s/object"], rows))


def paper_table() -> str:
    rows = [
        [name, *(f"{row[k]:.2f}" if k in row else "–" for k in COLUMNS)]
        for name, row in PAPER_NRMSE.items()
    ]
    return "\n".join(markdown_table(["source", *HEADERS], rows))


def per_push_table(methods: dict, param: str) -> str:
    """NRMSE of `param` after k = 0..K pushes (all objects), one row per method."""
    k = len(next(iter(methods.values()))["per_push"])
    rows = [
        [name, *(f"{r[param]:.3f}" for r in m["per_push"])]
        for name, m in methods.items()
        if len(m["per_push"]) == k  # not e.g. the oracle: final estimate only
    ]
    return "\n".join(markdown_table(["method", *(f"k={j}" for j in range(k))], rows))


def coverage_by_push_table(methods: dict) -> str:
    """90% coverage per parameter after the first push and after the last (all objects), one
    row per method that reports every push (not e.g. the oracle: final estimate only)."""
    k = max(len(m["per_push"]) for m in methods.values())
    header = ["method", *(f"{h}, push 1" for h in HEADERS[:-1])]
    header += [f"{h}, push {k - 1}" for h in HEADERS[:-1]]
    rows = []
    for name, m in methods.items():
        pp = m["per_push"]
        if len(pp) != k or "coverage90" not in pp[1]:
            continue
        cells = [f"{pp[j]['coverage90'][p]:.2f}" for j in (1, k - 1) for p in COLUMNS[:-1]]
        rows.append([name, *cells])
    return "\n".join(markdown_table(header, rows))


def interpretation(methods: dict, primary: str, novel: dict | None = None) -> str:
    """A paragraph reading the held-out numbers (and, given, the novel ones) in the light of
    the testbed's physics (docs/PHYSICS.md)."""
    p, prior = methods[primary], methods["prior-mean"]
    n, pn = p["nrmse"], prior["nrmse"]

    def change(k: str) -> str:
        return f"{100 * (n[k] - pn[k]) / pn[k]:+.0f}%"

    forest = methods.get("forest")
    text = [
        f"After {len(p['per_push']) - 1} pushes, {primary} changes the prior-mean predictor's "
        f"NRMSE by {change('mass')} for mass, {change('friction')} for friction, "
        f"{change('com_x')} for c_x, {change('com_y')} for c_y and {change('inertia')} for I_z; "
        f"the product μ·m, which is what a quasi-static push's force measures, "
        f"falls from {prior['mu_m']:.3f} to {p['mu_m']:.3f}.",
    ]
    if n["friction"] >= pn["friction"] or n["mass"] >= 0.8 * pn["mass"]:
        text.append(
            f"{primary} does not separate mass and friction well: our pushes are slow and "
            "constant-speed, so "
            "the force mostly reports μ·m and the split between m and μ is carried by the prior "
            "and by the little dynamic content a 20 mm/s push has; a filter that is honest "
            "about this should keep the m–μ posterior elongated along the μ·m = const curve."
        )
    if n["inertia"] >= 0.8 * pn["inertia"]:
        text.append(
            "I_z barely enters quasi-static motion, so no method should be expected to learn it "
            "from these pushes; an I_z NRMSE near or above the prior's is the physics, not noise."
        )
    text.append(
        f"The CoM is where the motion carries information: c_y {n['com_y']:.3f} and c_x "
        f"{n['com_x']:.3f} against the prior's {pn['com_y']:.3f} and {pn['com_x']:.3f}."
    )
    if forest is not None:
        fn = forest["nrmse"]
        text.append(
            f"The random forest, given ground-truth poses of the same pushes, reaches overall "
            f"{fn['overall']:.3f} (μ·m {forest['mu_m']:.3f}); with the filter's VisNet-driven "
            f"pose track instead, {methods['forest-visnet']['nrmse']['overall']:.3f}."
        )
        if fn["mass"] < 0.7 * n["mass"] and fn["friction"] < 0.7 * n["friction"]:
            text.append(
                f"The forest separates m ({fn['mass']:.3f}) from μ ({fn['friction']:.3f}) on "
                "these catalogue objects although constant pushes carry only μ·m: the twelve "
                "products μ·m of the catalogue grid are all distinct, so a regressor can read "
                "m and μ off the grid value of μ·m."
            )
            if novel is not None and "forest" in novel:
                nf, np_ = novel["forest"]["nrmse"], novel["prior-mean"]["nrmse"]
                text.append(
                    f"On the novel objects (continuous parameters) that trick fails: the "
                    f"forest's μ NRMSE is {nf['friction']:.3f} against the prior's "
                    f"{np_['friction']:.3f}."
                )
        if fn["com_x"] > 0.85 * pn["com_x"]:
            text.append(
                "The forest cannot place the CoM (near the prior for c_x and c_y): that needs "
                "the motion read in the object's frame, which is what the filter does."
            )
    verdict = (
        "within 5 points of nominal"
        if abs(p["coverage90"] - 0.9) <= 0.05
        else "below nominal: the posterior is overconfident"
        if p["coverage90"] < 0.9
        else "above nominal: the intervals are wider than they need be"
    )
    text.append(
        f"Calibration: {100 * p['coverage90']:.0f}% of the true parameters fall inside "
        f"{primary}'s 90% intervals ({100 * p['coverage68']:.0f}% inside the 68% ones), "
        f"{verdict}."
    )
    return " ".join(text)


def render_report(results: dict, command: str, appendices: list[str] = ()) -> str:
    """The whole RESULTS.md text; `appendices`: markdown sections appended verbatim (the real
    data and ablation reports, each generated by its own command)."""
    cfg = results["config"]
    mach = results["machine"]
    primary = results["primary"]
    out = [
        "# Results",
        "",
        "Generated by one command (do not edit by hand):",
        "",
        f"    {command}",
        "",
        f"Machine: {mach['processor']}, {mach['cpus']} CPUs, {mach['platform']}, "
        f"Python {mach['python']}, torch {mach['torch']}. Evaluation seed {cfg['seed']}, "
        f"{cfg['pushes']} pushes per object, {cfg['folds']} folds; training data: "
        + (
            "none given (no forest rows; the prior-mean row is the estimators' prior)."
            if results.get("data") is None
            else f"{results['data']['objects']} objects, {results['data']['pushes']} pushes "
            f"(`{shown_path(results['data']['path'])}`)."
        ),
        "",
        "Models:",
        "",
    ]
    for m in results["models"]:
        info = m["info"]
        t = info.get("timings", {}).get("total_s")
        marker = (info.get("sim_config") or {}).get("orientation_marker", False)
        out.append(
            f"- **{m['name']}** `{shown_path(m['path'])}`: trained with seed {info.get('seed')} on "
            f"{info.get('train_objects')} objects × {info.get('pushes_per_object')} pushes "
            f"(data seed {info.get('data_seed')}, {info.get('objects_from')})"
            + (f", {t / 60:.1f} min" if t else "")
            + f"; {m.get('structure', 'black-box')} model structure, "
            + f"{' and '.join(info.get('profiles') or ['constant'])} pushes"
            + "; testbed images "
            + ("with" if marker else "without")
            + " the orientation marker (it is evaluated on the same)"
        )
    out += [
        "",
        "Protocol (see `pushtoknow.evaluation.suite`): NRMSE = RMSE / catalogue range, mean ± "
        "std over folds of the evaluation objects (each learned model is trained once, on the "
        "objects listed above, none of them an evaluation object, so the spread is over "
        "objects, not training runs); "
        "coverage = share of (object, parameter) pairs inside the method's equal-tailed interval "
        "(the filter's is Gaussian in its normalised, log-space parameters, so asymmetric in SI; "
        "the forest's and the prior's are Gaussian in SI); impossible = estimates (objects × "
        "(pushes + 1)) with m, μ or I_z not positive, the CoM outside the true footprint's convex "
        "hull or I_z above m·max‖p − c‖²; outside interval = estimates whose mean lies outside "
        "their own 90% interval for some parameter (target 0: mean and interval come from one "
        "distribution per parameter, docs/DESIGN.md §2; the forest's and the prior's intervals, "
        "mean ± 1.645·std, hold their mean by construction; – where the run recorded no "
        "intervals).",
        "",
    ]
    for set_name, title in SET_TITLES:
        if set_name not in results["sets"]:
            continue
        s = results["sets"][set_name]
        out += [
            f"## {title} ({len(s['objects'])} objects)",
            "",
            method_table(s["methods"]),
            "",
        ]
        out += [
            upper_bound_note(name, m) for name, m in s["methods"].items() if m.get("upper_bound")
        ]
        if set_name == "novel":
            out += [
                "Novel = unseen shapes (pentagon, trapezoid, 2:1 ellipse, L-shape) alternating "
                "with catalogue shapes, all with continuous parameters within the catalogue "
                "ranges.",
                "",
            ]
        if set_name == "random":
            out += [
                f"Random = random-shape objects (`random:{cfg.get('random_seed')}:I`, "
                "`testbed.random_shapes`), continuous parameters.",
                "",
            ]
        out += [f"*{row}*: {note}.\n" for row, note in s.get("notes", {}).items()]
    out += ["## 90% coverage after the first push and after the last", ""]
    for set_name, title in SET_TITLES:
        if set_name in results["sets"]:
            out += [
                f"**{title}**",
                "",
                coverage_by_push_table(results["sets"][set_name]["methods"]),
                "",
            ]
    out += ["## The paper's numbers (Sim-Robotac, Table III)", "", paper_table(), ""]
    held = results["sets"]["heldout"]["methods"]
    out += ["## NRMSE after k pushes (held-out objects)", ""]
    for param in ("overall", "com_x", "com_y", "mass", "friction", "inertia"):
        out += [f"**{param}**", "", per_push_table(held, param), ""]
    out += ["## Figures", ""]
    for name, path in results["figures"].items():
        out += [f"**{name}**", "", f"![{name}](figures/{Path(path).name})", ""]
    novel = results["sets"].get("novel", {}).get("methods")
    out += ["", "## Interpretation", "", interpretation(held, primary, novel), ""]
    for a in appendices:
        out += [a.strip(), ""]
    return "\n".join(out)


def upper_bound_note(name: str, m: dict) -> str:
    """The line under a table for an upper-bound row (the oracle): its label, its 90% coverage
    per parameter and its compute."""
    cov = ", ".join(f"{k} {v:.2f}" for k, v in m["coverage90_per_param"].items() if k != "overall")
    secs = m.get("seconds_per_object")
    when = f"; {secs:.1f} s per object (median)" if secs else ""
    return f"*{name}*: {m['label']}; 90% coverage per parameter: {cov}{when}.\n"


def identification_markdown(reports: list[dict], commands: list[str]) -> str:
    """Section for `identify-bench` reports (one per profile set): NRMSE and 90% coverage per
    parameter, μ·m relative error, what stays unidentified, compute."""
    keys = ["mass", "friction", "com_x", "com_y", "inertia", "overall"]
    rows = [
        "## Physics-based identification on novel objects (`identify-bench`)",
        "",
        "Upper bound for any estimator on this testbed: `identify` with the exact simulator and "
        "the true footprint, on novel objects (unseen shapes, continuous parameters), pushes "
        "taken in turn from the profiles named. Commands:",
        "",
        *[f"    {c}" for c in commands],
        "",
        "| pushes | objects | " + " | ".join(keys) + " | μ·m rel. error median / max (≤ 2 %) "
        "| cov90 " + " / ".join(keys[:-1]) + " | not identified | poor fits "
        "| s/object median (max) | rollouts/object median |",
        "|" + "---|" * (len(keys) + 8),
    ]
    for r in reports:
        rel = r["mu_m_relative_error"]
        cov = " / ".join(f"{r['coverage90'][k]:.2f}" for k in keys[:-1])
        unid = ", ".join(f"{k} ({v})" for k, v in r["unidentified"].items()) or "none"
        secs = r["seconds_per_object"]
        rows.append(
            f"| {' + '.join(sorted(set(r['profiles'])))} | {r['objects']} | "
            + " | ".join(f"{r['nrmse'][k]:.3f}" for k in keys)
            + f" | {100 * rel['median']:.2f} % / {100 * rel['max']:.2f} % "
            f"({100 * rel['share_within_2pct']:.0f} % within) | {cov} | {unid} | "
            f"{r['poor_fits']} | {secs['median']:.1f} ({secs['max']:.1f}) | "
            f"{r['rollouts_per_object']['median']:.0f} |"
        )
    rows += [
        "",
        "Not identified: the objects whose interval on that parameter kept the prior's width "
        "(signed by the direction in the fit's coordinates). With constant pushes only, m at "
        "fixed μ·m and I_z stay at the prior by construction (docs/DESIGN.md §10, §12). Poor "
        "fits: reduced χ² still above `restart_chi2` after every start and the coarse-to-fine "
        "descent; their noise is raised to the misfit's and m at fixed μ·m and I_z keep the "
        "prior's width (docs/DESIGN.md §12). A rollout replays one candidate φ over all pushes.",
    ]
    return "\n".join(rows)


def efficiency_markdown(
    results: EfficiencyResults, command: str, figure: str = "efficiency.png"
) -> str:
    """The learning-efficiency section from `ablate-efficiency`'s results
    (`run_efficiency`): validation NLL and RMSE (mean ± std over seeds) per collection policy
    versus the number of training pushes."""
    lines = [
        "## Learning efficiency of the collection policies (Fig. 4b)",
        "",
        "Validation loss = NLL of the true parameters after one push from the prior, on fixed "
        "held-out catalogue objects, of a model retrained on all pushes collected so far "
        "(round 0: random affordance pushes shared by every policy). Mean ± std over seeds "
        f"{next(iter(results.policies.values()))[0].seeds}. Command:",
        "",
        f"    {command}",
        "",
        "| policy | training pushes | val NLL | val RMSE (normalised) |",
        "|---|---|---|---|",
    ]
    for policy, rounds in results.policies.items():
        for r in rounds:
            lines.append(
                f"| {policy} | {r.pushes} | {r.mean:.1f} ± {r.std:.1f} | "
                f"{r.rmse_mean:.3f} ± {r.rmse_std:.3f} |"
            )
    lines += ["", f"![learning efficiency](figures/{figure})"]
    return "\n".join(lines)


def heldout_markdown(u: dict, command: str) -> str:
    """Section for one `pushtoknow evaluate-heldout --out` JSON: NRMSE after every push."""
    keys = ["mass", "friction", "com_x", "com_y", "inertia", "overall", "mu_m"]
    p = u["prior_mean"]
    rows = [
        f"## All {u['objects']} held-out objects, {u['policy']} pushes (`evaluate-heldout`)",
        "",
        f"    {command}",
        "",
        "| after push | m | μ | c_x | c_y | I_z | overall | μ·m | cov 90% |",
        "|---" * 9 + "|",
        "| prior mean | " + " | ".join(f"{p[k]:.3f}" for k in keys) + " | |",
    ]
    for r in u["per_push"]:
        cells = " | ".join(f"{r[k]:.3f}" for k in keys)
        rows.append(f"| {r['push']} | {cells} | {r['coverage90']['overall']:.2f} |")
    return "\n".join(rows)
