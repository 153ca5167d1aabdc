"""Training-data collection with a push policy and the current model (`pushtoknow collect`), and
the union of several datasets for training (docs/DESIGN.md §7, §8).

`collect_dataset` pushes each object K times with `inference.session.infer_object`, i.e. with
the trained model's filter running and the parameter belief carried from push to push, so an
active policy (active-kl, active-entropy) picks each push for the belief at that moment; uniform
and random choose among the same affordances without looking at the belief. The executed pushes
are written as shards in the format of `pushtoknow simulate` (atomic, resumable shard by shard;
`generation.json` records the model path and SHA-256, the policy, the seed and the settings, and
each shard carries `collection_policy` and `model_sha256` attributes).

Determinism: the objects are the first `first_object_index + objects` of `select_objects(
objects_from, ..., seed)` minus the first `first_object_index` (so consecutive calls with growing
`first_object_index` take disjoint blocks of one seeded order, and the blocks continue the
order of a `pushtoknow simulate` dataset with the same seed and source); object i (its global
index) gets its own generator seeded by (seed, 3, i) for the executor and the inference, so the
data do not depend on the number of workers or on the shards already written. The executor
re-centres the object between pushes (as at inference) so the filter's pose carries over.

`combine_datasets` makes one dataset directory out of several by linking their shards (hard
links, else symbolic links, else copies) under unique names, after checking that all were
simulated with the same testbed settings and that no object index occurs twice (the readers
split by `object_index`); `train_model` then trains on the union like on any dataset.
"""

from __future__ import annotations

import hashlib
import json
import os
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py
import numpy as np
from pydantic import Field

from pushtoknow.common.errors import DatasetError
from pushtoknow.common.files import file_sha256
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.parallel import Workers
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.common.policy_names import POLICY_NAMES, PolicyName
from pushtoknow.datasets.generate import (
    GENERATION_FILE,
    objects_file_sha256,
    prepare_dataset_dir,
    select_objects,
    write_pending_shards,
)
from pushtoknow.datasets.lock import dataset_lock
from pushtoknow.datasets.shards import (
    ObjectEpisode,
    list_shards,
    open_shard,
    shard_path,
    write_shard,
)
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.sim_config import SimConfig

COMBINED_FILE = "combined.json"


class CollectionConfig(Config):
    """Settings of one `collect_dataset` call (its fingerprint excludes the model's path, so
    a moved checkpoint with the same bytes resumes)."""

    model: str = Field(..., description="checkpoint path (provenance only)")
    model_sha256: str
    policy: PolicyName
    objects_from: str = "catalogue-train"
    objects: int = Field(4, gt=0)
    pushes: int = Field(2, gt=0)
    seed: int = 0
    first_object_index: int = Field(0, ge=0)
    objects_per_shard: int = Field(4, gt=0)
    candidates: int = Field(16, ge=1, description="affordances sampled per push decision")
    num_sigma_points: int | None = Field(None, ge=MIN_SIGMA_POINTS, description="None: the model's")
    sim: SimConfig = SimConfig()

    def fingerprint(self) -> str:
        """Hash of the settings; an objects FILE counts by its bytes, not its path."""
        data = self.model_dump(mode="json", exclude={"model"})
        data["objects_from"] = objects_file_sha256(self.objects_from) or self.objects_from
        return hashlib.sha256(json.dumps(data, sort_keys=True).encode()).hexdigest()[:16]


def check_policy(policy: str) -> str:
    if policy not in POLICY_NAMES:
        raise ValueError(f"policy must be one of {', '.join(POLICY_NAMES)}, got {policy!r}")
    return policy


def checkpoint_file(model_path: Path) -> Path:
    path = Path(model_path)
    return path / "model.pt" if path.is_dir() else path


def collection_objects(cfg: CollectionConfig) -> list[ObjectSpec]:
    """The objects of a collection: positions first_object_index … + objects − 1 of the seeded
    order of `objects_from`."""
    specs = select_objects(cfg.objects_from, cfg.first_object_index + cfg.objects, cfg.seed)
    return specs[cfg.first_object_index :]


def collect_object(model, spec: ObjectSpec, index: int, cfg: CollectionConfig) -> ObjectEpisode:
    """K pushes on one object chosen by `cfg.policy` with `model`'s filter running."""
    from pushtoknow.inference import InferenceConfig, infer_object
    from pushtoknow.inference.policies import make_policy
    from pushtoknow.testbed.executor import SimulatedExecutor

    rng = np.random.default_rng([cfg.seed, 3, index])
    ex_seed, inf_seed = (int(x) for x in rng.integers(2**31, size=2))
    icfg = InferenceConfig(
        estimator="vt-addf",  # collects the learned filter's training data
        pushes=cfg.pushes,
        policy=cfg.policy,
        candidates=cfg.candidates,
        num_sigma_points=cfg.num_sigma_points,
    )
    policy = make_policy(cfg.policy, icfg.active_horizon_fraction)
    ex = SimulatedExecutor(spec, cfg.sim, seed=ex_seed, recentre=True)
    try:
        res = infer_object(
            model,
            ex,
            icfg,
            inf_seed,
            initial_pose=ex.initial_pose,
            truth=spec.params.as_array(),
            policy=policy,
            sim_config=cfg.sim,  # the executor's
        )
    finally:
        ex.close()
    return ObjectEpisode(spec, index, res.records)


_MODELS: dict[str, object] = {}


def _load_model(path: str, sha256: str):
    """The checkpoint (cached per process), checked against the hash the collection started
    with."""
    from pushtoknow.models.checkpoint import load_checkpoint

    if sha256 not in _MODELS:
        actual = file_sha256(checkpoint_file(Path(path)))
        if actual != sha256:
            raise DatasetError(path, "the checkpoint changed while the collection was running")
        _MODELS.clear()
        _MODELS[sha256] = load_checkpoint(Path(path))
    return _MODELS[sha256]


def _worker_init() -> None:
    import torch

    torch.set_num_threads(1)  # one process per core


def _collect_shard(args) -> tuple[int, int]:
    out, shard_index, local, cfg_json = args
    cfg = CollectionConfig.model_validate_json(cfg_json)
    model = _load_model(cfg.model, cfg.model_sha256)
    specs = collection_objects(cfg)
    episodes = [collect_object(model, specs[i], cfg.first_object_index + i, cfg) for i in local]
    write_shard(
        shard_path(Path(out), shard_index),
        episodes,
        fingerprint=cfg.fingerprint(),
        shard_index=shard_index,
        sim_config_json=cfg.sim.model_dump_json(),
        attrs={"collection_policy": cfg.policy, "model_sha256": cfg.model_sha256},
    )
    return shard_index, len(local)


def collect_dataset(
    out: Path,
    model_path: Path,
    policy: str,
    objects_from: str = "catalogue-train",
    objects: int = 4,
    pushes: int = 2,
    seed: int = 0,
    workers: Workers = 1,
    first_object_index: int = 0,
    *,
    objects_per_shard: int = 4,
    candidates: int = 16,
    num_sigma_points: int | None = None,
    progress: bool = True,
) -> dict:
    """Collect (or resume) a dataset in `out` with `policy` and the model at `model_path` (a run
    directory or a checkpoint file); see the module docstring. The pushes use the model's
    testbed settings (`TrainedModel.sim_config`), so the data can be trained on together with
    the model's own. Returns counts of written and skipped shards."""
    from pushtoknow.models.checkpoint import load_checkpoint

    check_policy(policy)
    out, model_path = Path(out), Path(model_path)
    model = load_checkpoint(model_path)  # CheckpointError if missing or unreadable
    cfg = CollectionConfig(
        model=str(model_path),
        model_sha256=file_sha256(checkpoint_file(model_path)),
        policy=policy,
        objects_from=objects_from,
        objects=objects,
        pushes=pushes,
        seed=seed,
        first_object_index=first_object_index,
        objects_per_shard=objects_per_shard,
        candidates=candidates,
        num_sigma_points=num_sigma_points,
        sim=model.sim_config,
    )
    collection_objects(cfg)  # validate early, in the parent
    k = cfg.objects_per_shard
    plan = [list(range(s, min(s + k, cfg.objects))) for s in range(0, cfg.objects, k)]
    with dataset_lock(out):
        prepare_dataset_dir(
            out,
            cfg.fingerprint(),
            {"kind": "collect", "config": cfg.model_dump(mode="json")},
            "made with other settings, policy or model",
        )
        written, skipped = _write_pending(out, plan, cfg, model, workers, progress)
    return {
        "shards_written": written,
        "shards_skipped": skipped,
        "objects": cfg.objects,
        "pushes": cfg.objects * cfg.pushes,
        "policy": policy,
        "model_sha256": cfg.model_sha256,
    }


def _write_pending(out, plan, cfg, model, workers, progress) -> tuple[int, int]:
    """`write_pending_shards` of a collection, the loaded `model` cached meanwhile."""
    _MODELS.clear()
    _MODELS[cfg.model_sha256] = model  # the serial path reuses the loaded model
    try:
        return write_pending_shards(
            out,
            plan,
            cfg.fingerprint(),
            cfg.model_dump_json(),
            _collect_shard,
            workers,
            f"collecting ({cfg.policy})",
            progress,
            initializer=_worker_init,
        )
    finally:
        _MODELS.clear()


# --------------------------------------------------------------------------------------------
def _shard_summary(path: Path) -> tuple[str, list[int], int]:
    """(sim_config JSON, object indices, pushes) of one shard."""
    with open_shard(path) as f:
        objs = f["objects"]
        idx = [int(objs[k].attrs["object_index"]) for k in objs]
        pushes = sum(len(objs[k]["pushes"]) for k in objs)
        return str(f.attrs["sim_config"]), idx, pushes


def _link(src: Path, dst: Path) -> str:
    """dst → the same file as src (hard link, else symbolic link, else a copy), atomically."""
    tmp = dst.with_name(dst.name + ".link.tmp")
    tmp.unlink(missing_ok=True)
    try:
        os.link(src, tmp)
        how = "hardlink"
    except OSError:
        try:
            os.symlink(src.resolve(), tmp)
            how = "symlink"
        except OSError:
            shutil.copy2(src, tmp)
            how = "copy"
    os.replace(tmp, dst)
    return how


@dataclass(frozen=True)
class CombinedDataset:
    """What `combine_datasets` made: the combined directory (`path`), the shards linked into
    it, and the objects and pushes they hold (summed over the sources)."""

    path: str
    shards: int
    objects: int
    pushes: int

    def to_json(self) -> dict:
        return asdict(self)


def combine_datasets(dirs: list[Path], out: Path) -> CombinedDataset:
    """One dataset directory `out` holding the shards of every directory in `dirs` (see the
    module docstring); idempotent (re-running with the same sources rewrites the links).
    `out/generation.json` sums the sources' objects and pushes and lists their provenance;
    `out/combined.json` lists the linked files."""
    dirs = [Path(d) for d in dirs]
    out = Path(out)
    if not dirs:
        raise ValueError("combine_datasets needs at least one dataset directory")
    if any(out.resolve() == d.resolve() for d in dirs):
        raise DatasetError(out, "is one of the datasets being combined")
    sim_ref, owner = None, {}
    plan: list[tuple[Path, str]] = []
    sources, total_objects, total_pushes = [], 0, 0
    for i, d in enumerate(dirs):
        shards = list_shards(d)
        if not shards:
            raise DatasetError(d, "no shard-*.h5 files")
        n_obj = n_push = 0
        for s in shards:
            sim, idx, pushes = _shard_summary(s)
            if sim_ref is None:
                sim_ref, sim_from = sim, s
            elif sim != sim_ref:
                raise DatasetError(
                    s, f"simulated with other testbed settings than {sim_from}; cannot combine"
                )
            for k in idx:
                if k in owner:
                    raise DatasetError(
                        s,
                        f"object index {k} also occurs in {owner[k]}: the combined dataset "
                        "would merge two objects (collect with another --first-object-index)",
                    )
                owner[k] = s
            n_obj += len(idx)
            n_push += pushes
            plan.append((s, f"shard-{i:03d}-{s.name[len('shard-') :]}"))
        gen = d / GENERATION_FILE
        g = json.loads(gen.read_text()) if gen.exists() else {}
        sources.append(
            {
                "path": str(d),
                "fingerprint": g.get("fingerprint"),
                "kind": g.get("kind", "simulate" if g else None),
                "config": g.get("config"),
                "objects": n_obj,
                "pushes": n_push,
            }
        )
        total_objects += n_obj
        total_pushes += n_push
    out.mkdir(parents=True, exist_ok=True)
    existing = set(list_shards(out))
    if existing and not (out / COMBINED_FILE).exists():
        raise DatasetError(out, f"holds shards but no {COMBINED_FILE}: not a combined dataset")
    names = {name for _, name in plan}
    for stale in existing:
        if stale.name not in names:
            stale.unlink()
    links = {}
    for src, name in plan:
        links[name] = {"source": str(src), "how": _link(src, out / name)}
    per_object = {s["config"].get("pushes") for s in sources if s.get("config")}
    fingerprint = hashlib.sha256(
        json.dumps([s["fingerprint"] for s in sources]).encode()
    ).hexdigest()[:16]
    record = {
        "fingerprint": fingerprint,
        "kind": "combined",
        "config": {
            "objects": total_objects,
            "pushes": per_object.pop() if len(per_object) == 1 else None,
            "seed": None,
            "objects_from": "+".join(
                sorted({str((s.get("config") or {}).get("objects_from")) for s in sources})
            ),
        },
        "pushes_total": total_pushes,
        "sources": sources,
    }
    for name, data in ((GENERATION_FILE, record), (COMBINED_FILE, links)):
        tmp = out / (name + ".tmp")
        tmp.write_text(json.dumps(data, indent=1))
        os.replace(tmp, out / name)
    return CombinedDataset(str(out), len(plan), total_objects, total_pushes)


def dataset_policies(root: Path) -> dict[str, int]:
    """Pushes per collection policy in a dataset ("simulate" for shards without one)."""
    counts: dict[str, int] = {}
    for s in list_shards(root):
        with h5py.File(s, "r") as f:
            policy = str(f.attrs.get("collection_policy", "simulate"))
            n = sum(len(g["pushes"]) for g in f["objects"].values())
        counts[policy] = counts.get(policy, 0) + n
    return counts
