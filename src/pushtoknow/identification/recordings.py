"""Recorded pushes to identify from, read from the project's dataset format
(`datasets.shards`), a recording file (`datasets.recording`) or a ROS 2 bag / MCAP file
(`datasets.mcap_reader`), and the footprint to identify with: the one stored with the pushes,
one given, or one estimated from the first image's mask S_0 and the camera model."""

from __future__ import annotations

import json
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
import yaml

from pushtoknow.common.errors import DatasetError, IdentificationError, ObjectSpecError
from pushtoknow.common.frozen_config import read_utf8
from pushtoknow.identification.prior import EVERYDAY_PRIOR, PriorRanges, generator_prior
from pushtoknow.identification.replay import ReplayScene
from pushtoknow.testbed.objects import NOVEL_SHAPES, recentred_legacy_shape, resolve_shape
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, footprint_from_shape
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig, stored_sim_config

if TYPE_CHECKING:
    from pushtoknow.datasets.mcap_reader import BagOptions
    from pushtoknow.datasets.recording import RecordingMeta


@dataclass(frozen=True)
class RecordedObject:
    """One object's recorded pushes. shape: the footprint stored with them (object frame);
    height (m); truth (5,) SI: the parameters stored with them (the simulator's truth; a
    recording of a real object stores its catalogue values; NaN where a recording does not
    know one) or None; sim_config: the settings the pushes were recorded with (for a recording
    or bag: the testbed's, with its clock, pad radius, force noise and push length); notes:
    what the reader changed (a resampling, a moved object frame); prior: the ranges of m, μ
    and I_z to start from (`prior.generator_prior` for objects the testbed drew and simulated,
    `prior.EVERYDAY_PRIOR` for real ones: recordings, bags, imported MIT Push pushes)."""

    name: str
    index: int
    shape: dict | None
    height: float
    truth: np.ndarray | None
    records: tuple[PushRecord, ...]
    sim_config: SimConfig
    notes: tuple[str, ...] = ()
    prior: PriorRanges = EVERYDAY_PRIOR


def _shard_paths(path: Path) -> list[Path]:
    """Shards of a dataset directory, of one shard file, or of an inference run's output
    (its RUN_PUSHES folder)."""
    from pushtoknow.datasets.shards import RUN_PUSHES, SHARD_GLOB, list_shards

    path = Path(path)
    if path.is_file():
        return [path]
    if not path.exists():
        raise IdentificationError(
            f"--pushes {path}: no such dataset directory, inference run or shard file"
        )
    shards = list_shards(path)
    if not shards and (path / RUN_PUSHES).is_dir():
        shards = list_shards(path / RUN_PUSHES)
    if not shards:
        raise IdentificationError(
            f"--pushes {path}: empty dataset (no {SHARD_GLOB} files, nor an inference run's "
            f"{RUN_PUSHES}/ folder)"
        )
    return shards


def recorded_clock(sim_config: SimConfig, time_scales, where: str) -> SimConfig:
    """The settings to replay pushes on the clock they were recorded on. A push time-rescaled
    by s (`import-mit --as-speed`: its samples relabelled k / r, r the stored rate) is the
    recording sampled at r·s Hz, so it is replayed at that rate. The pushes must share one s;
    raises IdentificationError naming `where` otherwise."""
    scales = sorted({round(float(s), 9) for s in time_scales})
    if len(scales) > 1:
        raise IdentificationError(
            f"{where}: pushes with different time scales {scales}: identify needs one "
            "recorded clock (import them separately)"
        )
    if not scales or scales[0] == 1.0:
        return sim_config
    tactile = sim_config.tactile.model_copy(
        update={"rate_hz": sim_config.tactile.rate_hz * scales[0]}
    )
    return sim_config.model_copy(update={"tactile": tactile})


def _fits_physics(rate: float, sim_config: SimConfig) -> bool:
    """Whether a sample period 1 / rate is a whole number of the testbed's physics steps."""
    steps = 1.0 / (rate * sim_config.physics.timestep)
    return abs(steps - round(steps)) < 1e-6 and round(steps) >= 1


def recording_object(path: Path, meta: RecordingMeta, records: list[PushRecord]) -> RecordedObject:
    """The object of a recording or bag read as (meta, records). Its settings are the
    testbed's with the recording's clock (meta.rate), pad radius and force noise (0: unknown),
    and a push length (horizon) that fits the pushes `identify` replays with their speed
    profile; those must share one length (IdentificationError naming the push otherwise)."""

    base = SimConfig()
    rate = float(meta.rate)
    if not _fits_physics(rate, base):
        raise IdentificationError(
            f"{path}: a {rate:g} Hz clock is not a whole number of {base.physics.timestep} s "
            "physics steps; resample it (e.g. rate 10 Hz)"
        )

    def settings(samples: int) -> SimConfig:
        return base.model_copy(
            update={
                "pad": base.pad.model_copy(
                    update={
                        "radius": float(meta.pusher_radius),
                        "friction": float(meta.pusher_friction),
                    }
                ),
                "tactile": base.tactile.model_copy(
                    update={"rate_hz": rate, "force_noise_std": float(meta.force_noise_std or 0.0)}
                ),
                "push": base.push.model_copy(update={"horizon": (samples - 1) / rate}),
            }
        )

    # the longest push sets the horizon: a push following its profile over it is replayed with
    # the profile, any other along its recorded pad track (`fit.tracks_from_records`)
    sim = settings(max(len(r.time) for r in records))
    truth = np.asarray(meta.truth, dtype=np.float64)
    shape = None
    if meta.outline is not None:
        shape = {"type": "polygon", "vertices": np.asarray(meta.outline).tolist()}
    return RecordedObject(
        name=meta.name,
        index=0,
        shape=shape,
        height=float(meta.height),
        truth=None if np.isnan(truth).all() else truth,
        records=tuple(records),
        sim_config=sim,
        notes=meta.notes,
    )


def load_recorded_objects(
    path: Path, bag: BagOptions | None = None, images: bool = False
) -> list[RecordedObject]:
    """Every object of a dataset directory (or one shard file), pushes without images (S_0
    kept) unless `images`; or the one object of a recording file (`datasets.recording`; its
    clock resampled to the testbed's 10 Hz, with a note, when its period is not a whole number
    of physics steps) or of a ROS 2 bag / MCAP file (`datasets.mcap_reader`, mapped by `bag`,
    default topics without). Raises DatasetError / IdentificationError naming the problem."""
    from pushtoknow.datasets.mcap_reader import is_bag, read_bag
    from pushtoknow.datasets.mit_import import TIME_SCALE_ATTR
    from pushtoknow.datasets.recording import is_recording, read_recording
    from pushtoknow.datasets.shards import open_shard, read_push

    path = Path(path)
    if is_bag(path):
        return [recording_object(path, *read_bag(path, bag))]
    if bag is not None:
        raise IdentificationError(
            f"--pushes {path}: topic options apply to ROS 2 bags and MCAP files only"
        )
    if is_recording(path):
        meta, records = read_recording(path, images=images)
        if not _fits_physics(float(meta.rate), SimConfig()):
            rate = SimConfig().tactile.rate_hz
            meta, records = read_recording(path, rate=rate, images=images)
        return [recording_object(path, meta, records)]
    out = []
    for shard in _shard_paths(path):
        with open_shard(shard) as f:
            sim_config = stored_sim_config(f.attrs.get("sim_config"))
            for key in sorted(f["objects"], key=int):
                g = f["objects"][key]
                try:
                    d = json.loads(g.attrs["spec"])
                    pushes = g["pushes"]
                except (KeyError, json.JSONDecodeError) as e:
                    raise DatasetError(
                        shard, f"object {key}: no readable spec or pushes ({e})"
                    ) from None
                truth = (
                    np.asarray(g.attrs["params"], dtype=np.float64) if "params" in g.attrs else None
                )
                keys = sorted(pushes, key=int)
                records = tuple(read_push(shard, pushes[k], images=images) for k in keys)
                scales = [float(pushes[k].attrs.get(TIME_SCALE_ATTR, 1.0)) for k in keys]
                shape = d.get("shape")
                out.append(
                    RecordedObject(
                        name=str(d.get("name", f"object {key}")),
                        index=int(g.attrs.get("object_index", key)),
                        shape=resolve_shape(recentred_legacy_shape(shape))
                        if shape is not None
                        else None,
                        height=float(d.get("height", 0.013)),
                        truth=truth,
                        records=records,
                        sim_config=recorded_clock(sim_config, scales, f"{shard} object {key}"),
                        prior=EVERYDAY_PRIOR
                        if any(TIME_SCALE_ATTR in pushes[k].attrs for k in keys)
                        else generator_prior(d.get("name")),
                    )
                )
    if not out:
        raise IdentificationError(f"--pushes {path}: the dataset holds no objects")
    return out


def parse_shape(text: str) -> dict:
    """A footprint given by the user: a catalogue or novel shape name ("rect1", "pentagon"), an
    inline JSON shape (`{"type": "polygon", ...}`) or object spec (with "shape"), or a JSON/YAML
    file holding either. Returns the shape dict (validated)."""
    if text in CATALOGUE_SHAPES:
        shape = CATALOGUE_SHAPES[text]
    elif text in NOVEL_SHAPES:
        shape = NOVEL_SHAPES[text]
    else:
        if text.lstrip().startswith("{"):
            try:
                data = json.loads(text)
            except json.JSONDecodeError as e:
                raise IdentificationError(f"--shape: not valid JSON ({e})") from None
        else:
            p = Path(text)
            if not p.is_file():
                raise IdentificationError(
                    f"--shape {text!r}: no such file or shape name (shape names: "
                    f"{', '.join([*CATALOGUE_SHAPES, *NOVEL_SHAPES])}; or dataset, from-mask)"
                )
            try:
                data = yaml.safe_load(read_utf8(p))
            except yaml.YAMLError as e:
                raise IdentificationError(f"--shape {text}: not valid JSON/YAML ({e})") from None
            except ValueError as e:  # not UTF-8 text
                raise IdentificationError(f"--shape {text}: {e}") from None
        if isinstance(data, dict) and "shape" in data:
            data = data["shape"]
        shape = resolve_shape(data) if isinstance(data, str) else data
    footprint_from_shape(shape)  # raises ObjectSpecError naming the field
    return shape


def footprint_from_mask(obj: RecordedObject) -> tuple[dict, tuple[float, float]]:
    """The footprint seen in the first push's outline mask (else S_0; camera of the stored
    settings, the object's top at its stored height), traced as the physics filter traces the
    outline it replays (`perception.footprint.replay_shape`: corners sharpened), in the object
    frame of the recorded pose track. Returns (shape dict, frame offset: the polygon's centroid
    in that frame, m)."""
    from pushtoknow.perception.footprint import replay_shape

    rec = obj.records[0]
    mask = rec.s0 if rec.outline_mask is None else rec.outline_mask
    if mask is None or not np.asarray(mask).any():
        raise IdentificationError(f"{obj.name}: no object mask S_0 to estimate the footprint from")
    camera = obj.sim_config.camera.model()
    try:
        return replay_shape(np.asarray(mask, dtype=bool), camera, obj.height, rec.pose[0])
    except (ValueError, ObjectSpecError) as e:
        raise IdentificationError(
            f"{obj.name}: the mask S_0 gives no simple footprint ({e})"
        ) from None


def replay_scene(
    obj: RecordedObject, shape: str = "dataset", stop_at_rest: float = 1e-4
) -> ReplayScene:
    """The scene to identify `obj` in. shape: "dataset" (the footprint stored with the pushes),
    "from-mask" (`footprint_from_mask`) or a footprint for `parse_shape`."""
    sim = obj.sim_config.model_copy(update={"render": False})
    offset = (0.0, 0.0)
    if shape == "dataset":
        if obj.shape is None:
            raise IdentificationError(
                f"{obj.name}: the dataset stores no footprint; pass --shape SHAPE or from-mask"
            )
        fp_shape = obj.shape
    elif shape == "from-mask":
        fp_shape, offset = footprint_from_mask(obj)
    else:
        fp_shape = parse_shape(shape)
    try:
        footprint_from_shape(fp_shape)
    except ObjectSpecError as e:
        raise IdentificationError(f"{obj.name}: unusable footprint ({e})") from None
    return ReplayScene(fp_shape, obj.height, sim, offset, stop_at_rest)
