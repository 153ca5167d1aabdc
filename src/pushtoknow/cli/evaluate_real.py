"""`pushtoknow evaluate-real`: the real-data benchmark, every estimator on every object of a
folder of real pushes (`pushtoknow.evaluation.real_benchmark`, docs/DESIGN.md §11)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from pushtoknow.cli.options import prior_option, prior_ranges, seed_option
from pushtoknow.cli.shared import app, command_line, console, err_console, fail
from pushtoknow.common.errors import PushToKnowError


def _parse_estimators(text: str) -> tuple[str, ...]:
    from pushtoknow.common.estimators import ESTIMATOR_NAMES

    names = tuple(e.strip() for e in text.split(",") if e.strip())
    bad = [e for e in names if e not in ESTIMATOR_NAMES]
    if not names or bad or len(set(names)) != len(names):
        raise typer.BadParameter(
            f"--estimators {text!r}: distinct names among {', '.join(ESTIMATOR_NAMES)}"
        )
    return names


@app.command("evaluate-real")
def evaluate_real_command(
    ctx: typer.Context,
    data_dir: Path = typer.Argument(
        ...,
        help="folder of real pushes, searched recursively: MIT Push files, recordings, datasets",
    ),
    forest_data: Path | None = typer.Option(
        None, "--forest-data", help="simulated dataset (`pushtoknow simulate`) to fit the forest on"
    ),
    model: str = typer.Option(
        "pretrained", "--model", help="RUN directory or 'pretrained' (perception, vt-addf)"
    ),
    seed: int = seed_option(),
    estimators: str = typer.Option(
        "physics,vt-addf", "--estimators", help="comma-separated: physics,vt-addf"
    ),
    max_pushes: int | None = typer.Option(
        None, "--max-pushes", min=1, help="only the first K pushes of each object"
    ),
    trees: int = typer.Option(200, "--trees", min=1, help="random-forest trees"),
    out: Path | None = typer.Option(None, "--out", help="write the report JSON here"),
    prior_mass: str | None = prior_option("mass"),
    prior_friction: str | None = prior_option("friction"),
    prior_inertia: str | None = prior_option("inertia"),
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON"),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the report as a RESULTS.md section here"
    ),
):
    """Run every estimator (physics filter, VT-ADDF, the prior, the forest with --forest-data)
    on every object in DATA_DIR and compare with its known mass, I_z, CoM and the friction
    measured on its pure translations; μ per surface across its objects."""
    from pushtoknow.evaluation.real_benchmark import evaluate_real
    from pushtoknow.identification.prior import EVERYDAY_PRIOR

    names = _parse_estimators(estimators)
    if out is not None and out.is_dir():
        raise typer.BadParameter(f"--out {out}: is a folder, not a file")

    def progress(text: str) -> None:
        err_console.print(f"[dim]{escape(text)}[/]", highlight=False)

    try:
        given = prior_mass or prior_friction or prior_inertia
        prior = (
            prior_ranges(EVERYDAY_PRIOR, prior_mass, prior_friction, prior_inertia)
            if given
            else None
        )
        report = evaluate_real(
            data_dir, forest_data, seed, names, max_pushes, model=model,
            forest_trees=trees, progress=progress,
            prior=prior,
        )  # fmt: skip
    except PushToKnowError as e:
        fail(e)
    data = report.to_json()
    if markdown is not None:
        from pushtoknow.common.files import atomic_write

        try:
            atomic_write(markdown, report.results_section(command_line(ctx)))
        except PushToKnowError as e:
            fail(e)
    if out is not None:
        from pushtoknow.common.files import atomic_write

        try:
            out.parent.mkdir(parents=True, exist_ok=True)
            atomic_write(out, json.dumps(data, indent=1))
        except PushToKnowError as e:  # a full disk
            fail(e)
    if as_json:
        print(json.dumps(data))
        return
    _print(report)
    if out is not None:
        console.print(f"→ {out}")


def _print(report) -> None:
    header, rows = report.table_rows()
    t = Table(
        title=f"{report.data_dir}: {len(report.objects)} objects, seed {report.seed}",
        title_justify="left",
    )
    for i, h in enumerate(header):
        t.add_column(h, justify="left" if i < 2 else "right", no_wrap=i < 2)
    for r in rows:
        t.add_row(*r)
    console.print(t)
    header, rows = report.surface_rows()
    if rows:
        t = Table(title="μ per surface (one surface, one μ)", title_justify="left")
        for i, h in enumerate(header):
            t.add_column(h, justify="left" if i in (0, 1, 4) else "right")
        for r in rows:
            t.add_row(*r)
        console.print(t)
    header, rows = report.mass_rows()
    if rows:
        t = Table(
            title=f"m from force and acceleration (probe's own mass {report.probe_text()}; "
            "not fused)",
            title_justify="left",
        )
        for h in header:
            t.add_column(h, justify="left")
        for r in rows:
            t.add_row(*r)
        console.print(t)
    lines = ["cells: estimate ± std (|z|); * truth outside the 90% interval"]
    for key, o in report.objects.items():
        lines += [f"{key}: skipped {s['file']}: {s['reason']}" for s in o["skipped"]]
        lines += [f"{key}: {m} not run: {why}" for m, why in o["skipped_methods"].items()]
    lines += [f"{e['object']}: every push skipped" for e in report.empty_objects]
    lines += [f"note: {n}" for n in report.notes]
    for line in lines:
        console.print(f"[dim]{escape(line)}[/]", soft_wrap=True)
    console.print(f"[dim]{report.seconds:.0f} s[/]")
