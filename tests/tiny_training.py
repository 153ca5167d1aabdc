"""One tiny dataset and one tiny trained run shared by the training, inference and CLI tests
(helpers, not tests; `tests/` is on sys.path via the root conftest).

Built at most once per test process (session cache) under pytest's tmp_path_factory:
6 training-catalogue objects × 2 pushes of 2 s (21 samples each), and a vt-addf run with
networks a few units wide and a handful of optimisation steps per stage (≈ 3 s).
"""

from __future__ import annotations

from pathlib import Path

from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
from pushtoknow.testbed.sim_config import PushConfig, SimConfig
from pushtoknow.training.pipeline import TrainConfig, train_model

HORIZON_S = 2.0
SIM = SimConfig(push=PushConfig(horizon=HORIZON_S))
DATA_OBJECTS, DATA_PUSHES, DATA_SEED = 6, 2, 3
SIGMA_POINTS = 20

# Smallest networks that keep every stage meaningful; everything else at the defaults.
TINY_MODELS = {
    "encoder": {"image_size": 32, "channels": [4, 4, 4], "hidden_dim": 16, "out_dim": 8},
    "process": {"enc_dim": 8, "hidden_dims": [16, 16]},
    "tac": {"enc_dim": 8, "hidden_dims": [16, 16, 16]},
    "obs_noise": {"hidden_dim": 8},
}
TINY_TRAIN = {
    "visnet": {
        "epochs": 1,
        "frame_every": 5,
        "batch_size": 32,
        "net": {
            "in_channels": 6,
            "image_size": 32,
            "channels": [4, 4],
            "kernel_sizes": [3, 3],
            "strides": [2, 2],
            "hidden_dims": [16, 16],
        },
    },
    "models": TINY_MODELS,
    "supervised": {"steps": 5, "log_every": 5, "batch_size": 16},
    "end_to_end": {
        "steps": 2,
        "val_every": 1,
        "val_pushes": 2,
        "window": 3,
        "batch_size": 2,
        "num_sigma_points": SIGMA_POINTS,
        "val_num_sigma_points": SIGMA_POINTS,
    },
    "calibration": {
        "noise_scales": [1.0, 4.0],
        "update_every": [1],
        "val_pushes": 2,
        "num_sigma_points": SIGMA_POINTS,
    },
    "sequence_calibration": {"weights": [0.0, 1.0], "num_sigma_points": SIGMA_POINTS},
    "inference_sigma_points": SIGMA_POINTS,
}
TINY_CALIBRATION_GRID = 2  # rows of calibration.csv (and of sequence_calibration.csv)

_cache: dict[str, Path] = {}


def tiny_train_config() -> TrainConfig:
    return TrainConfig.model_validate(TINY_TRAIN)


def tiny_dataset(tmp_path_factory) -> Path:
    if "data" not in _cache:
        out = tmp_path_factory.mktemp("tiny-data")
        cfg = GenerationConfig(
            objects=DATA_OBJECTS,
            pushes=DATA_PUSHES,
            seed=DATA_SEED,
            objects_from="catalogue-train",
            sim=SIM,
            profiles=("constant", "release"),  # the tiny model may be asked for either
        )
        generate_dataset(out, cfg, workers=1, progress=False)
        _cache["data"] = out
    return _cache["data"]


def tiny_run(tmp_path_factory) -> Path:
    """Run directory of `train_model` (vt-addf, seed 0) on `tiny_dataset`."""
    if "run" not in _cache:
        data = tiny_dataset(tmp_path_factory)
        out = tmp_path_factory.mktemp("tiny-run")
        train_model(data, out, tiny_train_config(), seed=0, progress=False)
        _cache["run"] = out
    return _cache["run"]
