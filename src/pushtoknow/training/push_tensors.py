"""Pushes of a dataset as tensors for training and evaluation.

Everything the filter needs per push, images excepted (VisNet turns them into poses first):
S_0, the object-frame footprint polygon seen before the push (`perception.footprint.
footprint_seen`), poses, tactile, pusher track, the action and the true parameters.
"""

from __future__ import annotations

from dataclasses import dataclass, fields
from pathlib import Path

import numpy as np
import torch

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import normalise_params
from pushtoknow.datasets.shards import list_shards, open_shard
from pushtoknow.perception.footprint import footprint_seen
from pushtoknow.testbed.push import Push, release_point
from pushtoknow.testbed.sim_config import SimConfig, stored_sim_config


@dataclass
class PushTensors:
    """N pushes of T samples (float32 unless said).

    mask0 (N, 1, H, W) · pose (N, T, 3) true · tactile (N, T, 3)
    pusher (N, T, 2) · action (N, 5) · params (N, 5) SI (float64) · params_norm (N, 5)
    footprint (N, V, 2) seen before the push
    release (N, 3) each push's `testbed.push.release_point`
    · object_index (N,) int64
    push_index (N,) int64 (order within its object) · vision_pose (N, T, 3) or None
    step_dt: time between samples (s)
    """

    mask0: torch.Tensor
    pose: torch.Tensor
    tactile: torch.Tensor
    pusher: torch.Tensor
    action: torch.Tensor
    params: torch.Tensor
    params_norm: torch.Tensor
    footprint: torch.Tensor
    release: torch.Tensor
    object_index: torch.Tensor
    push_index: torch.Tensor
    camera: CameraModel
    horizon_steps: int
    vision_pose: torch.Tensor | None = None
    step_dt: float = 0.1

    def __len__(self) -> int:
        return self.pose.shape[0]

    def subset(self, idx) -> PushTensors:
        idx = torch.as_tensor(idx, dtype=torch.long)
        out = {}
        for f in fields(self):
            v = getattr(self, f.name)
            out[f.name] = v[idx] if isinstance(v, torch.Tensor) else v
        return PushTensors(**out)


def dataset_camera(root: Path) -> tuple[CameraModel, SimConfig]:
    shards = list_shards(root)
    if not shards:
        raise DatasetError(root, "no shards")
    with open_shard(shards[0]) as f:
        cfg = stored_sim_config(f.attrs["sim_config"])
    return cfg.camera.model(), cfg


def load_push_tensors(root: Path, max_objects: int | None = None) -> PushTensors:
    """Read every push of a dataset (without images) into a `PushTensors`."""
    root = Path(root)
    camera, sim_config = dataset_camera(root)
    cols: dict[str, list] = {
        k: []
        for k in (
            "mask0",
            "pose",
            "tactile",
            "pusher",
            "action",
            "params",
            "footprint",
            "object_index",
            "push_index",
        )
    }
    n_obj = 0
    for s in list_shards(root):
        with open_shard(s) as f:
            for okey in sorted(f["objects"], key=int):
                if max_objects is not None and n_obj >= max_objects:
                    break
                g = f["objects"][okey]
                n_obj += 1
                params = np.asarray(g.attrs["params"], np.float64)
                for pk in sorted(g["pushes"], key=int):
                    p = g["pushes"][pk]
                    s0 = p["s0"][()]
                    pose = p["pose"][()]
                    outline = p["outline_mask"][()] if "outline_mask" in p else None
                    fp = footprint_seen(s0, p["depth"][0], outline, camera, pose[0])
                    cols["mask0"].append(s0[None].astype(np.float32))
                    cols["pose"].append(pose)
                    cols["tactile"].append(p["tactile"][()])
                    cols["pusher"].append(p["pusher"][()])
                    cols["action"].append(np.asarray(p.attrs["action"]))
                    cols["params"].append(params)
                    cols["footprint"].append(fp)
                    cols["object_index"].append(int(g.attrs["object_index"]))
                    cols["push_index"].append(int(pk))
    if not cols["pose"]:
        raise DatasetError(root, "no pushes")
    lengths = {len(x) for x in cols["pose"]}
    if len(lengths) != 1:
        raise DatasetError(root, f"pushes of different lengths {sorted(lengths)}")
    f32 = {
        k: torch.as_tensor(np.stack(cols[k]), dtype=torch.float32)
        for k in ("mask0", "pose", "tactile", "pusher", "action", "footprint")
    }
    params = torch.as_tensor(np.stack(cols["params"]), dtype=torch.float64)
    release = [release_point(Push.from_array(a), sim_config.push) for a in cols["action"]]
    return PushTensors(
        **f32,
        release=torch.tensor(release, dtype=torch.float32),
        params=params,
        params_norm=normalise_params(params).float(),
        object_index=torch.as_tensor(cols["object_index"]),
        push_index=torch.as_tensor(cols["push_index"]),
        camera=camera,
        horizon_steps=lengths.pop(),
        step_dt=1.0 / sim_config.tactile.rate_hz,
    )


def iter_push_groups(root: Path, max_objects: int | None = None):
    """The HDF5 push groups of a dataset, in the order of `load_push_tensors` (shards sorted,
    objects and pushes by index)."""
    n_obj = 0
    for s in list_shards(root):
        with open_shard(s) as f:
            for okey in sorted(f["objects"], key=int):
                if max_objects is not None and n_obj >= max_objects:
                    return
                n_obj += 1
                pushes = f["objects"][okey]["pushes"]
                for pk in sorted(pushes, key=int):
                    yield pushes[pk]


def load_frames(root: Path, every: int = 5, max_objects: int | None = None):
    """Image frames for VisNet: every `every`-th frame of each push.

    Returns VisNet inputs rgbd (F, 4, H, W) (`perception.visnet.rgbd_input`), mask0 (F, 1, H, W),
    pose (F, 3), pose0 (F, 3), push id (F,).
    """
    from pushtoknow.perception.visnet import frames_as_tensors

    rgbd, mask0, pose, pose0, pid = [], [], [], [], []
    camera, _ = dataset_camera(root)
    for push, p in enumerate(iter_push_groups(root, max_objects)):
        ps = p["pose"][()]
        idx = np.arange(0, len(ps), every)
        rgbd.append(frames_as_tensors(p["rgb"][()][idx], p["depth"][()][idx], camera).numpy())
        s0 = p["s0"][()].astype(np.float32)
        mask0.append(np.repeat(s0[None, None], len(idx), 0))
        pose.append(ps[idx])
        pose0.append(np.repeat(ps[:1], len(idx), 0))
        pid += [push] * len(idx)
    t = lambda xs: torch.as_tensor(np.concatenate(xs), dtype=torch.float32)  # noqa: E731
    return t(rgbd), t(mask0), t(pose), t(pose0), torch.as_tensor(pid)


def compute_vision_poses(
    root: Path, measure, max_objects: int | None = None, progress=None
) -> torch.Tensor:
    """VisNet poses (N, T, 3) of every frame of every push, in `load_push_tensors` order.

    measure(rgbd (T, 4, H, W), mask0 (T, 1, H, W), pose (T, 3) true, pose0 (T, 3)) → (T, 3):
    the caller's VisNet measurement (its reference pose derived from the truth, e.g. perturbed).
    """
    from pushtoknow.perception.visnet import frames_as_tensors

    camera, _ = dataset_camera(root)
    out = []
    for p in iter_push_groups(root, max_objects):
        pose = torch.as_tensor(p["pose"][()], dtype=torch.float32)
        rgbd = frames_as_tensors(p["rgb"][()], p["depth"][()], camera)
        s0 = torch.as_tensor(p["s0"][()], dtype=torch.float32)[None, None]
        n = len(pose)
        out.append(measure(rgbd, s0.expand(n, -1, -1, -1), pose, pose[:1].expand(n, -1)))
        if progress is not None:
            progress()
    return torch.stack(out)
