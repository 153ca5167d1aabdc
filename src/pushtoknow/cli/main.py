"""`pushtoknow` command-line interface."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import enum

import typer
from rich.console import Console
from rich.table import Table

from pushtoknow.cli.options import (
    SEED_HELP,
    PolicyChoice,
    policy_option,
    seed_option,
    sigma_points_option,
)
from pushtoknow.common.errors import IdentificationError, PushToKnowError, first_line
from pushtoknow.testbed.push import PROFILES

ProfileName = enum.Enum("ProfileName", {p: p for p in PROFILES}, type=str)  # CLI choices

app = typer.Typer(
    add_completion=False,
    no_args_is_help=True,
    help="Learn an object's mass, friction, CoM and inertia by pushing it.",
)
dataset_app = typer.Typer(no_args_is_help=True, help="Inspect datasets.")
bench_app = typer.Typer(no_args_is_help=True, help="Benchmarks (speed and memory).")
app.add_typer(dataset_app, name="dataset")
app.add_typer(bench_app, name="bench")
console = Console()
err_console = Console(stderr=True, soft_wrap=True)


def _version(value: bool) -> None:
    if value:
        from pushtoknow import __version__

        print(f"pushtoknow {__version__}")
        raise typer.Exit()


@app.callback()
def _main_options(
    version: bool = typer.Option(
        False, "--version", callback=_version, is_eager=True, help="print the version and exit"
    ),
) -> None:
    """Learn an object's mass, friction, CoM and inertia by pushing it."""


PROFILES_HELP = (
    "comma-separated speed profiles the policy may use: constant,release "
    "(default: those the model was trained on)"
)


def _save_and_print_json(data: dict, out: Path | None, as_json: bool) -> bool:
    """Write `data` to `out` (if given) and print it as JSON (if `as_json`); True when printed,
    so the caller skips its tables."""
    if out is not None:
        out.parent.mkdir(parents=True, exist_ok=True)
        out.write_text(json.dumps(data, indent=1))
    if as_json:
        print(json.dumps(data))
    return as_json


REPORT_OPTIONS = {"markdown", "as_json", "append"}  # how a result is shown, not what it is


def _command_line(ctx: typer.Context) -> str:
    """The command that reproduces this one's results: its path and every option given a value
    other than its default (output-display options left out), for reports."""
    import enum as _enum
    import shlex

    parts = ["pushtoknow", *ctx.command_path.split()[1:]]
    for p in ctx.command.params:
        value = ctx.params.get(p.name)
        if p.name in REPORT_OPTIONS or value is None or value == p.default or value == []:
            continue
        values = value if isinstance(value, (list, tuple)) else [value]
        for v in values:
            v = v.value if isinstance(v, _enum.Enum) else v
            flag = p.opts[0] if p.opts[0].startswith("-") else None
            if isinstance(v, bool):
                parts.append(flag if v else p.secondary_opts[0] if p.secondary_opts else "")
            else:
                parts += [flag, str(v)] if flag else [str(v)]
    return shlex.join([x for x in parts if x])


IMAGE_FORMATS = ("png", "jpg", "jpeg", "pdf", "svg")


def _image_out(path: Path, option: str = "--out") -> Path:
    """An image path checked before any work: a known format (no suffix: .png), not a folder."""
    if path.is_dir():
        raise typer.BadParameter(f"{option} {path}: is a folder, not an image file")
    suffix = path.suffix.lower().lstrip(".")
    if not suffix:
        return path.with_suffix(".png")
    if suffix not in IMAGE_FORMATS:
        raise typer.BadParameter(
            f"{option} {path}: unsupported image format '{suffix}' ({', '.join(IMAGE_FORMATS)})"
        )
    return path


def _out_folder(path: Path | None, option: str = "--out") -> None:
    """Refuse, before any work, an output folder that is an existing file."""
    if path is not None and path.exists() and not path.is_dir():
        raise typer.BadParameter(f"{option} {path}: is a file, not a folder")


def _flatten(data: dict, prefix: str = "") -> list[tuple[str, str]]:
    rows = []
    for k, v in data.items():
        if isinstance(v, dict):
            rows += _flatten(v, f"{prefix}{k}.")
        else:
            rows.append((f"{prefix}{k}", f"{v:.4g}" if isinstance(v, float) else str(v)))
    return rows


def _print_result(data: dict, as_json: bool, title: str) -> None:
    """A command's result on stdout: JSON with --json, else a table of its (flattened) fields."""
    if as_json:
        print(json.dumps(data))
        return
    t = Table(title=title)
    t.add_column("field")
    t.add_column("value", justify="right")
    for k, v in _flatten(data):
        t.add_row(k, v)
    console.print(t)


def _profiles(text: str) -> tuple[str, ...]:
    """'constant,release' → ("constant", "release"), each checked."""
    names = tuple(p.strip() for p in text.split(",") if p.strip())
    bad = [p for p in names if p not in PROFILES]
    if not names or bad:
        raise typer.BadParameter(
            f"--profiles: unknown profile(s) {bad or text!r}; choose from {', '.join(PROFILES)}"
        )
    return names


def _validation_summary(e: Exception) -> str | None:
    """'field: problem; …' for a settings validation error (pydantic), else None."""
    errors = getattr(e, "errors", None)
    if not callable(errors) or type(e).__name__ != "ValidationError":
        return None
    return "; ".join(f"{'.'.join(map(str, d['loc'])) or '<root>'}: {d['msg']}" for d in errors())


def _fail(e: Exception) -> None:
    message = _validation_summary(e) or first_line(e)
    err_console.print(f"[bold red]error:[/] {message}", highlight=False)
    raise typer.Exit(2)


@app.command()
def simulate(
    out: Path = typer.Option(..., "--out", help="output directory (resumed if it exists)"),
    objects: int = typer.Option(4, "--objects", min=1),
    pushes: int = typer.Option(2, "--pushes", min=1, help="pushes per object"),
    seed: int = seed_option(),
    workers: int = typer.Option(1, "--workers", min=1),
    objects_from: str = typer.Option(
        "catalogue",
        "--objects-from",
        help="catalogue | catalogue-train | catalogue-test | continuous | "
        "catalogue-train+continuous (alternately) | FILE (JSON/YAML specs)",
    ),
    profiles: str = typer.Option(
        "constant", "--profiles", help="comma-separated speed profiles: constant,release"
    ),
    objects_per_shard: int = typer.Option(4, "--objects-per-shard", min=1),
    config: Path | None = typer.Option(None, "--config", help="SimConfig YAML"),
):
    """Simulate pushes and write an HDF5 dataset (atomic shards, resumable)."""
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
    from pushtoknow.testbed.config import SimConfig

    try:
        sim = SimConfig.from_yaml(config) if config else SimConfig()
        cfg = GenerationConfig(
            objects=objects,
            pushes=pushes,
            seed=seed,
            objects_from=objects_from,
            profiles=_profiles(profiles),
            objects_per_shard=objects_per_shard,
            sim=sim,
        )
        res = generate_dataset(out, cfg, workers=workers)
    except (PushToKnowError, ValueError) as e:
        _fail(e)
    console.print(
        f"wrote {res['shards_written']} shards, skipped {res['shards_skipped']} "
        f"finished ones → {out}"
    )


@dataset_app.command("info")
def dataset_info_cmd(
    root: Path,
    as_json: bool = typer.Option(False, "--json"),
    verify: bool = typer.Option(
        False, "--verify", help="read every shard and check its checksums and content digest"
    ),
):
    """Summarise a dataset directory."""
    from pushtoknow.datasets.shards import dataset_info

    try:
        info = dataset_info(root, verify=verify)
    except PushToKnowError as e:
        _fail(e)
    if info["complete"] is False:
        err_console.print(
            f"[bold yellow]incomplete:[/] {info['objects']} of {info['expected_objects']} objects "
            "written (an interrupted run: the same command resumes it)"
        )
    if as_json:
        print(json.dumps(info))
        return
    t = Table(title=str(root))
    t.add_column("field")
    t.add_column("value")
    for k, v in info.items():
        t.add_row(k, str(v))
    console.print(t)


@bench_app.command("sim")
def bench_sim(
    as_json: bool = typer.Option(False, "--json"),
    pushes: int = typer.Option(6, "--pushes", min=1),
    seed: int = seed_option(),
):
    """Simulator real-time factor (64×64 RGB-D + tactile at 10 Hz, one process)."""
    from pushtoknow.bench.sim import run_sim_bench

    res = run_sim_bench(pushes=pushes, seed=seed)
    _print_result(res, as_json, "simulator speed")


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
            _fail(ValueError(f"--before {before}: {e}"))
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
    _print_result(res, as_json, "filter latency and throughput")


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
    _print_result(res, as_json, "active push decision")


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
    out: Path = typer.Option(None, "--out", help="write the metrics JSON here"),
    as_json: bool = typer.Option(False, "--json"),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the report section (markdown) here"
    ),
):
    """NRMSE after each of K pushes on held-out catalogue objects (the catalogue's test split),
    with the prior-mean predictor and the coverage of the 68% / 90% intervals."""
    profile_names = None if profiles is None else _profiles(profiles)
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
    with Progress(console=err_console) as bar:
        task = bar.add_task("held-out objects", total=n)
        run = evaluate_heldout(
            path,
            ids,
            pushes,
            policy_name,
            seed,
            workers,
            progress=lambda: bar.advance(task),
            profiles=profile_names,
        )
    metrics = heldout_metrics(run)
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
        from pushtoknow.evaluation.report import heldout_markdown

        markdown.write_text(heldout_markdown(metrics, _command_line(ctx)) + "\n")
    if _save_and_print_json(metrics, out, as_json):
        return
    t = Table(title=f"NRMSE on {n} held-out objects ({policy_name}, seed {seed})")
    for c in ["after push", *PARAM_NAMES, "overall", "μ·m", "coverage90"]:
        t.add_column(c, justify="right")
    fmt = lambda r: [f"{r[k]:.3f}" for k in (*PARAM_NAMES, "overall", "mu_m")]  # noqa: E731
    t.add_row("prior mean", *fmt(metrics["prior_mean"]), "")
    for r in metrics["per_push"]:
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

    from pushtoknow.common.policies import POLICY_NAMES
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
        _profiles(",".join(profiles))
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
    data: Path = typer.Option(..., "--data", help="training dataset (forest + prior-mean fit)"),
    models: list[str] = typer.Option(
        ..., "--models", help="trained runs (RUN dir, model.pt or 'pretrained'); repeat the flag"
    ),
    folds: int = typer.Option(None, "--folds", min=2, help="default: the config's (5)"),
    out: Path = typer.Option(..., "--out", help="report folder: results.json, RESULTS.md, figures"),
    config: Path = typer.Option(None, "--config", help="YAML EvaluationConfig"),
    seed: int = seed_option(None, "default: the config's; " + SEED_HELP),
    workers: int = typer.Option(None, "--workers", min=1),
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
):
    """Prior mean, random forest (ground-truth and VisNet poses), each model and push policy on
    held-out and novel objects: NRMSE (mean ± std over folds), coverage, figures, RESULTS.md."""

    from rich.progress import Progress

    from pushtoknow.evaluation.report import render_report
    from pushtoknow.evaluation.suite import EvaluationConfig, run_evaluation
    from pushtoknow.pretrained import resolve_model_path

    cfg = EvaluationConfig.from_yaml(config) if config else EvaluationConfig()
    overrides = {"folds": folds, "seed": seed, "workers": workers, "oracle": oracle}
    cfg = cfg.model_copy(update={k: v for k, v in overrides.items() if v is not None})
    cfg = EvaluationConfig.model_validate(cfg.model_dump())
    refs = [r for m in models for r in m.split(",") if r]
    paths = [resolve_model_path(r) for r in refs]
    extra = [Path(a).read_text() for a in append]  # read first: fail before hours of work
    with Progress(console=err_console) as bar:

        def progress(desc: str, total: int):
            task = bar.add_task(desc, total=total)
            return lambda: bar.advance(task)

        results = run_evaluation(
            data, paths, cfg, out, progress=progress, echo=lambda m: err_console.print(m)
        )
    command = _command_line(ctx)
    (out / "RESULTS.md").write_text(render_report(results, command, extra))
    if as_json:
        print(json.dumps({k: results[k] for k in ("methods", "primary", "config")}))
        return
    from pushtoknow.evaluation.report import COLUMNS

    for set_name, s in results["sets"].items():
        t = Table(title=f"NRMSE after {cfg.pushes} pushes, {set_name} ({len(s['objects'])})")
        for c in ["method", *COLUMNS, "μ·m", "cov90"]:
            t.add_column(c, justify="right")
        for name, m in s["methods"].items():
            cells = [f"{m['nrmse'][k]:.3f}±{m['nrmse_std'][k]:.3f}" for k in COLUMNS]
            t.add_row(name, *cells, f"{m['mu_m']:.3f}", f"{m['coverage90']:.2f}")
        console.print(t)
    console.print(f"wrote {out / 'results.json'}, {out / 'RESULTS.md'} and {out / 'figures'}")


@app.command("import-mit")
def import_mit(
    src: Path = typer.Argument(
        ..., help="folder of MIT Push .json/.h5 files (searched recursively)"
    ),
    out: Path = typer.Option(..., "--out"),
    surface: str | None = typer.Option(None, "--surface", help="e.g. plywood, abs, delrin"),
    shape: str | None = typer.Option(None, "--shape", help="e.g. rect1"),
    acceleration: float | None = typer.Option(
        None, "--acceleration", help="a=… in the file name; 0 selects the paper's subset"
    ),
    speed: float | None = typer.Option(None, "--speed", help="push speed in mm/s (v=…)"),
    rate: float = typer.Option(
        10.0,
        "--rate",
        min=0.1,
        max=250.0,
        help="resampling rate (Hz; at most the recordings' ~250 Hz)",
    ),
    as_speed: float | None = typer.Option(
        None,
        "--as-speed",
        min=0.1,
        help="mm/s: time-rescale each push to this speed (quasi-static)",
    ),
    as_json: bool = typer.Option(False, "--json"),
):
    """Convert MIT Push recordings into the project's dataset format (synthetic RGB-D)."""
    from pushtoknow.datasets.mit_import import import_mit_dataset

    try:
        res = import_mit_dataset(
            src,
            out,
            surface=surface,
            shape=shape,
            acceleration=acceleration,
            speed=None if speed is None else speed / 1000.0,
            rate=rate,
            as_speed=None if as_speed is None else as_speed / 1000.0,
        )
    except PushToKnowError as e:
        _fail(e)
    _print_result(res, as_json, f"imported into {out}")


@app.command("push")
def push_cmd(
    obj: str = typer.Option("catalogue:0", "--object", help="catalogue:ID or a JSON/YAML spec"),
    profile: ProfileName = typer.Option(ProfileName.constant, "--profile", help="speed profile"),
    seed: int = seed_option(),
    out: Path = typer.Option(Path("push.png"), "--out", help="frame strip + force plot PNG"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Simulate one push on an object, print its summary and save a strip of frames."""
    from pushtoknow.testbed.objects import load_object_spec
    from pushtoknow.viz import one_push, save_push_strip

    out = _image_out(out)
    try:
        spec = load_object_spec(obj)
        rec, camera = one_push(spec, profile.value, seed)
    except PushToKnowError as e:
        _fail(e)
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
        _fail(ValueError(f"--variant must be vt-addf, vt-jdf or v-ddf, got {variant!r}"))
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


def _format_estimate(mean: float, std: float, name: str) -> str:
    from pushtoknow.common.params import DISPLAY_UNITS

    scale, unit = DISPLAY_UNITS[name]
    return f"{mean * scale:.3g} ± {std * scale:.2g} {unit}".strip()


def _estimate_table(estimate, truth, title: str) -> Table:
    from pushtoknow.common.params import DISPLAY_UNITS, PARAM_NAMES

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
            _format_estimate(estimate.mean[j], estimate.std[j], name),
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
) -> dict:
    """Shared by `infer` and `demo`: K pushes on the testbed, tables, plot, JSON. profiles:
    None for those the model was trained on."""
    from pushtoknow.datasets.shards import write_run_pushes
    from pushtoknow.inference.session import InferenceConfig, infer_object
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path
    from pushtoknow.testbed.executor import SimulatedExecutor
    from pushtoknow.testbed.objects import load_object_spec
    from pushtoknow.viz import plot_estimates, save_push_strip

    _out_folder(out)
    model = load_checkpoint(resolve_model_path(model_ref))
    spec = load_object_spec(object_ref)
    truth = spec.params.as_array()
    show = Console(stderr=True) if as_json else console
    sim_cfg = model.sim_config
    cfg = InferenceConfig(
        pushes=pushes,
        policy=policy,
        num_sigma_points=sigma_points,
        profiles=model.profiles if profiles is None else profiles,
    )
    ex = SimulatedExecutor(spec, sim_cfg, seed=seed, recentre=True)
    show.print(
        f"[bold]{spec.name or 'object'}[/] ({spec.shape if isinstance(spec.shape, str) else ''})"
        f", model {model.variant} ({model_ref}), policy {policy}, {pushes} pushes, seed {seed}"
    )
    try:

        def on_push(e) -> None:
            show.print(_estimate_table(e, truth, f"after push {e.index}"))

        result = infer_object(
            model,
            ex,
            cfg,
            seed,
            initial_pose=ex.initial_pose,
            truth=truth,
            object_name=spec.name or "",
            on_push=on_push,
        )
    finally:
        ex.close()
    report = result.to_json()
    if out is not None:
        out.mkdir(parents=True, exist_ok=True)
        plot_estimates(result, out / "estimates.png", title=f"{spec.name} · {model.variant}")
        (out / "estimates.json").write_text(json.dumps(report, indent=1))
        pushes_file = write_run_pushes(out, spec, result.records, sim_cfg.model_dump_json())
        show.print(f"estimates plot → {out / 'estimates.png'}")
        show.print(f"executed pushes → {pushes_file} (`pushtoknow identify --pushes {out}`)")
        if strip:
            save_push_strip(
                result.records[0], model.camera, out / "push-1.png", title=f"{spec.name}, push 1"
            )
            show.print(f"frame strip → {out / 'push-1.png'}")
    if as_json:
        print(json.dumps(report))
    return report


@app.command()
def infer(
    model: str = typer.Option("pretrained", "--model", help="RUN directory or 'pretrained'"),
    obj: str = typer.Option(..., "--object", help="catalogue:ID, a JSON/YAML file or JSON"),
    pushes: int = typer.Option(5, "--pushes", min=1),
    policy: PolicyChoice = policy_option(),
    seed: int = seed_option(),
    out: Path = typer.Option(Path("infer-out"), "--out", help="where the plot and JSON go"),
    as_json: bool = typer.Option(False, "--json", help="print the estimates as JSON"),
    sigma_points: int = sigma_points_option(help="default: the model's (100)"),
    profiles: str = typer.Option(None, "--profiles", help=PROFILES_HELP),
):
    """Push an object K times on the testbed and estimate its parameters after every push."""
    run_inference(
        model,
        obj,
        pushes,
        policy.value,
        seed,
        out,
        as_json,
        sigma_points=sigma_points,
        profiles=None if profiles is None else _profiles(profiles),
    )


@app.command()
def demo(
    out: Path = typer.Option(Path("demo-out"), "--out"),
    seed: int = seed_option(),
    model: str = typer.Option("pretrained", "--model"),
    pushes: int = typer.Option(5, "--pushes", min=1),
):
    """Offline demo: the shipped model estimates a held-out catalogue object (never trained
    on) from 5 pushes; prints the tables, writes the plot and a strip of rendered frames."""
    from pushtoknow.testbed.objects import demo_object_id

    run_inference(
        model, f"catalogue:{demo_object_id()}", pushes, "uniform", seed, out, False, strip=True
    )


@app.command()
def collect(
    model: str = typer.Option(..., "--model", help="RUN directory, model.pt or 'pretrained'"),
    policy: PolicyChoice = policy_option(None, "push policy (required)"),
    objects: int = typer.Option(4, "--objects", min=1),
    pushes: int = typer.Option(2, "--pushes", min=1, help="pushes per object"),
    seed: int = seed_option(),
    out: Path = typer.Option(..., "--out", help="output directory (resumed if it exists)"),
    objects_from: str = typer.Option(
        "catalogue-train",
        "--objects-from",
        help="catalogue | catalogue-train | catalogue-test | continuous | FILE",
    ),
    first_object_index: int = typer.Option(
        0, "--first-object-index", min=0, help="skip this many objects of the seeded order"
    ),
    workers: int = typer.Option(1, "--workers", min=1),
    candidates: int = typer.Option(16, "--candidates", min=1),
    sigma_points: int = sigma_points_option(),
):
    """Collect training data with a push policy and a trained model (the filter runs, so active
    policies choose each push for the current belief); writes shards like `simulate`."""
    from pushtoknow.collection.collect import collect_dataset
    from pushtoknow.pretrained import resolve_model_path

    if policy is None:
        raise typer.BadParameter("--policy is required")
    try:
        res = collect_dataset(
            out,
            resolve_model_path(model),
            policy.value,
            objects_from,
            objects,
            pushes,
            seed,
            workers,
            first_object_index,
            candidates=candidates,
            num_sigma_points=sigma_points,
        )
    except (PushToKnowError, ValueError) as e:
        _fail(e)
    console.print(
        f"wrote {res['shards_written']} shards, skipped {res['shards_skipped']} finished ones "
        f"({res['objects']} objects × {pushes} pushes, {policy.value}) → {out}"
    )


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
    from pushtoknow.evaluation.figures import plot_learning_efficiency

    try:
        cfg = EfficiencyConfig.from_yaml(config)
    except OSError as e:
        _fail(ValueError(f"{config}: {e.strerror}"))
    except PushToKnowError as e:
        _fail(e)
    try:
        results = run_efficiency(
            cfg, out, seed, workers, log=lambda m: err_console.print(f"[dim]efficiency[/] {m}")
        )
    except (PushToKnowError, ValueError) as e:
        _fail(e)
    series = figure_series(results, "nll")
    if series:
        plot_learning_efficiency(
            series,
            out / "efficiency.png",
            ylabel="validation parameter NLL",
            title=f"learning efficiency ({len(cfg.seeds)} seeds, mean ± std)",
        )
    if markdown is not None:
        from pushtoknow.evaluation.report import efficiency_markdown

        markdown.write_text(efficiency_markdown(results, _command_line(ctx)) + "\n")
    if as_json:
        print(json.dumps(results))
        return
    t = Table(title="validation loss vs training pushes (mean ± std over seeds)")
    for c in ("policy", "pushes", "param NLL", "param RMSE (norm.)"):
        t.add_column(c, justify="right")
    for p, rows in results.items():
        for r in rows:
            t.add_row(
                p,
                str(r["pushes"]),
                f"{r['mean']:.4g} ± {r['std']:.2g}",
                f"{r['rmse_mean']:.3f} ± {r['rmse_std']:.3f}",
            )
    console.print(t)
    console.print(
        f"wrote {out / 'efficiency.json'}, {out / 'efficiency.csv'}, {out / 'efficiency.png'}"
    )


from pushtoknow.cli.real import register as _register_real  # noqa: E402

_register_real(app)


IDENTIFY_SHAPE_HELP = (
    "footprint to identify with: 'dataset' (the one stored with the pushes), 'from-mask' "
    "(estimated from the first push's S_0 and the camera model), a shape name (rect1, "
    "pentagon, ...), inline JSON, or a JSON/YAML file (a shape or an object spec)"
)


def _identification_table(name: str, res, truth) -> Table:
    from pushtoknow.common.params import PARAM_NAMES, PARAM_UNITS

    t = Table(title=f"{name}: physics-based identification ({res.pushes} pushes)")
    for c in ["parameter", "mean ± std", f"{res.level:.0%} interval", "truth"]:
        t.add_column(c, justify="right")
    for i, k in enumerate(PARAM_NAMES):
        t.add_row(
            f"{k} ({PARAM_UNITS[k]})",
            f"{res.mean[i]:.4g} ± {res.std[i]:.2g}",
            f"[{res.lower[i]:.4g}, {res.upper[i]:.4g}]",
            "" if truth is None else f"{truth[i]:.4g}",
        )
    lo, hi = res.mu_m_interval
    t.add_row(
        "μ·m (kg)",
        f"{res.mu_m:.4g} ± {res.mu_m_std:.2g}",
        f"[{lo:.4g}, {hi:.4g}]",
        "" if truth is None else f"{truth[0] * truth[1]:.4g}",
    )
    return t


@app.command("identify")
def identify_cmd(
    pushes: Path = typer.Option(
        ...,
        "--pushes",
        help="dataset directory (shard-*.h5), one shard file, or an `infer`/`demo` --out "
        "RUN (the pushes it executed)",
    ),
    shape: str = typer.Option("dataset", "--shape", help=IDENTIFY_SHAPE_HELP),
    object_index: int = typer.Option(
        None, "--object", help="index of the object in the dataset (default: every object)"
    ),
    max_pushes: int = typer.Option(None, "--max-pushes", min=1, help="use the first K pushes"),
    seed: int = seed_option(),
    workers: int = typer.Option(2, "--workers", min=1, help="processes for the rollouts"),
    config: Path = typer.Option(None, "--config", help="IdentifyConfig YAML"),
    as_json: bool = typer.Option(False, "--json", help="print the estimates as JSON"),
):
    """Identify m, μ, CoM and I_z from recorded pushes by replaying them in MuJoCo (the
    testbed's own scene with the footprint and candidate parameters) and fitting the tactile
    force and pose tracks; intervals from the local curvature combined with the prior, and
    the directions the pushes do not reveal reported and kept at the prior's width."""
    from rich.progress import Progress

    from pushtoknow.identification.config import IdentifyConfig
    from pushtoknow.identification.fit import identify
    from pushtoknow.identification.recordings import load_recorded_objects, replay_scene
    from pushtoknow.identification.replay import RolloutPool

    try:
        cfg = IdentifyConfig.from_yaml(config) if config else IdentifyConfig()
        cfg = cfg.model_copy(update={"workers": workers})
        objects = load_recorded_objects(pushes)
        if object_index is not None:
            objects = [o for o in objects if o.index == object_index]
            if not objects:
                raise IdentificationError(f"--object {object_index}: no such object in {pushes}")
        results = []
        with RolloutPool(cfg.workers) as pool, Progress(console=err_console) as bar:
            for obj in objects:
                scene = replay_scene(obj, shape, cfg.stop_at_rest)
                records = obj.records[:max_pushes] if max_pushes else obj.records
                task = bar.add_task(f"{obj.name}: rollouts", total=None)
                res = identify(records, scene, cfg, seed, lambda n, t=task: bar.advance(t, n), pool)
                bar.update(task, total=res.rollouts, completed=res.rollouts)
                results.append((obj, res))
    except PushToKnowError as e:
        _fail(e)
    payload = {
        "pushes": str(pushes),
        "shape": shape,
        "seed": seed,
        "objects": [
            {
                "name": obj.name,
                "index": obj.index,
                "truth": None if obj.truth is None else obj.truth.tolist(),
                **res.as_dict(),
            }
            for obj, res in results
        ],
    }
    if as_json:
        print(json.dumps(payload))
        return
    for obj, res in results:
        console.print(_identification_table(obj.name, res, obj.truth))
        console.print(
            f"not identified (prior width kept): {', '.join(res.unidentified) or 'none'}; "
            f"reduced χ² {res.chi2:.2f}; {res.rollouts} rollouts ({res.push_rollouts} pushes "
            f"replayed) in {res.seconds:.1f} s"
        )
        for note in res.notes:
            console.print(f"note: {note}")


@app.command("identify-bench")
def identify_bench_cmd(
    ctx: typer.Context,
    objects: int = typer.Option(16, "--objects", min=1, help="novel objects (unseen shapes)"),
    pushes: int = typer.Option(5, "--pushes", min=1, help="pushes per object"),
    profiles: str = typer.Option(
        "constant,release", "--profiles", help="profiles taken in turn, push by push"
    ),
    seed: int = seed_option(),
    workers: int = typer.Option(2, "--workers", min=1),
    out: Path = typer.Option(None, "--out", help="write the results JSON here"),
    as_json: bool = typer.Option(False, "--json", help="print the results JSON"),
    markdown: Path | None = typer.Option(
        None, "--markdown", help="write the report section (markdown) here"
    ),
):
    """Accuracy, coverage and compute of `identify` on simulated novel objects (true
    footprint, the testbed's own physics: an upper bound for any estimator on this testbed)."""
    from rich.progress import Progress

    from pushtoknow.common.params import PARAM_NAMES
    from pushtoknow.evaluation.identification import run_identification_benchmark
    from pushtoknow.identification.config import IdentifyConfig

    names = _profiles(profiles)
    cfg = IdentifyConfig(workers=workers)
    with Progress(console=err_console) as bar:
        task = bar.add_task("objects identified", total=objects)
        res = run_identification_benchmark(
            objects, pushes, names, seed, cfg, progress=lambda _: bar.advance(task)
        )
    if markdown is not None:
        from pushtoknow.evaluation.report import identification_markdown

        markdown.write_text(identification_markdown([res], [_command_line(ctx)]) + "\n")
    if _save_and_print_json(res, out, as_json):
        return
    t = Table(
        title=f"identification on {objects} novel objects, pushes: {', '.join(res['profiles'])}"
    )
    for c in ["", *PARAM_NAMES, "overall"]:
        t.add_column(c, justify="right")
    t.add_row("NRMSE", *[f"{res['nrmse'][k]:.3f}" for k in (*PARAM_NAMES, "overall")])
    t.add_row("coverage 90%", *[f"{res['coverage90'][k]:.2f}" for k in (*PARAM_NAMES, "overall")])
    console.print(t)
    rel = res["mu_m_relative_error"]
    console.print(
        f"μ·m relative error: median {rel['median']:.2%}, max {rel['max']:.2%}; "
        f"median {res['seconds_per_object']['median']:.1f} s and "
        f"{res['rollouts_per_object']['median']:.0f} rollouts per object ({workers} workers)"
    )
    console.print(f"not identified (objects): {res['unidentified'] or 'none'}")


def error_message(e: BaseException) -> str | None:
    """The one-line message of an error a user can cause (bad options, input, files, disk), or
    None for a bug (which keeps its traceback)."""
    if hasattr(e, "format_message") and getattr(e, "exit_code", None) == 2:  # a usage error
        return f"{first_line(e.format_message())} (see --help)"
    if isinstance(e, PushToKnowError):
        return first_line(e)
    if (summary := _validation_summary(e)) is not None:
        return summary
    if isinstance(e, OSError) and e.strerror:
        where = f"{e.filename}: " if e.filename else ""
        return f"{where}{e.strerror.lower()}"
    return None


def main() -> None:  # pragma: no cover - the installed entry point; tests call it in process
    try:
        code = app(standalone_mode=False)  # errors come here, to be told in one line
    except typer.Abort:
        err_console.print("aborted")
        sys.exit(130)
    except Exception as e:
        if type(e).__name__ == "NoArgsIsHelpError":  # no command: the help was printed
            sys.exit(2)
        message = error_message(e)
        if message is None:
            raise
        err_console.print(f"[bold red]error:[/] {message}", highlight=False)
        sys.exit(2)
    sys.exit(code if isinstance(code, int) else 0)
