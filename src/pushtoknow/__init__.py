"""pushtoknow: learn an object's mass, friction, centre of mass and inertia by pushing it.

The Python API (`pushtoknow.api`, its `__all__`): `estimate_simulated`, `estimate_recording`,
`export_object`, `load_model`, `load_object` and the result types `InferenceResult`,
`PushEstimate`; imported on first use, so `import pushtoknow` stays light.

The layers, and which may import which, are stated in docs/DESIGN.md §1 (checked by
tests/test_layers.py and tests/test_import_cycles.py).
"""

from __future__ import annotations

import importlib
from typing import Any

from pushtoknow.common.version import __version__

__all__ = ["__version__"]


def __getattr__(name: str) -> Any:
    api = importlib.import_module("pushtoknow.api")
    if name in api.__all__:
        return getattr(api, name)
    raise AttributeError(f"module 'pushtoknow' has no attribute {name!r}")


def __dir__() -> list[str]:
    return sorted({*globals(), *importlib.import_module("pushtoknow.api").__all__})
