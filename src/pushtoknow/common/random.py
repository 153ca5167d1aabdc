"""Named random streams: one seed, one independent generator per purpose (docs/DESIGN.md §2).

A run's seed never feeds two consumers the same sequence: the simulator (object placement,
sensor noise), the push policy (candidates and choices) and the estimator (its sigma-point
draws) each draw from their own stream, `numpy.random.SeedSequence(seed)`'s child with the
purpose's fixed spawn key. Same seed and purpose, same stream; adding a purpose changes none of
the others.
"""

from __future__ import annotations

from typing import Literal, get_args

import numpy as np

StreamName = Literal["simulator", "policy", "estimator"]
STREAM_NAMES: tuple[str, ...] = get_args(StreamName)  # the spawn key is the index: append only


def _sequence(seed: int, purpose: StreamName) -> np.random.SeedSequence:
    if purpose not in STREAM_NAMES:
        raise ValueError(f"purpose: one of {', '.join(STREAM_NAMES)}, not {purpose!r}")
    return np.random.SeedSequence(int(seed), spawn_key=(STREAM_NAMES.index(purpose),))


def stream(seed: int, purpose: StreamName) -> np.random.Generator:
    """The generator of `purpose` under `seed` (≥ 0)."""
    return np.random.default_rng(_sequence(seed, purpose))


def stream_seed(seed: int, purpose: StreamName) -> int:
    """An integer seed in [0, 2⁶³) of `purpose` under `seed`, for consumers that take one (a
    `torch.Generator`, an executor)."""
    return int(_sequence(seed, purpose).generate_state(1, dtype=np.uint64)[0] >> np.uint64(1))
