"""A torch `Dataset` over HDF5 shards: one item per push."""

from __future__ import annotations

from pathlib import Path

import h5py
import numpy as np
import torch
from torch.utils.data import Dataset

from pushtoknow.common.params import normalise_params
from pushtoknow.datasets.shards import list_shards, open_shard, read_push


class PushDataset(Dataset):
    """Items are dicts of tensors for one push (T samples, H × W images):

    rgb (T, 3, H, W) float32 in [0, 1] · depth (T, 1, H, W) m · s0 (1, H, W) float32
    pose (T, 3) · tactile (T, 3) · pusher (T, 2) · time (T,) · action (5,)
    params (5,) SI · params_norm (5,) in [-1, 1] · object_index () int64

    Files are opened lazily in each worker process (h5py handles do not survive a fork).
    """

    def __init__(self, root: str | Path, images: bool = True):
        self.root = Path(root)
        self.images = images
        self.index: list[tuple[Path, str, str]] = []
        for s in list_shards(self.root):
            with open_shard(s) as f:
                for ok, g in f["objects"].items():
                    for pk in g["pushes"]:
                        self.index.append((s, ok, pk))
        self._files: dict[Path, h5py.File] = {}

    def __len__(self) -> int:
        return len(self.index)

    def _file(self, path: Path) -> h5py.File:
        if path not in self._files:
            self._files[path] = open_shard(path)
        return self._files[path]

    def __getitem__(self, i: int) -> dict[str, torch.Tensor]:
        path, ok, pk = self.index[i]
        g = self._file(path)["objects"][ok]
        r = read_push(path, g["pushes"][pk], images=self.images)
        params = np.asarray(g.attrs["params"], dtype=np.float64)
        item = {
            "pose": torch.as_tensor(r.pose, dtype=torch.float32),
            "tactile": torch.as_tensor(r.tactile, dtype=torch.float32),
            "pusher": torch.as_tensor(r.pusher, dtype=torch.float32),
            "time": torch.as_tensor(r.time, dtype=torch.float32),
            "action": torch.as_tensor(r.push.as_array(), dtype=torch.float32),
            "s0": torch.as_tensor(r.s0, dtype=torch.float32)[None],
            "params": torch.as_tensor(params, dtype=torch.float32),
            "params_norm": torch.as_tensor(normalise_params(params), dtype=torch.float32),
            "object_index": torch.tensor(int(g.attrs["object_index"])),
        }
        if self.images:
            item["rgb"] = torch.as_tensor(r.rgb).permute(0, 3, 1, 2).float() / 255.0
            item["depth"] = torch.as_tensor(r.depth)[:, None]
        return item

    def __getstate__(self):
        state = self.__dict__.copy()
        state["_files"] = {}
        return state
