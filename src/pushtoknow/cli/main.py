"""`pushtoknow` command-line interface."""

from __future__ import annotations

import json
import os
import sys
from pathlib import Path

os.environ.setdefault("MUJOCO_GL", "egl")

import typer
from rich.console import Console
from rich.table import Table

from pushtoknow.common.errors import PushToKnowError

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


def _fail(e: Exception) -> None:
    err_console.print(f"[bold red]error:[/] {e}")
    raise typer.Exit(2)


@app.command()
def simulate(
    out: Path = typer.Option(..., "--out", help="output directory (resumed if it exists)"),
    objects: int = typer.Option(4, "--objects", min=1),
    pushes: int = typer.Option(2, "--pushes", min=1, help="pushes per object"),
    seed: int = typer.Option(0, "--seed"),
    workers: int = typer.Option(1, "--workers", min=1),
    objects_from: str = typer.Option(
        "catalogue", "--objects-from", help="catalogue | continuous | FILE (JSON/YAML specs)"
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
            profiles=tuple(p.strip() for p in profiles.split(",")),
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
def dataset_info_cmd(root: Path, as_json: bool = typer.Option(False, "--json")):
    """Summarise a dataset directory."""
    from pushtoknow.datasets.shards import dataset_info

    try:
        info = dataset_info(root)
    except PushToKnowError as e:
        _fail(e)
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
def bench_sim(as_json: bool = typer.Option(False, "--json"), pushes: int = 6, seed: int = 0):
    """Simulator real-time factor (64×64 RGB-D + tactile at 10 Hz, one process)."""
    from pushtoknow.bench.sim import run_sim_bench

    res = run_sim_bench(pushes=pushes, seed=seed)
    print(json.dumps(res, indent=None if as_json else 1))


@bench_app.command("filter")
def bench_filter(as_json: bool = typer.Option(False, "--json"), seed: int = 0):
    """Filter step latency (C = 100) and batched throughput (32 objects)."""
    from pushtoknow.bench.filter import run_filter_bench

    res = run_filter_bench(seed=seed)
    print(json.dumps(res, indent=None if as_json else 1))


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
    rate: float = typer.Option(10.0, "--rate", help="resampling rate (Hz)"),
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
        )
    except PushToKnowError as e:
        _fail(e)
    console.print(json.dumps(res))


@app.command("push")
def push_cmd(
    obj: str = typer.Option("catalogue:0", "--object", help="catalogue:ID or a JSON/YAML spec"),
    profile: str = typer.Option("constant", "--profile"),
    seed: int = typer.Option(0, "--seed"),
    out: Path = typer.Option(Path("push.png"), "--out", help="frame strip + force plot PNG"),
    as_json: bool = typer.Option(False, "--json"),
):
    """Simulate one push on an object, print its summary and save a strip of frames."""
    from pushtoknow.testbed.objects import load_object_spec
    from pushtoknow.viz import one_push, save_push_strip

    try:
        spec = load_object_spec(obj)
        rec, camera = one_push(spec, profile, seed)
    except PushToKnowError as e:
        _fail(e)
    save_push_strip(rec, camera, out, title=f"{spec.name} ({profile})")
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
def demo(
    out: Path = typer.Option(Path("demo-out"), "--out"),
    seed: int = typer.Option(0, "--seed"),
):
    """Offline demo. Until the pretrained estimator ships, it simulates a constant-speed and a
    release push on a held-out object and shows what the robot sees and feels."""
    from pushtoknow.testbed.objects import load_object_spec
    from pushtoknow.viz import one_push, save_push_strip

    out.mkdir(parents=True, exist_ok=True)
    spec = load_object_spec("catalogue:412")
    for profile in ("constant", "release"):
        rec, camera = one_push(spec, profile, seed)
        path = out / f"push-{profile}.png"
        save_push_strip(rec, camera, path, title=f"{spec.name} ({profile})")
        _print_push_summary(spec, _push_summary(spec, rec))
        console.print(f"frame strip → {path}")


def main() -> None:  # pragma: no cover
    try:
        app()
    except PushToKnowError as e:
        err_console.print(f"[bold red]error:[/] {e}")
        sys.exit(2)
