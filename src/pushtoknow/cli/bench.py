"""`pushtoknow` commands: benchmarks (bench sim, physics, filter, active)."""

from __future__ import annotations

import json
from pathlib import Path

import typer

from pushtoknow.cli.options import (
    ray_option,
    seed_option,
    sigma_points_option,
)
from pushtoknow.cli.shared import (
    bench_app,
    fail,
    print_result,
)
from pushtoknow.common.errors import PushToKnowError


@bench_app.command("sim")
def bench_sim(
    as_json: bool = typer.Option(False, "--json"),
    pushes: int = typer.Option(6, "--pushes", min=1),
    seed: int = seed_option(),
):
    """Simulator real-time factor (64×64 RGB-D + tactile at 10 Hz, one process)."""
    from pushtoknow.bench.sim import run_sim_bench

    res = run_sim_bench(pushes=pushes, seed=seed)
    print_result(res, as_json, "simulator speed")


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
    from pushtoknow.bench.physics import render_markdown, run_physics_bench

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
    print_result(res, as_json, "filter latency and throughput")


@bench_app.command("active")
def bench_active(
    as_json: bool = typer.Option(False, "--json"),
    seed: int = seed_option(),
    candidates: int = typer.Option(16, "--candidates", min=1),
    sigma_points: int = sigma_points_option(100, "sigma points (≥ 10)"),
):
    """One active push decision: M candidates, N = 50% of the horizon, C sigma points; prints
    decision_s_median per score (kl, entropy)."""
    from pushtoknow.bench.active import run_active_bench

    res = run_active_bench(seed=seed, num_candidates=candidates, num_sigma_points=sigma_points)
    print_result(res, as_json, "active push decision")


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
