"""`pushtoknow` commands: evaluation (evaluate-heldout, ablate-profiles, evaluate,
ablate-efficiency, ridge)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from pushtoknow.cli.options import (
    SEED_HELP,
    PolicyChoice,
    policy_option,
    ray_option,
    seed_option,
)
from pushtoknow.cli.shared import (
    PROFILES_HELP,
    app,
    command_line,
    console,
    err_console,
    fail,
    parse_profiles,
    save_and_print_json,
)
from pushtoknow.common.errors import PushToKnowError


@app.command("evaluate-heldout")
def evaluate_heldout_cmd(
    ctx: typer.Context,
    model: str = typer.Option("pretrained", "--model"),
    objects: int = typer.Option(
        88, "--objects", min=1, max=88, help="held-out catalogue objects (≤ 88)"
    ),
    pushes: int = typer.Option(5, "--pushes", min=1),
    policy: PolicyChoice = policy_option(),
    seed: int = seed_option(),
    workers: int = typer.Option(2, "--workers", min=1),
    ray: str = ray_option(),
    out: Path = typer.Option(None, "--out", help="write the metrics JSON here"),
    as_json: bool = typer.Option(False, "--json"),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the report section (markdown) here"
    ),
):
    """NRMSE after each of K pushes on held-out catalogue objects (the catalogue's test split),
    with the prior-mean predictor and the coverage of the 68% / 90% intervals."""
    profile_names = None if profiles is None else parse_profiles(profiles)
    policy_name = policy.value
    if out is not None and out.is_dir():
        raise typer.BadParameter(f"--out {out}: is a folder; give the metrics JSON file")
    import numpy as np
    from rich.progress import Progress

    from pushtoknow.common.params import PARAM_NAMES
    from pushtoknow.evaluation.heldout import (
        evaluate_heldout,
        heldout_metrics,
        heldout_object_ids,
    )
    from pushtoknow.pretrained import resolve_model_path

    ids = heldout_object_ids(objects, seed)
    n = len(ids)
    path = resolve_model_path(model)
    if profile_names is None:
        from pushtoknow.models.checkpoint import load_checkpoint

        profile_names = load_checkpoint(path).profiles
    from pushtoknow.common.parallel import make_runner

    with make_runner(workers, ray) as runner, Progress(console=err_console) as bar:
        task = bar.add_task("held-out objects", total=n)
        run = evaluate_heldout(
            path,
            ids,
            pushes,
            policy_name,
            seed,
            runner,
            progress=lambda: bar.advance(task),
            profiles=profile_names,
        )
    result = heldout_metrics(run)
    metrics = result.to_json()
    metrics.update(
        {
            "model": str(path),
            "policy": policy_name,
            "profiles": list(profile_names),
            "pushes": pushes,
            "seed": seed,
            "object_ids": ids,
            "seconds_per_object_median": float(np.median(run.seconds)),
            "per_object": [
                {
                    "id": i,
                    "truth": run.truth[n].tolist(),
                    "mean": run.mean[n, -1].tolist(),
                    "std": run.std[n, -1].tolist(),
                }
                for n, i in enumerate(run.ids)
            ],
        }
    )
    if markdown is not None:
        from pushtoknow.reporting.results import heldout_markdown

        markdown.write_text(heldout_markdown(metrics, command_line(ctx)) + "\n")
    if save_and_print_json(metrics, out, as_json):
        return
    t = Table(title=f"NRMSE on {n} held-out objects ({policy_name}, seed {seed})")
    for c in ["after push", *PARAM_NAMES, "overall", "μ·m", "coverage90"]:
        t.add_column(c, justify="right")
    fmt = lambda r: [f"{r[k]:.3f}" for k in (*PARAM_NAMES, "overall", "mu_m")]  # noqa: E731
    t.add_row("prior mean", *fmt(result.prior_mean), "")
    for r in result.per_push:
        t.add_row(str(r["push"]), *fmt(r), f"{r['coverage90']['overall']:.2f}")
    console.print(t)


@app.command("ablate-profiles")
def ablate_profiles_cmd(
    model: str = typer.Option(..., "--model", help="RUN trained on constant and release pushes"),
    out: Path = typer.Option(..., "--out", help="profiles.json, one JSON per condition"),
    objects: int = typer.Option(44, "--objects", help="held-out catalogue objects (≤ 88)"),
    pushes: int = typer.Option(5, "--pushes", min=1),
    conditions: list[str] = typer.Option(
        None,
        "--condition",
        help="POLICY:PROFILES, repeatable (default: uniform and active-entropy, each with "
        "constant and with constant,release)",
    ),
    reference: str = typer.Option(
        None, "--reference", help="also run this model (e.g. pretrained) uniform, constant"
    ),
    folds: int = typer.Option(4, "--folds", min=2),
    seed: int = seed_option(),
    workers: int = typer.Option(2, "--workers", min=1),
    markdown: Path = typer.Option(None, "--markdown", help="write the RESULTS.md section here"),
):
    """Speed-profile ablation: NRMSE of m, μ, I_z (and the rest) after K pushes
    when the policy may or may not use release pushes, on the same held-out objects."""
    from rich.progress import Progress

    from pushtoknow.common.policy_names import POLICY_NAMES
    from pushtoknow.evaluation.heldout import heldout_object_ids
    from pushtoknow.evaluation.profiles import (
        DEFAULT_CONDITIONS,
        parse_condition,
        profiles_markdown,
        run_profile_ablation,
    )
    from pushtoknow.pretrained import resolve_model_path

    conds = [parse_condition(c) for c in conditions] if conditions else list(DEFAULT_CONDITIONS)
    for policy, profiles in conds:
        if policy not in POLICY_NAMES:
            raise typer.BadParameter(f"--condition policy must be one of {', '.join(POLICY_NAMES)}")
        parse_profiles(",".join(profiles))
    ids = heldout_object_ids(objects, seed)
    with Progress(console=err_console) as bar:

        def progress(name: str, total: int):
            task = bar.add_task(name, total=total)
            return lambda: bar.advance(task)

        report = run_profile_ablation(
            resolve_model_path(model),
            ids,
            out,
            conds,
            pushes,
            seed,
            workers,
            folds,
            progress,
            resolve_model_path(reference) if reference else None,
        )
    command = f"pushtoknow ablate-profiles --model {model} --out {out} --objects {objects}"
    command += f" --seed {seed}" + (f" --reference {reference}" if reference else "")
    text = profiles_markdown(report, command)
    if markdown is not None:
        markdown.write_text(text + "\n")
    console.print(text)


@app.command("evaluate")
def evaluate_cmd(
    ctx: typer.Context,
    data: Path = typer.Option(
        None,
        "--data",
        help="training dataset (forest + prior-mean fit); without it, sets computed here get no "
        "forest rows and the estimators' prior as their prior-mean row",
    ),
    models: list[str] = typer.Option(
        ..., "--models", help="trained runs (RUN dir, model.pt or 'pretrained'); repeat the flag"
    ),
    folds: int = typer.Option(None, "--folds", min=2, help="default: the config's (5)"),
    out: Path = typer.Option(..., "--out", help="report folder: results.json, RESULTS.md, figures"),
    config: Path = typer.Option(None, "--config", help="YAML EvaluationConfig"),
    seed: int = seed_option(None, "default: the config's; " + SEED_HELP),
    workers: int = typer.Option(None, "--workers", min=1),
    ray: str = ray_option(),
    append: list[Path] = typer.Option(
        [], "--append", help="markdown file appended to RESULTS.md (e.g. estimate-real's)"
    ),
    as_json: bool = typer.Option(False, "--json", help="print results.json to stdout"),
    oracle: bool = typer.Option(
        None,
        "--oracle/--no-oracle",
        help="add the 'oracle' row: physics-based identification on the same pushes with the "
        "true footprint and the simulator's own physics, an upper bound (~40 s per object)",
    ),
    physics_policies: str = typer.Option(
        None,
        "--physics-policies",
        help="comma-separated policies the physics estimator is evaluated under (rows "
        "physics:POLICY), 'none' for none; default: the config's (uniform)",
    ),
    physics_sets: str = typer.Option(
        None,
        "--physics-sets",
        help="comma-separated sets (heldout, novel, random) with physics rows; default: every "
        "set (the physics filter takes 1–5 min per object on 2 cores)",
    ),
    random_objects: int = typer.Option(
        None, "--random-objects", min=0, help="random-shape set size (default: the config's, 0)"
    ),
    random_seed: int = typer.Option(
        None, "--random-seed", min=0, help="seed of the random shapes (default: 9001)"
    ),
    keep: Path = typer.Option(
        None,
        "--keep",
        help="a results.json whose rows are kept, not recomputed: only missing sets and rows "
        "are computed (its pushes, seed, folds, object counts and policies must be this run's)",
    ),
):
    """Prior mean, random forest (ground-truth and VisNet poses), each model and push policy and
    the physics estimator on held-out, novel (and random-shape) objects: NRMSE (mean ± std over
    folds), coverage, figures, RESULTS.md. --keep: add missing rows to an earlier results.json."""

    from rich.progress import Progress

    from pushtoknow.evaluation.suite import EvaluationConfig, run_evaluation
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.reporting.results import render_report

    cfg = EvaluationConfig.from_yaml(config) if config else EvaluationConfig()
    overrides = {"folds": folds, "seed": seed, "workers": workers, "oracle": oracle}
    overrides |= {"random_objects": random_objects, "random_seed": random_seed}
    if physics_policies is not None:
        names = [p.strip() for p in physics_policies.split(",") if p.strip()]
        overrides["physics_policies"] = () if names == ["none"] else tuple(names)
    if physics_sets is not None:
        overrides["physics_sets"] = tuple(p.strip() for p in physics_sets.split(",") if p.strip())
    cfg = cfg.model_copy(update={k: v for k, v in overrides.items() if v is not None})
    cfg = EvaluationConfig.model_validate(cfg.model_dump())
    refs = [r for m in models for r in m.split(",") if r]
    paths = [resolve_model_path(r) for r in refs]
    from pushtoknow.models.checkpoint import checkpoint_file

    for ref, path in zip(refs, paths):  # checked first: fail before hours of work
        if not checkpoint_file(path).exists():
            fail(ValueError(f"--models {ref}: no such run folder or checkpoint ({path})"))
    extra = [Path(a).read_text() for a in append]
    from pushtoknow.common.parallel import make_runner

    with make_runner(cfg.workers, ray) as runner, Progress(console=err_console) as bar:

        def progress(desc: str, total: int):
            task = bar.add_task(desc, total=total)
            if err_console.is_terminal:
                return lambda: bar.advance(task)
            done = iter(range(1, total + 1))  # a log (no live bar): one line per object

            def advance():
                bar.advance(task)
                err_console.print(f"{desc}: {next(done, total)}/{total} objects")

            return advance

        results = run_evaluation(
            data,
            paths,
            cfg,
            out,
            progress=progress,
            echo=lambda m: err_console.print(m),
            runner=runner,
            keep=keep,
        )
    command = command_line(ctx)
    full = results.to_json()
    (out / "RESULTS.md").write_text(render_report(full, command, extra))
    if as_json:
        print(json.dumps({k: full[k] for k in ("methods", "primary", "config")}))
        return
    from pushtoknow.reporting.results import COLUMNS

    for set_name, s in results.sets.items():
        t = Table(title=f"NRMSE after {cfg.pushes} pushes, {set_name} ({len(s['objects'])})")
        for c in ["method", *COLUMNS, "μ·m", "cov90"]:
            t.add_column(c, justify="right")
        for name, m in s["methods"].items():
            cells = [f"{m['nrmse'][k]:.3f}±{m['nrmse_std'][k]:.3f}" for k in COLUMNS]
            t.add_row(name, *cells, f"{m['mu_m']:.3f}", f"{m['coverage90']:.2f}")
        console.print(t)
    console.print(f"wrote {out / 'results.json'}, {out / 'RESULTS.md'} and {out / 'figures'}")


@app.command("ablate-efficiency")
def ablate_efficiency(
    ctx: typer.Context,
    config: Path = typer.Option(..., "--config", help="YAML EfficiencyConfig"),
    out: Path = typer.Option(..., "--out", help="ablation folder (resumed if it exists)"),
    seed: int = seed_option(help="base seed (≥ 0): replicates use seed + config seeds"),
    workers: int = typer.Option(None, "--workers", min=1, help="default: the config's"),
    as_json: bool = typer.Option(False, "--json", help="print efficiency.json to stdout"),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the report section (markdown) here"
    ),
):
    """Learning efficiency (paper Fig. 4b): validation loss versus training pushes for data
    collected with each policy, over seeds; writes efficiency.json/.csv/.png."""
    from pushtoknow.collection.efficiency import EfficiencyConfig, figure_series, run_efficiency
    from pushtoknow.reporting.figures import plot_learning_efficiency

    try:
        cfg = EfficiencyConfig.from_yaml(config)
    except OSError as e:
        fail(ValueError(f"{config}: {e.strerror}"))
    except PushToKnowError as e:
        fail(e)
    try:
        results = run_efficiency(
            cfg, out, seed, workers, log=lambda m: err_console.print(f"[dim]efficiency[/] {m}")
        )
    except (PushToKnowError, ValueError) as e:
        fail(e)
    series = figure_series(results, "nll")
    if series:
        plot_learning_efficiency(
            series,
            out / "efficiency.png",
            ylabel="validation parameter NLL",
            title=f"learning efficiency ({len(cfg.seeds)} seeds, mean ± std)",
        )
    if markdown is not None:
        from pushtoknow.reporting.results import efficiency_markdown

        markdown.write_text(efficiency_markdown(results, command_line(ctx)) + "\n")
    if as_json:
        print(json.dumps(results.to_json()))
        return
    t = Table(title="validation loss vs training pushes (mean ± std over seeds)")
    for c in ("policy", "pushes", "param NLL", "param RMSE (norm.)"):
        t.add_column(c, justify="right")
    for p, rounds in results.policies.items():
        for r in rounds:
            t.add_row(
                p,
                str(r.pushes),
                f"{r.mean:.4g} ± {r.std:.2g}",
                f"{r.rmse_mean:.3f} ± {r.rmse_std:.3f}",
            )
    console.print(t)
    console.print(
        f"wrote {out / 'efficiency.json'}, {out / 'efficiency.csv'}, {out / 'efficiency.png'}"
    )


@app.command("ridge")
def ridge_cmd(
    model: str = typer.Option("pretrained", "--model", help="pretrained[:NAME] or a run folder"),
    data: Path = typer.Option(..., "--data", help="recorded pushes (a simulate dataset)"),
    max_objects: int = typer.Option(None, "--max-objects", min=1, help="default: all"),
    as_json: bool = typer.Option(False, "--json", help="print the result as JSON"),
):
    """Where each part of a model places the pushes on the m-against-μ ridge: the one-step
    misfit at (m·e^δ, μ·e^−δ), every other parameter true, split into the free slide, the other
    dynamic steps, the steady steps and the force (docs/DESIGN.md §10). A part whose best δ
    is far from 0 biases m and μ push after push; a part with no rise cannot tell them apart."""
    from pushtoknow.evaluation.ridge import RIDGE_PARTS, ridge_misfit
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.training.push_tensors import load_push_tensors

    try:
        trained = load_checkpoint(resolve_model_path(model)).eval()
        pushes = load_push_tensors(data, max_objects)
    except (PushToKnowError, OSError) as e:
        fail(e)
    r = ridge_misfit(trained, pushes, progress=True)
    kinds = {"release": r.release, "constant": ~r.release}
    rows = [
        {
            "part": part,
            "pushes": kind,
            "count": int(mask.sum()),
            "best_delta": r.best_delta(part, mask),
            "rise_nats": r.rise(part, mask),
        }
        for kind, mask in kinds.items()
        for part in RIDGE_PARTS
    ]
    if as_json:
        print(
            json.dumps(
                {"model": model, "data": str(data), "deltas": r.deltas.tolist(), "parts": rows}
            )
        )
        return
    t = Table(title="m-against-μ ridge: best δ = log(m/m_true) = −log(μ/μ_true)")
    for c in ("pushes", "part", "n", "best δ", "rise (nats)"):
        t.add_column(c, justify="right")
    for row in rows:
        best = "flat" if row["best_delta"] is None else f"{row['best_delta']:+.2f}"
        t.add_row(row["pushes"], row["part"], str(row["count"]), best, f"{row['rise_nats']:.1f}")
    console.print(t)
