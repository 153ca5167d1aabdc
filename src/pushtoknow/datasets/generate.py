"""Dataset generation: `pushtoknow simulate`. Parallel over processes, resumable, seeded.

Each object i gets its own generator seeded by (seed, i), so the data do not depend on the
number of workers or on which shards were already written before an interruption.
"""

from __future__ import annotations

import hashlib
import json
import re
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Literal

import numpy as np
import yaml
from pydantic import Field

from pushtoknow.common.errors import DatasetError, ObjectSpecError, yaml_error_summary
from pushtoknow.common.files import atomic_write, file_sha256
from pushtoknow.common.frozen_config import Config, read_utf8
from pushtoknow.common.parallel import Workers, runner_for
from pushtoknow.datasets.lock import dataset_lock
from pushtoknow.datasets.shards import (
    GENERATION_FILE,
    SHARD_GLOB,
    ObjectEpisode,
    open_shard,
    shard_is_finished,
    shard_path,
    write_shard,
)
from pushtoknow.geometry.affordances import sample_push_affordances
from pushtoknow.testbed.executor import SimulatedExecutor
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import (
    ObjectSpec,
    build_catalogue,
    catalogue_split,
    novel_objects,
    sample_continuous_object,
)
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.random_shapes import random_objects
from pushtoknow.testbed.sim_config import SimConfig


class GenerationConfig(Config):
    objects: int = Field(4, gt=0)
    pushes: int = Field(2, gt=0)
    seed: int = 0
    objects_from: str = Field(
        "catalogue",
        description="catalogue | catalogue-train | catalogue-test | continuous | novel | "
        "random[:SEED] | FILE | SOURCE+SOURCE[+…] (those sources in turn, e.g. "
        "catalogue-train+continuous+random)",
    )
    profiles: tuple[Literal["constant", "release"], ...] = ("constant",)
    objects_per_shard: int = Field(4, gt=0)
    sim: SimConfig = SimConfig()

    def fingerprint(self) -> str:
        """Hash of the settings; an objects FILE counts by its bytes, not its path."""
        digest = objects_file_sha256(self.objects_from)
        cfg = self if digest is None else self.model_copy(update={"objects_from": digest})
        return hashlib.sha256(cfg.model_dump_json().encode()).hexdigest()[:16]

    def push_speed(self, profile: str) -> float:
        return self.sim.push.profile_speed(profile)


OBJECT_SOURCES = ("catalogue", "catalogue-train", "catalogue-test", "continuous", "novel",
                  "random")  # fmt: skip


def _named_source(objects_from: str) -> bool:
    """Whether `objects_from` names generated objects (a source, random:SEED or several joined
    by '+'), not a file."""
    parts = objects_from.split("+")
    return all(p in OBJECT_SOURCES or p.startswith("random:") for p in parts)


def objects_file_sha256(objects_from: str) -> str | None:
    """'sha256:HEX' of the bytes of an `objects_from` that names a file, else None."""
    if _named_source(objects_from):
        return None
    path = Path(objects_from)
    return f"sha256:{file_sha256(path)}" if path.is_file() else None


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
    if "+" in objects_from and _named_source(objects_from):  # the sources in turn
        parts = objects_from.split("+")
        k = len(parts)
        pools = [select_objects(p, len(range(j, n, k)), seed) for j, p in enumerate(parts)]
        return [pools[i % k][i // k] for i in range(n)]
    if objects_from == "novel":  # the evaluation's kind of object: unseen shapes among them
        return novel_objects(n, seed)
    if objects_from == "random":  # random shapes (testbed.random_shapes) of the dataset seed
        if seed < 0:
            raise ObjectSpecError("--seed", seed, "random objects need a non-negative seed")
        return random_objects(n, seed)
    if objects_from.startswith("random:"):  # random shapes of their own seed
        key = objects_from.partition(":")[2]
        if not re.fullmatch(r"[0-9]+", key):
            raise ObjectSpecError(
                "--objects-from", objects_from, "random:SEED needs a non-negative integer SEED"
            )
        return random_objects(n, int(key))
    path = Path(objects_from)
    if not path.exists():
        raise ObjectSpecError(
            "--objects-from",
            objects_from,
            "neither 'catalogue', 'continuous', 'novel', 'random[:SEED]', sources joined by "
            "'+' nor an existing file",
        )
    try:
        data = yaml.safe_load(read_utf8(path))
    except yaml.YAMLError as e:
        raise ObjectSpecError("--objects-from", objects_from, yaml_error_summary(e)) from None
    except ValueError as e:  # not UTF-8 text
        raise ObjectSpecError("--objects-from", objects_from, str(e)) from None
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
    fingerprint = cfg.fingerprint()
    recorded = _recorded_fingerprint(Path(out))
    if recorded is not None and recorded != fingerprint:  # an objects FILE edited meanwhile
        raise DatasetError(
            cfg.objects_from,
            f"changed while {out} was being simulated from it (its bytes differ), so {out} "
            "holds a run of other inputs; use another --out directory",
        )
    episodes = [simulate_object(specs[i], i, cfg) for i in indices]
    write_shard(
        shard_path(Path(out), shard_index),
        episodes,
        fingerprint=fingerprint,
        shard_index=shard_index,
        sim_config_json=cfg.sim.model_dump_json(),
    )
    return shard_index, len(indices)


def shard_plan(cfg: GenerationConfig) -> list[list[int]]:
    k = cfg.objects_per_shard
    return [list(range(s, min(s + k, cfg.objects))) for s in range(0, cfg.objects, k)]


def _recorded_fingerprint(out: Path) -> str | None:
    """The fingerprint in `out`'s provenance record (None without a readable one)."""
    try:
        return json.loads((out / GENERATION_FILE).read_text()).get("fingerprint")
    except (OSError, ValueError, AttributeError):
        return None


def check_objects_file(out: Path, cfg: GenerationConfig, digest: str | None) -> None:
    """Refuse, naming the file, to resume `out` from an objects FILE whose bytes differ from
    those it was simulated from (the other settings equal): its shards hold other objects."""
    try:
        record = json.loads((out / GENERATION_FILE).read_text())
        old_cfg, old_digest = record["config"], record.get("objects_sha256")
    except (OSError, ValueError, KeyError, TypeError):
        return  # no record: `prepare_dataset_dir` decides
    old_from = str(old_cfg.get("objects_from", ""))
    was_file = old_from not in OBJECT_SOURCES and not old_from.startswith("random:")
    same = {k: v for k, v in old_cfg.items() if k != "objects_from"} == {
        k: v for k, v in cfg.model_dump(mode="json").items() if k != "objects_from"
    }
    if digest is None or not was_file or not same or old_digest == digest:
        return
    why = (
        f"changed since {out} was simulated from it (its bytes differ), so {out} holds"
        if old_digest
        else f"{out} was simulated from it by an older pushtoknow, which did not record its "
        f"bytes, so {out} may hold"
    )
    raise DatasetError(
        cfg.objects_from, f"{why} a run of other inputs (objects); use another --out directory"
    )


def prepare_dataset_dir(out: Path, fingerprint: str, record: dict, refusal: str) -> None:
    """Create `out` (or accept it when its GENERATION_FILE has this fingerprint; else a
    DatasetError "holds a dataset `refusal` …"), write the provenance record atomically on first
    use, and drop temp files left by an interrupted run."""
    out.mkdir(parents=True, exist_ok=True)
    gen_file = out / GENERATION_FILE
    if gen_file.exists():
        try:
            old = json.loads(gen_file.read_text())
        except json.JSONDecodeError as e:
            raise DatasetError(
                gen_file, f"unreadable provenance record (not valid JSON: {e})"
            ) from None
        if old.get("fingerprint") != fingerprint:
            raise DatasetError(
                out,
                f"holds a dataset {refusal} (see {GENERATION_FILE}); use another --out directory",
            )
    else:
        for shard in sorted(out.glob(SHARD_GLOB)):  # a folder whose record was lost: its shards
            with open_shard(shard) as f:  # decide, before a record is written for them
                if f.attrs.get("fingerprint") != fingerprint:
                    raise DatasetError(shard, f"written {refusal}; use another --out directory")
        atomic_write(gen_file, json.dumps({"fingerprint": fingerprint, **record}, indent=1))
    for stale in out.glob("*.h5.tmp"):
        stale.unlink()


def write_pending_shards(
    out: Path,
    plan: list[list[int]],
    fingerprint: str,
    cfg_json: str,
    make_shard,
    workers: Workers,
    description: str,
    progress: bool = True,
    initializer=None,
) -> tuple[int, int]:
    """Write the shards of `plan` (object indices per shard) not yet finished, with
    make_shard((out, shard index, indices, cfg_json)) → (shard index, objects), on `workers`
    (a number of local processes, or a `TaskRunner`); a progress bar counts objects. Returns
    (written, skipped)."""
    todo = [
        (str(out), i, idx, cfg_json)
        for i, idx in enumerate(plan)
        if not shard_is_finished(shard_path(out, i), fingerprint)
    ]
    skipped = len(plan) - len(todo)

    from pushtoknow.common.progress import progress_bar

    with progress_bar(progress) as bar, runner_for(workers) as runner:
        task = bar.add_task(
            f"{description} ({skipped} shards already done)", total=sum(len(t[2]) for t in todo)
        )
        runner.map(
            make_shard, todo, on_done=lambda _, r: bar.advance(task, r[1]), initializer=initializer
        )
    return len(todo), skipped


@dataclass(frozen=True)
class GenerationResult:
    """The result of `generate_dataset` (`pushtoknow simulate`): shards written by this call,
    shards skipped (already finished, from an earlier run) and the objects of the dataset
    (`GenerationConfig.objects`, over all shards)."""

    shards_written: int
    shards_skipped: int
    objects: int

    def to_json(self) -> dict:
        return asdict(self)


def generate_dataset(
    out: Path, cfg: GenerationConfig, workers: Workers = 1, progress: bool = True
) -> GenerationResult:
    """Generate (or resume) a dataset in `out` on `workers` (local processes or a
    `TaskRunner`). Returns counts of written and skipped shards (`GenerationResult`)."""
    out = Path(out)
    select_objects(cfg.objects_from, cfg.objects, cfg.seed)  # validate early, in the parent
    digest = objects_file_sha256(cfg.objects_from)
    record = {"config": cfg.model_dump(mode="json")}
    if digest is not None:  # an objects FILE: its bytes are the provenance, not its path
        record["objects_sha256"] = digest
    with dataset_lock(out):
        check_objects_file(out, cfg, digest)
        fingerprint = cfg.fingerprint()
        prepare_dataset_dir(out, fingerprint, record, "generated with other settings")
        written, skipped = write_pending_shards(
            out,
            shard_plan(cfg),
            fingerprint,
            cfg.model_dump_json(),
            _make_shard,
            workers,
            "simulating",
            progress,
        )
    return GenerationResult(shards_written=written, shards_skipped=skipped, objects=cfg.objects)
