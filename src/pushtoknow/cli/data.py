"""`pushtoknow` commands: data (simulate, dataset info, import-mit, collect,
convert-recording)."""

from __future__ import annotations

import json
from pathlib import Path

import typer
from rich.markup import escape
from rich.table import Table

from pushtoknow.cli.identify import (
    BAG_CONFIG_HELP,
    FORCE_TOPIC_HELP,
    OBJECT_TOPIC_HELP,
    PUSHER_TOPIC_HELP,
)
from pushtoknow.cli.options import (
    PolicyChoice,
    policy_option,
    pushes_option,
    ray_option,
    seed_option,
    sigma_points_option,
)
from pushtoknow.cli.shared import (
    app,
    console,
    dataset_app,
    err_console,
    fail,
    parse_profiles,
    print_result,
)
from pushtoknow.common.errors import PushToKnowError

OBJECTS_FROM_HELP = (
    "catalogue | catalogue-train | catalogue-test | continuous | novel (the evaluation's novel "
    "objects: unseen shapes and catalogue shapes alternately, continuous parameters) | "
    "random[:SEED] (random shapes, continuous parameters; SEED defaults to --seed) | FILE "
    "(JSON/YAML specs) | SOURCE+SOURCE[+…] (in turn, e.g. catalogue-train+continuous+random)"
)


@app.command()
def simulate(
    out: Path = typer.Option(..., "--out", help="output directory (resumed if it exists)"),
    objects: int = typer.Option(4, "--objects", min=1),
    pushes: int = pushes_option(2),
    seed: int = seed_option(),
    workers: int = typer.Option(1, "--workers", min=1),
    ray: str = ray_option(),
    objects_from: str = typer.Option(
        "catalogue",
        "--objects-from",
        help=OBJECTS_FROM_HELP,
    ),
    profiles: str = typer.Option(
        "constant", "--profiles", help="comma-separated speed profiles: constant,release"
    ),
    objects_per_shard: int = typer.Option(4, "--objects-per-shard", min=1),
    config: Path | None = typer.Option(None, "--config", help="SimConfig YAML"),
):
    """Simulate pushes and write an HDF5 dataset (atomic shards, resumable)."""
    from pushtoknow.common.parallel import make_runner
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
    from pushtoknow.testbed.sim_config import SimConfig

    try:
        sim = SimConfig.from_yaml(config) if config else SimConfig()
        cfg = GenerationConfig(
            objects=objects,
            pushes=pushes,
            seed=seed,
            objects_from=objects_from,
            profiles=parse_profiles(profiles),
            objects_per_shard=objects_per_shard,
            sim=sim,
        )
        with make_runner(workers, ray) as runner:
            res = generate_dataset(out, cfg, workers=runner)
    except (PushToKnowError, ValueError) as e:
        fail(e)
    console.print(
        f"wrote {res.shards_written} shards, skipped {res.shards_skipped} finished ones → {out}"
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
    from pushtoknow.datasets.shards import dataset_info, incompleteness

    try:
        info = dataset_info(root, verify=verify)
    except PushToKnowError as e:
        fail(e)
    if (note := incompleteness(info.objects, info.expected_objects)) is not None:
        err_console.print(f"[bold yellow]{escape(note)}[/]")
    if as_json:
        print(json.dumps(info.to_json()))
        return
    t = Table(title=str(root))
    t.add_column("field")
    t.add_column("value")
    for k, v in info.to_json().items():
        t.add_row(k, str(v))
    console.print(t)


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
        fail(e)
    print_result(res.to_json(), as_json, f"imported into {out}")


@app.command()
def collect(
    model: str = typer.Option(..., "--model", help="RUN directory, model.pt or 'pretrained'"),
    policy: PolicyChoice = policy_option(None, "push policy (required)"),
    objects: int = typer.Option(4, "--objects", min=1),
    pushes: int = pushes_option(2),
    seed: int = seed_option(),
    out: Path = typer.Option(..., "--out", help="output directory (resumed if it exists)"),
    objects_from: str = typer.Option(
        "catalogue-train",
        "--objects-from",
        help=OBJECTS_FROM_HELP,
    ),
    first_object_index: int = typer.Option(
        0, "--first-object-index", min=0, help="skip this many objects of the seeded order"
    ),
    workers: int = typer.Option(1, "--workers", min=1),
    ray: str = ray_option(),
    candidates: int = typer.Option(16, "--candidates", min=1),
    sigma_points: int = sigma_points_option(),
):
    """Collect training data with a push policy and a trained model (the filter runs, so active
    policies choose each push for the current belief); writes shards like `simulate`."""
    from pushtoknow.collection.collect import collect_dataset
    from pushtoknow.common.parallel import make_runner
    from pushtoknow.pretrained import resolve_model_path

    if policy is None:
        raise typer.BadParameter("--policy is required")
    try:
        model_path = resolve_model_path(model)
        with make_runner(workers, ray) as runner:
            res = collect_dataset(
                out,
                model_path,
                policy.value,
                objects_from,
                objects,
                pushes,
                seed,
                runner,
                first_object_index,
                candidates=candidates,
                num_sigma_points=sigma_points,
            )
    except (PushToKnowError, ValueError) as e:
        fail(e)
    console.print(
        f"wrote {res['shards_written']} shards, skipped {res['shards_skipped']} finished ones "
        f"({res['objects']} objects × {pushes} pushes, {policy.value}) → {out}"
    )


@app.command("convert-recording")
def convert_recording_cmd(
    src: Path = typer.Argument(..., help="a ROS 2 bag folder or an .mcap / .db3 file"),
    out: Path = typer.Option(..., "--out", help="the recording file to write (.h5)"),
    pusher_topic: str = typer.Option(None, "--pusher-topic", help=PUSHER_TOPIC_HELP),
    object_topic: str = typer.Option(None, "--object-topic", help=OBJECT_TOPIC_HELP),
    force_topic: str = typer.Option(None, "--force-topic", help=FORCE_TOPIC_HELP),
    bag_config: Path = typer.Option(None, "--bag-config", help=BAG_CONFIG_HELP),
):
    """Convert a ROS 2 bag or MCAP file into a recording file (docs/RECORDING.md), checked
    as `identify` reads it."""
    from pushtoknow.cli.identify import bag_options
    from pushtoknow.common.errors import DatasetError
    from pushtoknow.datasets.mcap_reader import BagOptions, is_bag, read_bag
    from pushtoknow.datasets.recording import write_recording

    try:
        if not is_bag(src):
            raise DatasetError(src, "not a ROS 2 bag folder (metadata.yaml) or .mcap/.db3 file")
        opts = bag_options(bag_config, pusher_topic, object_topic, force_topic) or BagOptions()
        meta, records = read_bag(src, opts)
        write_recording(out, records, meta)
    except PushToKnowError as e:
        fail(e)
    for note in meta.notes:
        err_console.print(f"note: {note}")
    console.print(f"wrote {len(records)} pushes of {meta.name} at {meta.rate:g} Hz → {out}")
