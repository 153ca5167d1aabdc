"""`pushtoknow` commands: physics-based identification (identify, identify-bench)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.table import Table

from pushtoknow.cli.options import (
    checked_export,
    export_option,
    prior_option,
    prior_ranges,
    ray_option,
    seed_option,
)
from pushtoknow.cli.shared import (
    app,
    command_line,
    console,
    err_console,
    fail,
    parse_profiles,
    save_and_print_json,
)
from pushtoknow.common.errors import IdentificationError, PushToKnowError

IDENTIFY_SHAPE_HELP = (
    "footprint to identify with: 'dataset' (the one stored with the pushes), 'from-mask' "
    "(traced on the first push's outline mask, corners sharpened, as the physics filter "
    "traces the outline it replays), a shape name (rect1, "
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


PUSHER_TOPIC_HELP = "bag: the pad's PoseStamped or PointStamped topic (/pusher/pose)"
OBJECT_TOPIC_HELP = "bag: the object's PoseStamped topic (/object/pose)"
FORCE_TOPIC_HELP = "bag: the pad's WrenchStamped topic (/pusher/wrench)"
BAG_CONFIG_HELP = "bag: YAML of topics, frame, split and the object (docs/RECORDING.md)"


def bag_options(config: Path | None, pusher: str | None, obj: str | None, force: str | None):
    """The bag mapping (`BagOptions`) of the topic options and --bag-config (None when none
    is given). Raises ConfigError naming the file."""
    from pushtoknow.common.errors import ConfigError
    from pushtoknow.datasets.mcap_reader import BagOptions

    topics = {"pusher_topic": pusher, "object_topic": obj, "force_topic": force}
    given = {k: v for k, v in topics.items() if v is not None}
    if config is None and not given:
        return None
    if config is not None and not Path(config).is_file():
        raise ConfigError(config, "--bag-config: no such file")
    base = BagOptions.from_yaml(config) if config is not None else BagOptions()
    return base.model_copy(update=given)


@app.command("identify")
def identify_cmd(
    pushes: Path = typer.Option(
        ...,
        "--pushes",
        help="dataset directory (shard-*.h5), one shard file, an `infer`/`demo` --out RUN "
        "(the pushes it executed), a recording file (docs/RECORDING.md) or a ROS 2 bag / "
        ".mcap file",
    ),
    pusher_topic: str = typer.Option(None, "--pusher-topic", help=PUSHER_TOPIC_HELP),
    object_topic: str = typer.Option(None, "--object-topic", help=OBJECT_TOPIC_HELP),
    force_topic: str = typer.Option(None, "--force-topic", help=FORCE_TOPIC_HELP),
    bag_config: Path = typer.Option(None, "--bag-config", help=BAG_CONFIG_HELP),
    shape: str = typer.Option("dataset", "--shape", help=IDENTIFY_SHAPE_HELP),
    object_index: int = typer.Option(
        None, "--object", help="index of the object in the dataset (default: every object)"
    ),
    max_pushes: int = typer.Option(None, "--max-pushes", min=1, help="use the first K pushes"),
    seed: int = seed_option(),
    workers: int = typer.Option(2, "--workers", min=1, help="processes for the rollouts"),
    ray: str = ray_option(),
    config: Path = typer.Option(None, "--config", help="IdentifyConfig YAML"),
    prior_mass: str | None = prior_option("mass"),
    prior_friction: str | None = prior_option("friction"),
    prior_inertia: str | None = prior_option("inertia"),
    as_json: bool = typer.Option(False, "--json", help="print the estimates as JSON"),
    export: tuple[str, Path] | None = export_option(),
):
    """Identify m, μ, CoM and I_z from recorded pushes by replaying them in MuJoCo (the
    testbed's own scene with the footprint and candidate parameters) and fitting the tactile
    force and pose tracks; intervals from the local curvature combined with the prior, and
    the directions the pushes do not reveal reported and kept at the prior's width."""
    from rich.progress import Progress

    from pushtoknow.api import export_identification
    from pushtoknow.common.parallel import make_runner
    from pushtoknow.identification.fit import identify
    from pushtoknow.identification.identify_config import IdentifyConfig
    from pushtoknow.identification.prior import EVERYDAY_PRIOR
    from pushtoknow.identification.recordings import load_recorded_objects, replay_scene
    from pushtoknow.identification.replay import RolloutPool

    try:
        target = checked_export(export)
        prior_ranges(EVERYDAY_PRIOR, prior_mass, prior_friction, prior_inertia)  # checked first
        cfg = IdentifyConfig.from_yaml(config) if config else IdentifyConfig()
        cfg = cfg.model_copy(update={"workers": workers})
        objects = load_recorded_objects(
            pushes, bag_options(bag_config, pusher_topic, object_topic, force_topic)
        )
        if object_index is not None:
            objects = [o for o in objects if o.index == object_index]
            if not objects:
                raise IdentificationError(f"--object {object_index}: no such object in {pushes}")
        if target is not None and len(objects) != 1:
            raise IdentificationError(
                f"--export: {pushes} holds {len(objects)} objects; choose one with --object"
            )
        results = []
        with (
            make_runner(cfg.workers, ray) as runner,
            RolloutPool(runner) as pool,
            Progress(console=err_console) as bar,
        ):
            for obj in objects:
                scene = replay_scene(obj, shape, cfg.stop_at_rest)
                records = obj.records[:max_pushes] if max_pushes else obj.records
                default = cfg.prior if "prior" in cfg.model_fields_set else obj.prior
                prior = prior_ranges(default, prior_mass, prior_friction, prior_inertia)
                obj_cfg = cfg.model_copy(update={"prior": prior})
                task = bar.add_task(f"{obj.name}: rollouts", total=None)
                res = identify(
                    records, scene, obj_cfg, seed, lambda n, t=task: bar.advance(t, n), pool
                )
                bar.update(task, total=res.rollouts, completed=res.rollouts)
                results.append((obj, res, prior))
        if target is not None:
            obj, res, _ = results[0]
            written = export_identification(res, scene, obj.name, *target)
    except PushToKnowError as e:
        fail(e)
    payload = {
        "pushes": str(pushes),
        "shape": shape,
        "seed": seed,
        "objects": [
            {
                "name": obj.name,
                "index": obj.index,
                "truth": None
                if obj.truth is None
                else [float(v) if v == v else None for v in obj.truth],
                "recording_notes": list(obj.notes),
                "prior": prior.model_dump(mode="json"),
                **res.as_dict(),
            }
            for obj, res, prior in results
        ],
    }
    if target is not None:
        err_console.print(f"exported ({target[0]}) → {', '.join(map(str, written))}")
    if as_json:
        print(json.dumps(payload))
        return
    for obj, res, prior in results:
        for note in obj.notes:
            err_console.print(f"{obj.name}: {note}")
        err_console.print(f"{obj.name}: prior {prior.label()}")
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
    from pushtoknow.identification.identify_config import IdentifyConfig

    names = parse_profiles(profiles)
    cfg = IdentifyConfig(workers=workers)
    with Progress(console=err_console) as bar:
        task = bar.add_task("objects identified", total=objects)
        res = run_identification_benchmark(
            objects, pushes, names, seed, cfg, progress=lambda _: bar.advance(task)
        )
    if markdown is not None:
        from pushtoknow.reporting.results import identification_markdown

        markdown.write_text(identification_markdown([res.to_json()], [command_line(ctx)]) + "\n")
    if save_and_print_json(res.to_json(), out, as_json):
        return
    t = Table(title=f"identification on {objects} novel objects, pushes: {', '.join(res.profiles)}")
    for c in ["", *PARAM_NAMES, "overall"]:
        t.add_column(c, justify="right")
    t.add_row("NRMSE", *[f"{res.nrmse[k]:.3f}" for k in (*PARAM_NAMES, "overall")])
    t.add_row("coverage 90%", *[f"{res.coverage90[k]:.2f}" for k in (*PARAM_NAMES, "overall")])
    console.print(t)
    rel = res.mu_m_relative_error
    console.print(
        f"μ·m relative error: median {rel['median']:.2%}, max {rel['max']:.2%}; "
        f"median {res.seconds_per_object['median']:.1f} s and "
        f"{res.rollouts_per_object['median']:.0f} rollouts per object ({workers} workers)"
    )
    console.print(f"not identified (objects): {res.unidentified or 'none'}")
