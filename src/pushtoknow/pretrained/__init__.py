"""Models shipped with the package (trained by `scripts/train-pretrained.sh`).

Each lives in its own directory: `model.pt` (the checkpoint), `config.yaml` (the training
config), `training.json` (data seed, provenance, timings, validation numbers) and the
training curves (`*.csv`).
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path

from pushtoknow.common.errors import CheckpointError

DEFAULT_PRETRAINED = "vt-addf"


def pretrained_dir(name: str = DEFAULT_PRETRAINED) -> Path:
    """Directory of the shipped model `name`; `CheckpointError` if the package lacks it."""
    path = Path(str(resources.files("pushtoknow.pretrained"))) / name
    if not (path / "model.pt").exists():
        available = sorted(p.name for p in path.parent.iterdir() if (p / "model.pt").exists())
        raise CheckpointError(
            f"no shipped model {name!r} in {path.parent} (available: {available or 'none'}); "
            "train one with `bash scripts/train-pretrained.sh`"
        )
    return path


def resolve_model_path(model: str) -> Path:
    """`pretrained`, `pretrained:NAME` or a run directory / checkpoint file."""
    if model == "pretrained":
        return pretrained_dir()
    if model.startswith("pretrained:"):
        return pretrained_dir(model.split(":", 1)[1])
    return Path(model)
