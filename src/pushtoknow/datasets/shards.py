"""HDF5 shard format (schema version 1) for push episodes.

One file per shard, `shard-NNNNN.h5`, built in memory, written to `*.h5.tmp` and renamed when
complete, so a finished shard is never half-written. Layout:

    /                       attrs: schema_version, pushtoknow_version, fingerprint, shard_index,
                                   sim_config (JSON), complete=True, content_sha256
    /objects/<i>            attrs: spec (JSON), params (5,) SI, object_index
    /objects/<i>/pushes/<k> attrs: action (5,) [cp_x, cp_y, pd, v, profile index], profile
        time (T,) s · pose (T, 3) x, y, θ (unwrapped) · tactile (T, 3) F_x, F_y (N), contact
        force_clean (T, 2) N (simulated pushes only) · pusher (T, 2) m · s0 (H, W) bool
        rgb (T, H, W, 3) uint8 · depth (T, H, W) float16 metres (±0.3 mm at 0.75 m)
        pusher_fine (N, 3) [t s, x m, y m] (a real pusher at its recorder's rate, where known)
Image datasets are chunked one frame per chunk and gzip-compressed. Integrity: every dataset
carries HDF5's Fletcher-32 checksum (a corrupt chunk fails to read, naming the dataset), and
`content_sha256` digests the objects' attributes and arrays (`content_digest`), so
`check_digest` (`dataset info --verify`, and resume before it skips a finished shard) finds
corruption anywhere in them. Shards written without a digest are checked for readability only.
"""

from __future__ import annotations

import hashlib
import json
import warnings
from dataclasses import asdict, dataclass
from functools import partial
from pathlib import Path

import h5py
import numpy as np

from pushtoknow.common.errors import DatasetError, PushToKnowWarning, first_line
from pushtoknow.common.files import atomic_write
from pushtoknow.common.version import __version__
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import stored_sim_config

SCHEMA_VERSION = 1
SHARD_GLOB = "shard-*.h5"
GENERATION_FILE = "generation.json"  # a generated dataset's provenance: its config and plan
RUN_PUSHES = "pushes"  # subfolder of an `infer` / `demo` output holding the executed pushes
RUN_ESTIMATES = "estimates.json"  # an `infer` / `demo` output's estimates
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
    """Write a shard atomically: built in memory, then written to `*.h5.tmp`, fsynced and
    renamed (`common.files.atomic_write`), so a full disk ends in a `DiskFullError` naming the
    shard, never in a half-written HDF5 file. `attrs`: extra root attributes (e.g. the push
    policy and model of `pushtoknow collect`); `object_attrs`, `push_attrs`: extra attributes
    per episode and per push of each episode (e.g. an import's provenance), covered by the
    content digest like the rest."""
    path = Path(path)
    build = partial(_shard_bytes, path, episodes, fingerprint, shard_index, sim_config_json)
    atomic_write(path, lambda tmp: tmp.write_bytes(build(attrs, object_attrs, push_attrs)))


def _shard_bytes(
    path, episodes, fingerprint, shard_index, sim_config_json, attrs, object_attrs, push_attrs
) -> bytes:
    """The HDF5 file of a shard (`write_shard`), built in memory (HDF5's core driver: the
    bytes a file on disk would hold)."""
    with h5py.File(f"{path}.in-memory", "w", driver="core", backing_store=False) as f:
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
                for name in PushRecord.TRACKS:  # force_clean: absent for a real push
                    if getattr(r, name) is not None:
                        p.create_dataset(name, data=getattr(r, name), **CHECKSUM)
                p.create_dataset("s0", data=r.s0, **COMPRESSION)
                for name in ("outline_mask", "outline_mask_end"):
                    if getattr(r, name) is not None:
                        p.create_dataset(name, data=getattr(r, name), **COMPRESSION)
                if r.pusher_fine is not None:
                    p.create_dataset("pusher_fine", data=r.pusher_fine, **CHECKSUM)
                T, H, W = r.depth.shape
                p.create_dataset("rgb", data=r.rgb, chunks=(1, H, W, 3), **COMPRESSION)
                p.create_dataset(
                    "depth", data=r.depth.astype(np.float16), chunks=(1, H, W), **COMPRESSION
                )
        f.attrs[DIGEST_ATTR] = content_digest(path, objs)
        f.attrs["complete"] = True
        f.flush()
        return f.id.get_file_image()


HDF5_ERRORS = (OSError, RuntimeError, KeyError, ValueError)  # what h5py raises on a damaged file


def raised_by_hdf5(e: BaseException) -> bool:
    """Whether `e` comes from h5py itself (a damaged file: broken object headers, B-trees or
    chunks), not from the code reading the file: one of HDF5_ERRORS raised in an h5py frame."""
    if not isinstance(e, HDF5_ERRORS) or isinstance(e, DatasetError):
        return False
    tb = e.__traceback__
    while tb is not None and tb.tb_next is not None:
        tb = tb.tb_next
    return tb is not None and str(tb.tb_frame.f_globals.get("__name__", "")).startswith("h5py")


def damaged(path: Path, e: BaseException) -> DatasetError:
    """The DatasetError of a shard h5py cannot read (`raised_by_hdf5`)."""
    return DatasetError(
        path,
        f"unreadable ({first_line(e)}): damaged, or not written by pushtoknow; move it away "
        "and rerun the command that wrote it to write it again",
    )


class Shard(h5py.File):
    """A shard open for reading (`open_shard`): an h5py.File whose `with` block turns what h5py
    raises on damaged metadata or data into a DatasetError naming the file."""

    shard_path: Path

    def __exit__(self, *exc_info) -> None:
        super().__exit__(*exc_info)
        if exc_info[1] is not None and raised_by_hdf5(exc_info[1]):
            raise damaged(self.shard_path, exc_info[1]) from None


def open_shard(path: Path) -> Shard:
    """Open a shard for reading, checking it is complete and of our schema version. In a `with`
    block, an error h5py raises on a damaged file becomes a DatasetError naming it."""
    path = Path(path)
    try:
        f = Shard(path, "r")
    except HDF5_ERRORS as e:
        raise DatasetError(path, f"not a readable HDF5 shard ({first_line(e)})") from None
    f.shard_path = path
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
    except BaseException as e:
        f.close()
        if raised_by_hdf5(e):
            raise damaged(path, e) from None
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
    fields = {n: _read(path, grp, n) for n in PushRecord.TRACKS if n != "force_clean"}
    fields["force_clean"] = _read(path, grp, "force_clean") if "force_clean" in grp else None
    rgb = depth = None
    if images:
        rgb = _read(path, grp, "rgb")
        depth = _read(path, grp, "depth").astype(np.float32)
    outline = _read(path, grp, "outline_mask") if "outline_mask" in grp else None
    outline_end = _read(path, grp, "outline_mask_end") if "outline_mask_end" in grp else None
    fine = _read(path, grp, "pusher_fine") if "pusher_fine" in grp else None
    return PushRecord(
        push=push, rgb=rgb, depth=depth, s0=_read(path, grp, "s0"), outline_mask=outline,
        pusher_fine=fine, outline_mask_end=outline_end, **fields,
    )  # fmt: skip


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


def run_pushes_path(run_dir: Path) -> Path:
    """The shard in which an inference run in `run_dir` keeps its pushes (`write_run_pushes`)."""
    return shard_path(Path(run_dir) / RUN_PUSHES, 0)


def write_run_pushes(
    run_dir: Path,
    spec: ObjectSpec,
    records: list[PushRecord],
    sim_config_json: str,
    path: Path | None = None,
) -> Path:
    """Keep the pushes an inference run executed as a one-object dataset in
    `run_dir`/RUN_PUSHES (shard 0, the object's true spec), so that other estimators
    (`pushtoknow identify --pushes RUN`) can use the very same pushes. `path`: write the shard
    there instead (the temporary name of a run's files written as a set). Returns the shard."""
    folder = Path(run_dir) / RUN_PUSHES
    folder.mkdir(parents=True, exist_ok=True)
    path = run_pushes_path(run_dir) if path is None else Path(path)
    write_shard(
        path,
        [ObjectEpisode(spec, 0, list(records))],
        fingerprint="inference run",
        shard_index=0,
        sim_config_json=sim_config_json,
    )
    return path


def check_run_dir(run_dir: Path, spec: ObjectSpec, overwrite: bool = False) -> None:
    """Refuse (`DatasetError`) to write the inference run of `spec` into `run_dir` when the
    folder holds the run of another object, unless `overwrite`: the object whose pushes it
    kept (`RUN_PUSHES`; a spec that differs in any field is another object), else the one its
    `RUN_ESTIMATES` names. A run of the same object, or a folder without a run, is accepted
    (its files are replaced)."""
    if overwrite or not Path(run_dir).is_dir():
        return
    pushes, estimates = run_pushes_path(run_dir), Path(run_dir) / RUN_ESTIMATES
    old = None
    if pushes.exists():
        try:
            with open_shard(pushes) as f:
                old = json.loads(next(iter(f["objects"].values())).attrs["spec"])
        except (DatasetError, StopIteration, KeyError, ValueError, TypeError):
            old = "an object whose pushes cannot be read"
        if old == json.loads(spec.to_json()):
            return
    elif estimates.exists():
        try:
            name = json.loads(estimates.read_text()).get("object")
        except (OSError, ValueError, AttributeError):
            name = None
        if name == spec.name:
            return
        old = name or "an unnamed object"
    if old is None:
        return
    what = old if isinstance(old, str) else old.get("name") or "an unnamed object"
    raise DatasetError(
        run_dir,
        f"holds the run of another object ({what}); pass --overwrite to replace it, or "
        "use another --out folder",
    )


def list_shards(root: Path) -> list[Path]:
    root = Path(root)
    if not root.is_dir():
        raise DatasetError(root, "no such dataset directory")
    return sorted(root.glob(SHARD_GLOB))


def _provenance(root: Path) -> dict | None:
    """A dataset's GENERATION_FILE (None without one); DatasetError when it is unreadable."""
    gen_file = Path(root) / GENERATION_FILE
    if not gen_file.exists():
        return None
    try:
        record = json.loads(gen_file.read_text())
        int(record["config"]["objects"])
    except (json.JSONDecodeError, KeyError, TypeError, ValueError):
        raise DatasetError(gen_file, "unreadable provenance record") from None
    return record


@dataclass(frozen=True)
class DatasetInfo:
    """Summary of a dataset directory (`dataset_info`, `pushtoknow dataset info`):
    schema_version; testbed_version (the physics the pushes were simulated with,
    docs/PHYSICS.md; the newest where shards differ); path; shards, objects, pushes and steps
    (time samples over all pushes) counted in the shards; expected_objects and complete (from
    its GENERATION_FILE; None without one); pushes per speed profile (`profiles`);
    image_shape (H, W, 3 of the last push's RGB; None without pushes); bytes (the shards'
    size on disk); verified_shards (with `verify` only: shards with a matching content digest,
    the others have none; left out of `to_json()` otherwise)."""

    schema_version: int
    testbed_version: int
    path: str
    shards: int
    objects: int
    expected_objects: int | None
    complete: bool | None
    pushes: int
    steps: int
    profiles: dict[str, int]
    image_shape: list[int] | None
    bytes: int
    verified_shards: int | None = None

    def to_json(self) -> dict:
        d = asdict(self)
        if self.verified_shards is None:
            del d["verified_shards"]
        return d


def dataset_info(root: Path, verify: bool = False) -> DatasetInfo:
    """Summary of the dataset directory `root` (see `DatasetInfo`); with `verify`, every
    shard's content is checked (`check_digest`; DatasetError names the first corrupt one), and
    its fingerprint against the GENERATION_FILE's."""
    shards = list_shards(root)
    if not shards:
        raise DatasetError(root, f"no {SHARD_GLOB} files")
    record = _provenance(root)
    expected = None if record is None else int(record["config"]["objects"])
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
    return DatasetInfo(
        schema_version=SCHEMA_VERSION,
        testbed_version=max(testbed_versions),
        path=str(root),
        shards=len(shards),
        objects=objects,
        expected_objects=expected,
        complete=None if expected is None else objects >= expected,
        pushes=pushes,
        steps=steps,
        profiles=profiles,
        image_shape=image_shape,
        bytes=int(sum(s.stat().st_size for s in shards)),
        verified_shards=verified,
    )


def incompleteness(objects: int, expected_objects: int | None) -> str | None:
    """'incomplete: N of M objects written (…)' when a dataset's provenance record plans more
    objects (`expected_objects`; None without a record) than its shards hold (`objects`), else
    None."""
    if expected_objects is None or objects >= expected_objects:
        return None
    return (
        f"incomplete: {objects} of {expected_objects} objects written (an "
        "interrupted run: the same command resumes it)"
    )


def warn_if_incomplete(root: Path, use: str) -> str | None:
    """Warn (`PushToKnowWarning`, one line naming `root` and what it is used for, `use`) when
    the dataset at `root` is incomplete (`incompleteness`: its shards hold fewer objects than
    its provenance record plans); returns the warning's text. Reads only the shards' object
    lists; an unreadable dataset is left to the reading that follows."""
    try:
        record = _provenance(root)
        if record is None:
            return None
        objects = 0
        for shard in list_shards(root):
            with open_shard(shard) as f:
                objects += len(f["objects"])
    except DatasetError:
        return None
    note = incompleteness(objects, int(record["config"]["objects"]))
    if note is None:
        return None
    text = f"{use} {root} is {note}"
    warnings.warn(text, PushToKnowWarning, stacklevel=2)
    return text
