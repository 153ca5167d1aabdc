"""`pushtoknow` commands: models (push, train, infer, demo)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.console import Console
from rich.table import Table

from pushtoknow.cli.options import (
    EstimatorChoice,
    PolicyChoice,
    checked_export,
    estimator_option,
    export_option,
    policy_option,
    pushes_option,
    seed_option,
    sigma_points_option,
)
from pushtoknow.cli.shared import (
    PROFILES_HELP,
    ProfileName,
    app,
    console,
    err_console,
    fail,
    image_out,
    out_folder,
    parse_profiles,
)
from pushtoknow.common.errors import PushToKnowError
from pushtoknow.common.estimators import DEFAULT_ESTIMATOR


@app.command("push")
def push_cmd(
    obj: str = typer.Option("catalogue:0", "--object", help="catalogue:ID or a JSON/YAML spec"),
    profile: ProfileName = typer.Option(ProfileName.constant, "--profile", help="speed profile"),
    seed: int = seed_option(),
    out: Path = typer.Option(Path("push.png"), "--out", help="frame strip + force plot PNG"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Simulate one push on an object, print its summary and save a strip of frames."""
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.viz import one_push, save_push_strip

    out = image_out(out)
    try:
        spec = load_object_spec(obj)
        rec, camera = one_push(spec, profile.value, seed)
    except PushToKnowError as e:
        fail(e)
    save_push_strip(rec, camera, out, title=f"{spec.name} ({profile.value})")
    summary = _push_summary(spec, rec)
    if as_json:
        print(json.dumps(summary))
        return
    _print_push_summary(spec, summary)
    console.print(f"frame strip → {out}")


def _push_summary(spec, rec) -> dict:
    import numpy as np

    from pushtoknow.common.params import GRAVITY

    f = np.linalg.norm(rec.force_clean, axis=1)
    touching = rec.tactile[:, 2] > 0
    d = rec.pose[-1] - rec.pose[0]
    return {
        "object": spec.to_dict(),
        "push": {
            "contact": list(rec.push.contact),
            "direction": rec.push.direction,
            "profile": rec.push.profile,
            "speed": rec.push.speed,
        },
        "displacement_m": float(np.hypot(d[0], d[1])),
        "rotation_deg": float(np.degrees(d[2])),
        "mean_force_in_contact_N": float(f[touching].mean()) if touching.any() else 0.0,
        "mu_m_g_N": spec.params.friction * spec.params.mass * GRAVITY,
        "samples": len(rec.time),
    }


def _print_push_summary(spec, s: dict) -> None:
    t = Table(title=f"one push on {spec.name}")
    t.add_column("quantity")
    t.add_column("value", justify="right")
    p = spec.params
    t.add_row("mass / friction", f"{p.mass:.3f} kg / {p.friction:.2f}")
    t.add_row("CoM (x, y)", f"({p.com_x * 1e3:+.1f}, {p.com_y * 1e3:+.1f}) mm")
    t.add_row("inertia", f"{p.inertia * 1e3:.2f} g·m²")
    t.add_row("profile", s["push"]["profile"])
    t.add_row("displacement", f"{s['displacement_m'] * 100:.1f} cm")
    t.add_row("rotation", f"{s['rotation_deg']:+.1f}°")
    t.add_row("mean ‖F‖ in contact", f"{s['mean_force_in_contact_N']:.2f} N")
    t.add_row("μ·m·g", f"{s['mu_m_g_N']:.2f} N")
    console.print(t)


@app.command()
def train(
    data: Path = typer.Option(..., "--data", help="dataset directory (`pushtoknow simulate`)"),
    out: Path = typer.Option(..., "--out", help="run directory to write"),
    variant: str = typer.Option("vt-addf", "--variant", help="vt-addf | vt-jdf | v-ddf"),
    config: Path = typer.Option(None, "--config", help="YAML TrainConfig"),
    seed: int = seed_option(),
    visnet_from: Path = typer.Option(
        None, "--visnet-from", help="reuse the VisNet of this run instead of training one"
    ),
):
    """Train VisNet, then the filter's networks (supervised, then end to end), calibrate the
    inference settings, and write RUN/model.pt with configs, curves and training.json."""
    from pushtoknow.training.pipeline import TrainConfig, train_model

    if variant not in ("vt-addf", "vt-jdf", "v-ddf"):
        fail(ValueError(f"--variant must be vt-addf, vt-jdf or v-ddf, got {variant!r}"))
    cfg = TrainConfig.from_yaml(config) if config else TrainConfig()
    cfg = cfg.model_copy(update={"variant": variant})

    def echo(stage: str, row: dict) -> None:
        keys = [k for k in row if k.startswith("val_") or k in ("epoch", "step", "train_loss")]
        brief = ", ".join(
            f"{k}={row[k]:.4g}" if isinstance(row[k], float) else f"{k}={row[k]}" for k in keys[:7]
        )
        err_console.print(f"[dim]{stage}[/] {brief}")

    model = train_model(data, out, cfg, seed, visnet_from=visnet_from, echo=echo)
    console.print(
        f"wrote {out / 'model.pt'} ({model.info['timings']['total_s']:.0f} s); "
        f"inference settings: {model.inference.model_dump()}"
    )


def _estimate_table(estimate, truth, title: str) -> Table:
    from pushtoknow.common.params import PARAM_NAMES
    from pushtoknow.reporting.units import DISPLAY_UNITS, format_estimate

    t = Table(title=title, title_justify="left")
    t.add_column("parameter")
    t.add_column("estimate (mean ± std)", justify="right")
    t.add_column("90% interval", justify="right")
    if truth is not None:
        t.add_column("truth", justify="right")
        t.add_column("|z| (>1.64: outside)", justify="right")
        zscores = abs(estimate.zscore(truth))
    lo, hi = estimate.interval(0.9)
    for j, name in enumerate(PARAM_NAMES):
        scale, unit = DISPLAY_UNITS[name]
        row = [
            name,
            format_estimate(estimate.mean[j], estimate.std[j], name),
            f"{lo[j] * scale:.3g} – {hi[j] * scale:.3g}",
        ]
        if truth is not None:
            row += [f"{truth[j] * scale:.3g} {unit}".strip(), f"{zscores[j]:.1f}"]
        t.add_row(*row)
    return t


def run_inference(
    model_ref: str,
    object_ref: str,
    pushes: int,
    policy: str,
    seed: int,
    out: Path | None,
    as_json: bool,
    strip: bool = False,
    sigma_points: int | None = None,
    profiles: tuple[str, ...] | None = None,
    estimator: str = DEFAULT_ESTIMATOR,
    export: tuple[str, Path] | None = None,
    overwrite: bool = False,
) -> dict:
    """Shared by `infer` and `demo`: K pushes on the testbed, tables, plot, JSON; the estimated
    object written for a simulator when `export` (kind, path) (`checked_export`) is given.
    profiles: None for those the model was trained on. The run's files are written as a set
    (`atomic_write_set`) into `out`, refused when it holds another object's run unless
    `overwrite` (`check_run_dir`)."""
    from pushtoknow.api import export_object
    from pushtoknow.common.files import atomic_write_set
    from pushtoknow.datasets import shards
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.viz import plot_estimates, save_push_strip

    out_folder(out)
    model = load_checkpoint(resolve_model_path(model_ref))
    spec = load_object_spec(object_ref)
    if out is not None:
        shards.check_run_dir(out, spec, overwrite)
    truth = spec.params.as_array()
    show = Console(stderr=True, emoji=False) if as_json else console
    sim_cfg = model.sim_config
    cfg = InferenceConfig(
        pushes=pushes,
        policy=policy,
        num_sigma_points=sigma_points,
        profiles=model.profiles if profiles is None else profiles,
        estimator=estimator,
    )
    show.print(
        f"[bold]{spec.name or 'object'}[/] ({spec.shape if isinstance(spec.shape, str) else ''})"
        f", estimator {estimator}, model {model.variant} ({model_ref}), policy {policy}, "
        f"{pushes} pushes, seed {seed}"
    )
    result = infer_simulated(
        model,
        spec,
        cfg,
        seed,
        on_push=lambda e: show.print(_estimate_table(e, truth, f"after push {e.index}")),
    )
    report = result.to_json()
    if out is not None:  # every file to a temporary name first, then all renamed into place
        (out / shards.RUN_PUSHES).mkdir(parents=True, exist_ok=True)
        pushes_file, strip_file = shards.run_pushes_path(out), out / "push-1.png"
        files = {
            out / "estimates.png": lambda tmp: plot_estimates(
                result, tmp, title=f"{spec.name} · {model.variant}"
            ),
            out / shards.RUN_ESTIMATES: json.dumps(report, indent=1),
            pushes_file: lambda tmp: shards.write_run_pushes(
                out, spec, result.records, sim_cfg.model_dump_json(), path=tmp
            ),
        }
        if strip:
            files[strip_file] = lambda tmp: save_push_strip(
                result.records[0], model.camera, tmp, title=f"{spec.name}, push 1", fmt="png"
            )
        atomic_write_set(files)
        if not strip:
            strip_file.unlink(missing_ok=True)  # an earlier run's: not of these pushes
        show.print(f"estimates plot → {out / 'estimates.png'}")
        show.print(f"executed pushes → {pushes_file} (`pushtoknow identify --pushes {out}`)")
        if strip:
            show.print(f"frame strip → {strip_file}")
    if export is not None:
        written = export_object(result, *export)
        show.print(f"estimated object ({export[0]}) → {', '.join(map(str, written))}")
    if as_json:
        print(json.dumps(report))
    return report


@app.command()
def infer(
    model: str = typer.Option("pretrained", "--model", help="RUN directory or 'pretrained'"),
    obj: str = typer.Option(..., "--object", help="catalogue:ID, a JSON/YAML file or JSON"),
    pushes: int = pushes_option(5, "pushes"),
    policy: PolicyChoice = policy_option(),
    seed: int = seed_option(),
    out: Path = typer.Option(Path("infer-out"), "--out", help="where the plot and JSON go"),
    as_json: bool = typer.Option(False, "--json", help="print the estimates as JSON"),
    sigma_points: int = sigma_points_option(help="default: the model's (100)"),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
    estimator: EstimatorChoice = estimator_option(),
    export: tuple[str, Path] | None = export_option(),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="replace a run of another object in --out"
    ),
):
    """Push an object K times on the testbed and estimate its parameters after every push."""
    try:
        target = checked_export(export)
    except PushToKnowError as e:
        fail(e)
    run_inference(
        model,
        obj,
        pushes,
        policy.value,
        seed,
        out,
        as_json,
        sigma_points=sigma_points,
        profiles=None if profiles is None else parse_profiles(profiles),
        estimator=estimator.value,
        export=target,
        overwrite=overwrite,
    )


@app.command()
def demo(
    out: Path = typer.Option(Path("demo-out"), "--out"),
    seed: int = seed_option(),
    model: str = typer.Option("pretrained", "--model"),
    pushes: int = pushes_option(5, "pushes"),
    estimator: EstimatorChoice = estimator_option(),
    overwrite: bool = typer.Option(
        False, "--overwrite", help="replace a run of another object in --out"
    ),
):
    """Offline demo: a held-out catalogue object (never trained on) estimated from 5 pushes;
    prints the tables, writes the plot and a strip of rendered frames."""
    from pushtoknow.testbed.objects import demo_object_id

    run_inference(
        model,
        f"catalogue:{demo_object_id()}",
        pushes,
        "uniform",
        seed,
        out,
        False,
        strip=True,
        estimator=estimator.value,
        overwrite=overwrite,
    )
