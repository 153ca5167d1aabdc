"""`pushtoknow estimate-real`: the learned filter, the random forest and the prior mean on real
(MIT Push) pushes of one object, against its known parameters (`pushtoknow.evaluation.real_object`).

Registered on the main app by `register(app)` (called at the end of `pushtoknow.cli.main`).
"""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from pushtoknow.cli.options import seed_option, sigma_points_option
from pushtoknow.cli.shared import fail
from pushtoknow.common.errors import PushToKnowError

console = Console(emoji=False)


def estimate_real(
    data_dir: Path = typer.Argument(
        ..., help="a `pushtoknow import-mit` output, or a folder of raw MIT Push files"
    ),
    model: str = typer.Option("pretrained", "--model", help="RUN directory or 'pretrained'"),
    forest_data: Path | None = typer.Option(
        None,
        "--forest-data",
        help="simulated dataset (`pushtoknow simulate`) to fit the random forest and the prior "
        "mean on (without it, neither row)",
    ),
    seed: int = seed_option(),
    obj: str | None = typer.Option(
        None, "--object", help="SHAPE or SURFACE:SHAPE when DATA_DIR holds several objects"
    ),
    sigma_points: int | None = sigma_points_option(),
    trees: int = typer.Option(200, "--trees", min=1, help="random-forest trees"),
    rescale: bool = typer.Option(
        True,
        "--rescale/--no-rescale",
        help="raw MIT files: time-rescale each push to the model's training speed "
        "(quasi-static assumption) or convert it as recorded",
    ),
    import_dir: Path | None = typer.Option(
        None, "--import-dir", help="raw MIT files: keep the converted dataset here"
    ),
    identify: bool = typer.Option(
        True,
        "--identify/--no-identify",
        help="also identify the parameters by replaying the recorded pusher tracks in MuJoCo "
        "(after 1…K pushes; ~100 s for the 3 MIT sample pushes on 2 cores)",
    ),
    out: Path | None = typer.Option(None, "--out", help="write the report JSON here"),
    markdown: Path | None = typer.Option(None, "--markdown", help="write the tables here (.md)"),
    as_json: bool = typer.Option(False, "--json", help="print the report as JSON"),
):
    """Estimate a real object's parameters from its recorded pushes (filter after every push,
    random forest, physics-based identification, prior mean) and compare with its known mass,
    I_z, CoM and a friction measured on its pure translations. Raw MIT Push files are
    converted first, time-rescaled to the model's training speed unless --no-rescale."""
    from pushtoknow.evaluation.real_object import estimate_real_object
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.reporting.real_report import error_rows, markdown_table

    try:
        report = estimate_real_object(
            data_dir,
            resolve_model_path(model),
            forest_data,
            seed,
            obj=obj,
            num_sigma_points=sigma_points,
            forest_trees=trees,
            rescale=rescale,
            import_dir=import_dir,
            identify=identify,
        )
    except PushToKnowError as e:
        fail(e)
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(report.to_json(), indent=1))
    if markdown is not None:
        markdown.parent.mkdir(parents=True, exist_ok=True)
        title = f"{report.object} (MIT Push, {len(report.pushes)} pushes), seed {seed}"
        markdown.write_text(markdown_table(report, title))
    if as_json:
        print(json.dumps(report.to_json()))
        return
    _print_report(report, error_rows, model)
    for target in (out, markdown):
        if target is not None:
            console.print(f"→ {target}")


def _print_report(report, error_rows, model_ref: str) -> None:
    from pushtoknow.reporting.real_report import table_rows

    header, rows = table_rows(report)
    t = Table(
        title=f"{report.object}: {len(report.pushes)} real pushes, model {model_ref}",
        title_justify="left",
    )
    for i, h in enumerate(header):
        t.add_column(h, justify="left" if i == 0 else "right", no_wrap=i == 0)
    for r in rows:
        t.add_row(*r)
    console.print(t)
    header, rows = error_rows(report)
    t = Table(title="|estimate − truth| / catalogue range", title_justify="left")
    for i, h in enumerate(header):  # parameter names in full, even in a narrow terminal
        t.add_column(h, justify="left" if i == 0 else "right", no_wrap=i == 0, min_width=len(h))
    for r in rows:
        t.add_row(*r)
    console.print(t)
    for k, p in enumerate(report.pushes):
        console.print(
            f"push {k + 1}: {p['samples']} samples at {p['speed_m_per_s']} m/s (time scale "
            f"{p['time_scale']:g}), moved {p['displacement_m'] * 100:.1f} cm, turned "
            f"{p['rotation_deg']:+.1f}°" + (" (pure translation)" if p["pure_translation"] else "")
        )
    ident = report.identify
    if ident is not None:
        last = ident.per_push[-1]
        console.print(
            f"identify: {ident.model}; replayed at {ident.rate_hz:g} Hz; not identified "
            f"(prior width kept): {', '.join(last['unidentified']) or 'none'}"
        )
        for n in ident.notes:
            console.print(f"[dim]identify note:[/] {n}")
    for n in report.notes:
        console.print(f"[dim]note:[/] {n}")
    console.print(f"[dim]{report.seconds:.1f} s[/]")


def register(app: typer.Typer) -> None:
    """Add `estimate-real` to the `pushtoknow` app."""
    app.command("estimate-real")(estimate_real)
