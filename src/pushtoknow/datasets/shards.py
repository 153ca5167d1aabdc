"""HDF5 shard format (schema version 1) for push episodes.

One file per shard, `shard-NNNNN.h5`, written to `*.h5.tmp` and renamed when complete, so a
finished shard is never half-written. Layout:

    /                       attrs: schema_version, pushtoknow_version, fingerprint, shard_index,
                                   sim_config (JSON), complete=True, content_sha256
    /objects/<i>            attrs: spec (JSON), params (5,) SI, object_index
    /objects/<i>/pushes/<k> attrs: action (5,) [cp_x, cp_y, pd, v, profile index], profile
        time (T,) s · pose (T, 3) x, y, θ (unwrapped) · tactile (T, 3) F_x, F_y (N), contact
        force_clean (T, 2) N · pusher (T, 2) m · s0 (H, W) bool
        rgb (T, H, W, 3) uint8 · depth (T, H, W) float16 metres (±0.3 mm at 0.75 m)
Image datasets are chunked one frame per chunk and gzip-compressed. Integrity: every dataset
carries HDF5's Fletcher-32 checksum (a corrupt chunk fails to read, naming the dataset), and
`content_sha256` digests the objects' attributes and arrays (`content_digest`), so
`check_digest` (`dataset info --verify`, and resume before it skips a finished shard) finds
corruption anywhere in them. Shards written without a digest are checked for readability only.
"""

from __future__ import annotations

import hashlib
import json
import os
from dataclasses import dataclass
from pathlib import Path

import h5py
import numpy as np

from pushtoknow import __version__
from pushtoknow.common.errors import DatasetError
from pushtoknow.testbed.config import stored_sim_config
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord

SCHEMA_VERSION = 1
SHARD_GLOB = "shard-*.h5"
GENERATION_FILE = "generation.json"  # a generated dataset's provenance: its config and plan
RUN_PUSHES = "pushes"  # subfolder of an `infer` / `demo` output holding the executed pushes
CHECKSUM = {"fletcher32": True}
COMPRESSION = {"compression": "gzip", "compression_opts": 4, "shuffle": True, **CHECKSUM}
DIGEST_ATTR = "content_sha256"


def shard_path(out: Path, index: int) -> Path:
    return Path(out) / f"shard-{index:05d}.h5"


@dataclass
class ObjectEpisode:
    spec: ObjectSpec
    object_index: int
    records: list[PushRecord]


def write_shard(
    path: Path,
    episodes: list[ObjectEpisode],
    *,
    fingerprint: str,
    shard_index: int,
    sim_config_json: str,
    attrs: dict | None = None,
    object_attrs: list[dict] | None = None,
    push_attrs: list[list[dict]] | None = None,
) -> None:
    """Write a shard atomically (temp file, fsync, rename). `attrs`: extra root attributes
    (e.g. the push policy and model of `pushtoknow collect`); `object_attrs`, `push_attrs`:
    extra attributes per episode and per push of each episode (e.g. an import's provenance),
    covered by the content digest like the rest."""
    path = Path(path)
    tmp = path.with_suffix(".h5.tmp")
    with h5py.File(tmp, "w") as f:
        f.attrs.update(
            schema_version=SCHEMA_VERSION,
            pushtoknow_version=__version__,
            fingerprint=fingerprint,
            shard_index=shard_index,
            sim_config=sim_config_json,
            complete=False,
        )
        f.attrs.update(attrs or {})
        objs = f.create_group("objects")
        for e, ep in enumerate(episodes):
            g = objs.create_group(str(ep.object_index))
            g.attrs.update(
                spec=ep.spec.to_json(),
                params=ep.spec.params.as_array(),
                object_index=ep.object_index,
            )
            g.attrs.update(object_attrs[e] if object_attrs else {})
            pushes = g.create_group("pushes")
            for k, r in enumerate(ep.records):
                p = pushes.create_group(str(k))
                p.attrs.update(action=r.push.as_array(), profile=r.push.profile)
                p.attrs.update(push_attrs[e][k] if push_attrs else {})
                for name in ("time", "pose", "tactile", "force_clean", "pusher"):
                    p.create_dataset(name, data=getattr(r, name), **CHECKSUM)
                p.create_dataset("s0", data=r.s0, **COMPRESSION)
                if r.outline_mask is not None:
                    p.create_dataset("outline_mask", data=r.outline_mask, **COMPRESSION)
                T, H, W = r.depth.shape
                p.create_dataset("rgb", data=r.rgb, chunks=(1, H, W, 3), **COMPRESSION)
                p.create_dataset(
                    "depth", data=r.depth.astype(np.float16), chunks=(1, H, W), **COMPRESSION
                )
        f.attrs[DIGEST_ATTR] = content_digest(tmp, objs)
        f.attrs["complete"] = True
        f.flush()
    with open(tmp, "rb+") as fh:
        os.fsync(fh.fileno())
    os.replace(tmp, path)


def open_shard(path: Path) -> h5py.File:
    """Open a shard for reading, checking it is complete and of our schema version."""
    path = Path(path)
    try:
        f = h5py.File(path, "r")
    except OSError as e:
        raise DatasetError(path, f"not a readable HDF5 shard ({e})") from None
    try:
        version = f.attrs.get("schema_version")
        if version is None:
            raise DatasetError(path, "no schema_version attribute: not a pushtoknow shard")
        if int(version) != SCHEMA_VERSION:
            raise DatasetError(
                path,
                f"schema version {int(version)}, this pushtoknow reads version {SCHEMA_VERSION}",
            )
        if not bool(f.attrs.get("complete", False)) or "objects" not in f:
            raise DatasetError(path, "shard is incomplete (interrupted write)")
    except DatasetError:
        f.close()
        raise
    return f


def _digest_value(h, value) -> None:
    a = np.asarray(value)
    h.update(f"{a.dtype.str}{a.shape}".encode())
    h.update(a.tobytes() if a.dtype != object else repr(a.tolist()).encode())


def content_digest(path: Path, objects: h5py.Group) -> str:
    """SHA-256 (hex) of a shard's /objects: every group's attributes and every array, in sorted
    order. Reading the arrays checks their Fletcher-32 checksums on the way (DatasetError)."""
    h = hashlib.sha256()

    def visit(name: str, node) -> None:
        h.update(name.encode())
        for key in sorted(node.attrs):
            h.update(key.encode())
            _digest_value(h, node.attrs[key])
        if isinstance(node, h5py.Dataset):
            _digest_value(h, _read(path, node.parent, node.name.rsplit("/", 1)[-1]))

    h.update(b"objects")
    for key in sorted(objects.attrs):
        _digest_value(h, objects.attrs[key])
    objects.visititems(visit)  # h5py visits in name order
    return h.hexdigest()


def check_digest(path: Path, f: h5py.File) -> bool:
    """Compare the content digest of the open shard `f` (at `path`) with the one written with it.
    Returns True when it matches, False when the shard has none (an older writer: only
    readability was checked); raises DatasetError naming the shard when it is corrupt."""
    digest = content_digest(path, f["objects"])
    stored = f.attrs.get(DIGEST_ATTR)
    if stored is None:
        return False
    if str(stored) != digest:
        raise DatasetError(
            path,
            "corrupt: its content does not match the digest written with it; move it away and "
            "rerun the command that wrote it to write it again",
        )
    return True


def shard_is_finished(path: Path, fingerprint: str) -> bool:
    """True if a complete, intact shard written with this fingerprint exists at `path`
    (resume; its content is verified, `check_digest`).

    Raises DatasetError naming the file if it is corrupt or was written with other settings.
    """
    if not Path(path).exists():
        return False
    with open_shard(path) as f:
        if f.attrs.get("fingerprint") != fingerprint:
            raise DatasetError(
                path,
                "written with other settings (objects, source files, seed or config differ); "
                "use another --out directory",
            )
        check_digest(path, f)
    return True


def _read(path: Path, grp, name: str):
    try:
        return grp[name][()]
    except (KeyError, OSError) as e:
        raise DatasetError(path, f"corrupt or missing dataset {grp.name}/{name} ({e})") from None


def read_push(path: Path, grp: h5py.Group, images: bool = True) -> PushRecord:
    """Read one push group into a PushRecord."""
    push = Push.from_array(grp.attrs["action"])
    fields = {n: _read(path, grp, n) for n in ("time", "pose", "tactile", "force_clean", "pusher")}
    rgb = depth = None
    if images:
        rgb = _read(path, grp, "rgb")
        depth = _read(path, grp, "depth").astype(np.float32)
    outline = _read(path, grp, "outline_mask") if "outline_mask" in grp else None
    return PushRecord(
        push=push, rgb=rgb, depth=depth, s0=_read(path, grp, "s0"), outline_mask=outline, **fields
    )


def read_shard(path: Path, images: bool = True) -> list[ObjectEpisode]:
    with open_shard(path) as f:
        out = []
        for key in sorted(f["objects"], key=int):
            g = f["objects"][key]
            try:
                spec = ObjectSpec.from_dict(json.loads(g.attrs["spec"]), stored=True)
            except (KeyError, json.JSONDecodeError) as e:
                raise DatasetError(path, f"object {key}: unreadable spec ({e})") from None
            recs = [read_push(path, g["pushes"][k], images) for k in sorted(g["pushes"], key=int)]
            out.append(ObjectEpisode(spec, int(g.attrs["object_index"]), recs))
        return out


def write_run_pushes(
    run_dir: Path, spec: ObjectSpec, records: list[PushRecord], sim_config_json: str
) -> Path:
    """Keep the pushes an inference run executed as a one-object dataset in
    `run_dir`/RUN_PUSHES (shard 0, the object's true spec), so that other estimators
    (`pushtoknow identify --pushes RUN`) can use the very same pushes. Returns the shard."""
    folder = Path(run_dir) / RUN_PUSHES
    folder.mkdir(parents=True, exist_ok=True)
    path = shard_path(folder, 0)
    write_shard(
        path,
        [ObjectEpisode(spec, 0, list(records))],
        fingerprint="inference run",
        shard_index=0,
        sim_config_json=sim_config_json,
    )
    return path


def list_shards(root: Path) -> list[Path]:
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(root, "no such dataset directory")
    return sorted(root.glob(SHARD_GLOB))


def dataset_info(root: Path, verify: bool = False) -> dict:
    """Summary of a dataset directory: schema_version, testbed_version (the physics the pushes
    were simulated with, docs/PHYSICS.md), shards, objects, expected_objects and complete (from
    its GENERATION_FILE; None without one), pushes, steps, bytes; with `verify`, every shard's
    content is checked (`check_digest`; DatasetError names the first corrupt one), and its
    fingerprint against the GENERATION_FILE's; verified_shards counts the shards with a matching
    digest (the others have none)."""
    shards = list_shards(root)
    if not shards:
        raise DatasetError(root, f"no {SHARD_GLOB} files")
    expected = record = None
    gen_file = Path(root) / GENERATION_FILE
    if gen_file.exists():
        try:
            record = json.loads(gen_file.read_text())
            expected = int(record["config"]["objects"])
        except (json.JSONDecodeError, KeyError, TypeError, ValueError):
            raise DatasetError(gen_file, "unreadable provenance record") from None
    verified = 0 if verify else None
    objects = pushes = steps = 0
    testbed_versions = set()
    profiles: dict[str, int] = {}
    image_shape = None
    for s in shards:
        with open_shard(s) as f:
            if verify:
                if record is not None and f.attrs.get("fingerprint") != record.get("fingerprint"):
                    raise DatasetError(
                        s, f"written with other settings than {GENERATION_FILE} records"
                    )
                verified += check_digest(s, f)
            testbed_versions.add(stored_sim_config(f.attrs["sim_config"]).testbed_version)
            for g in f["objects"].values():
                objects += 1
                for p in g["pushes"].values():
                    pushes += 1
                    steps += int(p["time"].shape[0])
                    prof = str(p.attrs["profile"])
                    profiles[prof] = profiles.get(prof, 0) + 1
                    image_shape = list(p["rgb"].shape[1:])
    return {
        "schema_version": SCHEMA_VERSION,
        "testbed_version": max(testbed_versions),
        "path": str(root),
        "shards": len(shards),
        "objects": objects,
        "expected_objects": expected,
        "complete": None if expected is None else objects >= expected,
        "pushes": pushes,
        "steps": steps,
        "profiles": profiles,
        "image_shape": image_shape,
        "bytes": int(sum(s.stat().st_size for s in shards)),
        **({} if verified is None else {"verified_shards": verified}),
    }
