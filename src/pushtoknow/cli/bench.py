"""`pushtoknow` commands: benchmarks (bench sim, physics, filter, active, scaling, estimator,
sysid)."""

from __future__ import annotations

import json
import statistics
from pathlib import Path

import typer

from pushtoknow.cli.options import (
    EstimatorChoice,
    PolicyChoice,
    estimator_option,
    policy_option,
    ray_option,
    seed_option,
    sigma_points_option,
)
from pushtoknow.cli.shared import (
    PROFILES_HELP,
    bench_app,
    console,
    err_console,
    fail,
    parse_profiles,
    print_result,
    save_and_print_json,
)
from pushtoknow.common.errors import PushToKnowError


@bench_app.command("sim")
def bench_sim(
    as_json: bool = typer.Option(False, "--json"),
    pushes: int = typer.Option(6, "--pushes", min=1),
    seed: int = seed_option(),
):
    """Simulator real-time factor (64×64 RGB-D + tactile at 10 Hz, one process)."""
    from pushtoknow.bench.throughput import run_sim_bench

    res = run_sim_bench(pushes=pushes, seed=seed)
    print_result(res.to_json(), as_json, "simulator speed")


@bench_app.command("physics")
def bench_physics(
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON"),
    quick: bool = typer.Option(False, "--quick", help="one shape, grid corners only"),
    save: Path | None = typer.Option(None, "--save", help="write the report's JSON here"),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the fidelity table (markdown) here"
    ),
    before: Path | None = typer.Option(
        None, "--before", help="JSON report of an earlier testbed version, shown beside"
    ),
    seed: int = seed_option(),
):
    """Physics fidelity of the testbed: chaos, quasi-static pushing, Coulomb release, what
    the 10 Hz record reveals, simulation speed (docs/PHYSICS.md)."""
    from pushtoknow.bench.physics_fidelity import render_markdown, run_physics_bench

    earlier = None
    if before is not None:
        try:
            earlier = json.loads(before.read_text())
        except (OSError, json.JSONDecodeError) as e:
            fail(ValueError(f"--before {before}: {e}"))
    report = run_physics_bench(seed=seed, quick=quick).to_dict()
    if save is not None:
        save.write_text(json.dumps(report, indent=1) + "\n")
    table = render_markdown(report, earlier)
    if markdown is not None:
        markdown.write_text(table)
    if as_json:
        print(json.dumps(report))
    else:
        print(table)


@bench_app.command("filter")
def bench_filter(as_json: bool = typer.Option(False, "--json"), seed: int = seed_option()):
    """Filter step latency (C = 100) and batched throughput (32 objects)."""
    from pushtoknow.bench.filter import run_filter_bench

    res = run_filter_bench(seed=seed)
    print_result(res.to_json(), as_json, "filter latency and throughput")


@bench_app.command("active")
def bench_active(
    as_json: bool = typer.Option(False, "--json"),
    seed: int = seed_option(),
    candidates: int = typer.Option(16, "--candidates", min=1),
    sigma_points: int = sigma_points_option(100, "default 100"),
):
    """One active push decision: M candidates, N = 50% of the horizon, C sigma points; prints
    decision_s_median per score (kl, entropy)."""
    from pushtoknow.bench.active import run_active_bench

    res = run_active_bench(seed=seed, num_candidates=candidates, num_sigma_points=sigma_points)
    print_result(res.to_json(), as_json, "active push decision")


@bench_app.command("scaling")
def bench_scaling(
    objects: int = typer.Option(8, "--objects", min=1),
    pushes: int = typer.Option(2, "--pushes", min=1),
    workers: int = typer.Option(2, "--workers", min=2, help="compared with 1 worker"),
    objects_per_shard: int = typer.Option(4, "--objects-per-shard", min=1),
    ray: str = ray_option(),
    seed: int = seed_option(),
    as_json: bool = typer.Option(False, "--json"),
    markdown: Path | None = typer.Option(None, "--markdown", help="write the table here"),
):
    """Throughput of `simulate` on 1 and --workers workers, on the local process pool and (with
    --ray) on Ray, and whether every run wrote the same arrays."""
    from pushtoknow.bench.scaling import run_scaling_bench, scaling_markdown

    try:
        report = run_scaling_bench(objects, pushes, workers, seed, objects_per_shard, ray)
    except (PushToKnowError, ValueError) as e:
        fail(e)
    table = scaling_markdown(report)
    if markdown is not None:
        markdown.write_text(table)
    if as_json:
        print(json.dumps(report.to_dict()))
    else:
        print(table)


@bench_app.command("estimator")
def bench_estimator_cmd(
    estimator: EstimatorChoice = estimator_option(),
    objects: int = typer.Option(
        4, "--objects", min=1, help="random objects random:SEED:0 … random:SEED:N-1"
    ),
    objects_seed: int = typer.Option(
        2026, "--objects-seed", min=0, help="SEED of the random objects"
    ),
    object_refs: list[str] = typer.Option(
        [],
        "--object",
        metavar="REF",
        help="an object reference (catalogue:ID, random:SEED:I, a file); repeat for more; "
        "replaces the random objects",
    ),
    pushes: int = typer.Option(5, "--pushes", min=1),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
    policy: PolicyChoice = policy_option(),
    model: str = typer.Option("pretrained", "--model", help="RUN directory or 'pretrained'"),
    threads: int | None = typer.Option(
        None,
        "--threads",
        min=1,
        help="torch intra-op threads (default: torch's, one per core); on a machine shared "
        "with other work, 1 avoids spin-waiting workers",
    ),
    seed: int = seed_option(),
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON"),
    out: Path | None = typer.Option(None, "--out", help="write the report's JSON here"),
):
    """An estimator's speed (seconds per update, per object) and accuracy (normalised error,
    90% coverage, means outside their own interval) on simulated objects."""
    from pushtoknow.bench.estimator_accuracy import bench_estimator, default_objects
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path

    if out is not None and out.is_dir():
        raise typer.BadParameter(f"--out {out}: is a folder, not a file")
    chosen = parse_profiles(profiles) if profiles is not None else None
    refs = list(object_refs) or default_objects(objects, objects_seed)
    try:
        trained = load_checkpoint(resolve_model_path(model))
    except (PushToKnowError, OSError) as e:
        fail(e)
    n = len(refs)

    def progress(i, row) -> None:
        err_console.print(
            f"object {i + 1}/{n} {row.name or row.ref}: {len(row.update_s)} updates, "
            f"median {statistics.median(row.update_s):.2f} s, object {row.object_s:.1f} s, "
            f"{sum(row.replays)} replays",
            highlight=False,
        )

    err_console.print(
        f"bench estimator {estimator.value}: {n} objects, {pushes} pushes, "
        f"policy {policy.value}, seed {seed}",
        highlight=False,
    )
    try:
        report = bench_estimator(
            trained,
            estimator.value,
            refs,
            pushes,
            chosen or trained.profiles,
            policy.value,
            seed,
            on_object=progress,
            threads=threads,
        )
    except PushToKnowError as e:
        fail(e)
    if not save_and_print_json(report.to_json(), out, as_json):
        _print_estimator_bench(report)


def _print_accuracy_summary(summary) -> None:
    """The summary table of an accuracy bench: mean |error| / catalogue range and 90% coverage
    per parameter, and the overall error."""
    from rich.table import Table

    from pushtoknow.common.params import PARAM_NAMES

    accuracy = Table(title="summary: accuracy", title_justify="left")
    accuracy.add_column("parameter")
    accuracy.add_column("mean |err|/range", justify="right")
    accuracy.add_column("90% coverage", justify="right")
    for p in PARAM_NAMES:
        row = (f"{summary.error_norm_mean[p]:.3f}", f"{summary.coverage90[p]:.2f}")
        accuracy.add_row(p, *row)
    accuracy.add_row("overall", f"{summary.error_norm_overall:.3f}", "")
    console.print(accuracy)


def _print_estimator_bench(report) -> None:
    from rich.table import Table

    from pushtoknow.common.params import PARAM_NAMES

    s = report.summary
    per_object = Table(
        title=f"{report.estimator}: per object, final estimate after {report.pushes} pushes "
        "(per parameter: |error| / catalogue range, and the truth's z-score)",
        title_justify="left",
    )
    per_object.add_column("object", no_wrap=True)
    per_object.add_column("update s (median)", justify="right")
    per_object.add_column("object s", justify="right")
    for p in PARAM_NAMES:
        per_object.add_column(p, justify="right", no_wrap=True)
    per_object.add_column("means outside interval", justify="right")
    for r in report.objects:
        per_object.add_row(
            r.name or r.ref,
            f"{statistics.median(r.update_s):.3g}",
            f"{r.object_s:.3g}",
            *(f"{r.error_norm[p]:.3f} ({r.zscore[p]:+.1f})" for p in PARAM_NAMES),
            str(sum(not v for v in r.mean_inside_interval.values())),
        )
    console.print(per_object)
    _print_accuracy_summary(s)
    print_result(
        {
            "update_s_median": s.update_s_median,
            "update_s_max": s.update_s_max,
            "object_s_median": s.object_s_median,
            "replays_median": s.replays_median,
            "replays_object_median": s.replays_object_median,
            "updates": s.updates,
            "means_outside_interval": s.means_outside_interval,
            "cpu_count": report.cpu_count,
            "torch_threads": report.torch_threads,
            "machine": report.machine,
        },
        False,
        "summary: speed",
    )


@bench_app.command("sysid")
def bench_sysid_cmd(
    objects: int = typer.Option(
        4, "--objects", min=1, help="random objects random:SEED:0 … random:SEED:N-1"
    ),
    objects_seed: int = typer.Option(
        2026, "--objects-seed", min=0, help="SEED of the random objects"
    ),
    object_refs: list[str] = typer.Option(
        [],
        "--object",
        metavar="REF",
        help="an object reference (catalogue:ID, random:SEED:I, a file); repeat for more; "
        "replaces the random objects",
    ),
    pushes: int = typer.Option(5, "--pushes", min=1),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
    model: str = typer.Option(
        "pretrained",
        "--model",
        help="RUN directory or 'pretrained': its testbed settings, camera and VisNet choose "
        "the pushes, as bench estimator's",
    ),
    max_iterations: int = typer.Option(
        30, "--max-iterations", min=1, help="sysid's Levenberg-Marquardt iterations per object"
    ),
    fd_step: float | None = typer.Option(
        None,
        "--fd-step",
        min=1e-9,
        help="sysid's finite-difference step, normalised units (default 0.01)",
    ),
    threads: int | None = typer.Option(
        None, "--threads", min=1, help="rollout and torch threads (default: one per core)"
    ),
    seed: int = seed_option(),
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON"),
    out: Path | None = typer.Option(None, "--out", help="write the report's JSON here"),
):
    """mujoco.sysid as a baseline: the pushes bench estimator runs with the physics estimator
    and the uniform policy, fitted by MuJoCo's own system identification given the true outline
    (the known-scene case): accuracy, 90% coverage, seconds and rollouts per object."""
    from pushtoknow.bench.estimator_accuracy import default_objects
    from pushtoknow.bench.sysid import bench_sysid
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path

    if out is not None and out.is_dir():
        raise typer.BadParameter(f"--out {out}: is a folder, not a file")
    chosen = parse_profiles(profiles) if profiles is not None else None
    refs = list(object_refs) or default_objects(objects, objects_seed)
    try:
        trained = load_checkpoint(resolve_model_path(model))
    except (PushToKnowError, OSError) as e:
        fail(e)
    n = len(refs)

    def progress(i, row) -> None:
        err_console.print(
            f"object {i + 1}/{n} {row.name or row.ref}: fit {row.fit_s:.1f} s, "
            f"{row.evaluations} evaluations, object {row.object_s:.1f} s",
            highlight=False,
        )

    err_console.print(
        f"bench sysid: {n} objects, {pushes} pushes, seed {seed}, known outline",
        highlight=False,
    )
    try:
        report = bench_sysid(
            trained,
            refs,
            pushes,
            chosen or trained.profiles,
            seed,
            max_iterations=max_iterations,
            threads=threads,
            fd_step=fd_step,
            on_object=progress,
        )
    except PushToKnowError as e:
        fail(e)
    if not save_and_print_json(report.to_json(), out, as_json):
        _print_sysid_bench(report)


def _print_sysid_bench(report) -> None:
    from rich.table import Table

    from pushtoknow.common.params import PARAM_NAMES

    s = report.summary
    per_object = Table(
        title=f"mujoco.sysid after {report.pushes} pushes, {report.scene} "
        "(per parameter: |error| / catalogue range, and the truth's z-score)",
        title_justify="left",
    )
    per_object.add_column("object", no_wrap=True)
    per_object.add_column("fit s", justify="right")
    per_object.add_column("evaluations", justify="right")
    for p in PARAM_NAMES:
        per_object.add_column(p, justify="right", no_wrap=True)
    per_object.add_column("μ·m error", justify="right")
    for r in report.objects:
        per_object.add_row(
            r.name or r.ref,
            f"{r.fit_s:.3g}",
            str(r.evaluations),
            *(
                f"{r.error_norm[p]:.3f} ({r.zscore[p]:+.1f})"
                if r.interval_bounded[p]
                else f"{r.error_norm[p]:.3f} (unbounded)"
                for p in PARAM_NAMES
            ),
            f"{100 * r.mu_m_rel_error:+.1f}%",
        )
    console.print(per_object)
    _print_accuracy_summary(s)
    print_result(
        {
            "fit_s_median": s.fit_s_median,
            "object_s_median": s.object_s_median,
            "evaluations_median": s.evaluations_median,
            "mu_m_rel_error_mean_abs": s.mu_m_rel_error_mean_abs,
            "unbounded_intervals": s.unbounded_intervals,
            "threads": report.threads,
            "machine": report.machine,
        },
        False,
        "summary: speed",
    )
