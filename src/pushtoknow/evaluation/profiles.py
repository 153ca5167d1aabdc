"""Speed-profile ablation (docs/DESIGN.md §10): do dynamic pushes separate m from μ?

Constant 20 mm/s pushes are quasi-static: the force reveals μ·m only. A *release* push
accelerates the object (F − μ·m·g = m·a) and lets it slide free (deceleration μ·g, whatever
m), so it carries the dynamic content that could split the product. One model trained on
pushes of both profiles runs on the same held-out objects under each condition (policy ×
profiles the policy may use); the table gives the NRMSE of every parameter after K pushes,
mean ± std over folds of the objects, and the share of release pushes executed.

`pushtoknow ablate-profiles` runs it; each condition is saved to OUT/<condition>.json when done
(atomically) and skipped on a rerun with the same settings.
"""

from __future__ import annotations

import json
import os
from collections.abc import Callable, Sequence
from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np

from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.evaluation.heldout import HeldoutRun, evaluate_heldout
from pushtoknow.evaluation.metrics import coverage, nrmse, product_nrmse
from pushtoknow.evaluation.suite import fold_indices

Condition = tuple[str, tuple[str, ...]]
"""(policy, speed profiles the policy may use)."""

DEFAULT_CONDITIONS: tuple[Condition, ...] = (
    ("uniform", ("constant",)),
    ("uniform", ("constant", "release")),
    ("active-entropy", ("constant",)),
    ("active-entropy", ("constant", "release")),
)


def condition_name(condition: Condition) -> str:
    policy, profiles = condition
    return f"{policy}+{'+'.join(profiles)}"


def parse_condition(text: str) -> Condition:
    """'active-entropy:constant,release' → ("active-entropy", ("constant", "release"))."""
    policy, _, profiles = text.partition(":")
    names = tuple(p.strip() for p in (profiles or "constant").split(",") if p.strip())
    return policy.strip(), names


@dataclass(frozen=True)
class ConditionSummary:
    """One condition's result (`summarise_condition`), after the last push: NRMSE per
    parameter and "overall" (the mean of the five) as {"mean", "std"} over the folds of the
    objects and "all" (over every object) (`nrmse`); the NRMSE of μ·m (`mu_m`); the 90%
    coverage over all parameters (`coverage90`); the share of executed pushes that were
    release pushes (`release_share`); the median wall time per object (s); the prior mean's
    NRMSE per parameter and "overall" (`prior_nrmse`). `to_json()` is what OUT/<condition>.json
    and profiles.json hold."""

    nrmse: dict[str, dict[str, float]]
    mu_m: float
    coverage90: float
    release_share: float
    seconds_per_object_median: float
    prior_nrmse: dict[str, float]

    def to_json(self) -> dict:
        return asdict(self)


def summarise_condition(run: HeldoutRun, folds: Sequence[np.ndarray]) -> ConditionSummary:
    """The `ConditionSummary` of `run`, with NRMSE mean ± std over `folds` (index arrays into
    the run's objects)."""
    k = run.mean.shape[1] - 1
    mean, truth = run.mean[:, k], run.truth
    per_fold = [nrmse(mean[f], truth[f]) for f in folds]
    keys = [*PARAM_NAMES, "overall"]
    profiles = [p for obj in (run.profiles or []) for p in obj]
    return ConditionSummary(
        nrmse={
            key: {
                "mean": float(np.mean([r[key] for r in per_fold])),
                "std": float(np.std([r[key] for r in per_fold])),
                "all": nrmse(mean, truth)[key],
            }
            for key in keys
        },
        mu_m=product_nrmse(mean, truth, run.product[:, k]),
        coverage90=coverage(run.zscore[:, k], 0.9)["overall"],
        release_share=float(np.mean([p == "release" for p in profiles])) if profiles else 0.0,
        seconds_per_object_median=float(np.median(run.seconds)),
        prior_nrmse=nrmse(run.mean[:, 0], truth),
    )


def run_profile_ablation(
    model_path: Path,
    objects: list[str],
    out: Path,
    conditions: Sequence[Condition] = DEFAULT_CONDITIONS,
    pushes: int = 5,
    seed: int = 0,
    workers: int = 1,
    folds: int = 4,
    progress: Callable[[str, int], Callable[[], None]] | None = None,
    reference: Path | None = None,
) -> dict:
    """Every condition on `objects`; returns {condition name: summary} and writes
    OUT/profiles.json. `reference`: another model (e.g. the shipped constant-speed one) run
    with uniform constant pushes on the same objects, kept under "reference".
    progress(name, total) → a per-object callback."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    fold_groups = fold_indices(len(objects), folds, seed)
    settings = {"model": str(model_path), "objects": objects, "pushes": pushes, "seed": seed}
    results, references = {}, {}
    jobs = [(model_path, c, results, condition_name(c)) for c in conditions]
    if reference is not None:
        jobs.append((reference, ("uniform", ("constant",)), references, "reference"))
    for model, cond, into, name in jobs:
        path = out / f"{name}.json"
        run_settings = {**settings, "model": str(model)}
        if path.exists():
            saved = json.loads(path.read_text())
            if saved.get("settings") == run_settings:
                into[name] = saved["summary"]
                continue
        policy, profiles = cond
        run = evaluate_heldout(
            model,
            objects,
            pushes,
            policy,
            seed,
            workers,
            progress=progress(name, len(objects)) if progress else None,
            profiles=profiles,
        )
        summary = summarise_condition(run, fold_groups).to_json()
        tmp = path.with_suffix(".json.tmp")
        tmp.write_text(json.dumps({"settings": run_settings, "summary": summary}, indent=1))
        os.replace(tmp, path)
        into[name] = summary
    report = {
        "settings": settings,
        "folds": folds,
        "conditions": results,
        "reference": {"model": str(reference), **references} if reference else None,
    }
    (out / "profiles.json").write_text(json.dumps(report, indent=1))
    return report


def profiles_markdown(report: dict, command: str) -> str:
    """RESULTS.md section from profiles.json (with the reference model's row, if run)."""
    conds = report["conditions"]
    n = len(report["settings"]["objects"])
    first = next(iter(conds.values()))
    prior = first["prior_nrmse"]
    lines = [
        "## Speed profiles: do dynamic pushes separate m from μ?",
        "",
        f"One VT-ADDF trained on pushes of both profiles (constant 20 mm/s; release: 0.5 m/s² "
        f"to 0.4 m/s, then the pad stops and the object slides free), {n} held-out catalogue "
        f"objects, {report['settings']['pushes']} pushes, seed {report['settings']['seed']}. "
        f"NRMSE after the last push, mean ± std over {report['folds']} folds of the objects. "
        "Command:",
        "",
        f"    {command}",
        "",
        "| policy | profiles | m | μ | c_x | c_y | I_z | overall | μ·m | cov 90% | release share |",
        "|---" * 11 + "|",
        "| prior mean | | "
        + " | ".join(f"{prior[k]:.3f}" for k in [*PARAM_NAMES, "overall"])
        + " | | | |",
    ]

    def row(label: str, s: dict) -> str:
        cells = " | ".join(
            f"{s['nrmse'][k]['mean']:.3f} ± {s['nrmse'][k]['std']:.3f}"
            for k in [*PARAM_NAMES, "overall"]
        )
        return (
            f"| {label} | {cells} | {s['mu_m']:.3f} | {s['coverage90']:.2f} | "
            f"{s['release_share']:.2f} |"
        )

    for name, s in conds.items():
        policy, _, profiles = name.partition("+")
        lines.append(row(f"{policy} | {profiles.replace('+', ', ')}", s))
    ref = report.get("reference")
    if ref and "reference" in ref:
        lines.append(row(f"reference model: uniform | constant ({ref['model']})", ref["reference"]))
    return "\n".join(lines)
