"""Dataset generation: `pushtoknow simulate`. Parallel over processes, resumable, seeded.

Each object i gets its own generator seeded by (seed, i), so the data do not depend on the
number of workers or on which shards were already written before an interruption.
"""

from __future__ import annotations

import hashlib
import json
import multiprocessing as mp
from pathlib import Path
from typing import Literal

import numpy as np
import yaml
from pydantic import Field

from pushtoknow.common.config import Config
from pushtoknow.common.errors import DatasetError, ObjectSpecError
from pushtoknow.datasets.shards import (
    ObjectEpisode,
    shard_is_finished,
    shard_path,
    write_shard,
)
from pushtoknow.geometry.affordances import sample_push_affordances
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.objects import (
    ObjectSpec,
    build_catalogue,
    catalogue_split,
    load_object_spec,
    sample_continuous_object,
)
from pushtoknow.testbed.push import Push

GENERATION_FILE = "generation.json"


class GenerationConfig(Config):
    objects: int = Field(4, gt=0)
    pushes: int = Field(2, gt=0)
    seed: int = 0
    objects_from: str = Field(
        "catalogue",
        description="catalogue | catalogue-train | catalogue-test | continuous | FILE",
    )
    profiles: tuple[Literal["constant", "release"], ...] = ("constant",)
    objects_per_shard: int = Field(4, gt=0)
    sim: SimConfig = SimConfig()

    def fingerprint(self) -> str:
        return hashlib.sha256(self.model_dump_json().encode()).hexdigest()[:16]

    def push_speed(self, profile: str) -> float:
        p = self.sim.push
        return p.speed if profile == "constant" else p.release_peak_speed


def select_objects(objects_from: str, n: int, seed: int) -> list[ObjectSpec]:
    """The n objects of a dataset, deterministic in (objects_from, n, seed)."""
    if objects_from in ("catalogue", "catalogue-train", "catalogue-test"):
        cat = build_catalogue().objects
        train, test = catalogue_split()
        pool = {"catalogue": range(len(cat)), "catalogue-train": train, "catalogue-test": test}
        ids = list(pool[objects_from])
        if n > len(ids):
            raise ValueError(f"--objects {n} exceeds the {len(ids)} objects of {objects_from}")
        order = np.random.default_rng(seed).permutation(len(ids))
        return [cat[ids[i]] for i in order[:n]]
    if objects_from == "continuous":
        return [sample_continuous_object(np.random.default_rng([seed, 1, i])) for i in range(n)]
    path = Path(objects_from)
    if not path.exists():
        raise ObjectSpecError(
            "--objects-from", objects_from, "neither 'catalogue', 'continuous' nor an existing file"
        )
    data = yaml.safe_load(path.read_text())
    items = data.get("objects", data) if isinstance(data, dict) else data
    items = items if isinstance(items, list) else [items]
    specs = [load_object_spec(x) if isinstance(x, str) else ObjectSpec.from_dict(x) for x in items]
    if n > len(specs):
        raise ValueError(f"--objects {n} exceeds the {len(specs)} objects in {path}")
    return specs[:n]


def simulate_object(spec: ObjectSpec, index: int, cfg: GenerationConfig) -> ObjectEpisode:
    """K pushes on one object: contact and direction from S_0's affordances, random profile."""
    rng = np.random.default_rng([cfg.seed, 0, index])
    ex = SimulatedExecutor(spec, cfg.sim, seed=int(rng.integers(2**31)))
    records = []
    try:
        for _ in range(cfg.pushes):
            view = ex.observe()
            cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
            profile = cfg.profiles[int(rng.integers(len(cfg.profiles)))]
            push = Push(tuple(cp[0]), float(pd[0]), profile, cfg.push_speed(profile))
            records.append(ex.execute(push))
    finally:
        ex.close()
    return ObjectEpisode(spec, index, records)


def _make_shard(args) -> tuple[int, int]:
    out, shard_index, indices, cfg_json = args
    cfg = GenerationConfig.model_validate_json(cfg_json)
    specs = select_objects(cfg.objects_from, cfg.objects, cfg.seed)
    episodes = [simulate_object(specs[i], i, cfg) for i in indices]
    write_shard(
        shard_path(Path(out), shard_index),
        episodes,
        fingerprint=cfg.fingerprint(),
        shard_index=shard_index,
        sim_config_json=cfg.sim.model_dump_json(),
    )
    return shard_index, len(indices)


def shard_plan(cfg: GenerationConfig) -> list[list[int]]:
    k = cfg.objects_per_shard
    return [list(range(s, min(s + k, cfg.objects))) for s in range(0, cfg.objects, k)]


def generate_dataset(
    out: Path, cfg: GenerationConfig, workers: int = 1, progress: bool = True
) -> dict:
    """Generate (or resume) a dataset in `out`. Returns counts of written and skipped shards."""
    out = Path(out)
    out.mkdir(parents=True, exist_ok=True)
    select_objects(cfg.objects_from, cfg.objects, cfg.seed)  # validate early, in the parent
    gen_file = out / GENERATION_FILE
    if gen_file.exists():
        old = json.loads(gen_file.read_text())
        if old.get("fingerprint") != cfg.fingerprint():
            raise DatasetError(
                out,
                "holds a dataset generated with other settings "
                f"(see {GENERATION_FILE}); use another --out directory",
            )
    else:
        gen_file.write_text(
            json.dumps(
                {"fingerprint": cfg.fingerprint(), "config": cfg.model_dump(mode="json")}, indent=1
            )
        )
    for stale in out.glob("*.h5.tmp"):
        stale.unlink()
    plan = shard_plan(cfg)
    todo = [
        (str(out), i, idx, cfg.model_dump_json())
        for i, idx in enumerate(plan)
        if not shard_is_finished(shard_path(out, i), cfg.fingerprint())
    ]
    skipped = len(plan) - len(todo)
    n_objects = sum(len(t[2]) for t in todo)

    from rich.progress import BarColumn, MofNCompleteColumn, Progress, TimeRemainingColumn

    with Progress(
        "[progress.description]{task.description}",
        BarColumn(),
        MofNCompleteColumn(),
        TimeRemainingColumn(),
        disable=not progress,
    ) as bar:
        task = bar.add_task(f"simulating ({skipped} shards already done)", total=n_objects)
        if workers <= 1 or len(todo) <= 1:
            for t in todo:
                bar.advance(task, _make_shard(t)[1])
        else:
            ctx = mp.get_context("spawn")  # fresh GL contexts; no forked MuJoCo state
            with ctx.Pool(min(workers, len(todo))) as pool:
                for _, n in pool.imap_unordered(_make_shard, todo):
                    bar.advance(task, n)
    return {"shards_written": len(todo), "shards_skipped": skipped, "objects": cfg.objects}
