"""Named random streams (`common.random`): independent per purpose, reproducible per seed."""

import numpy as np
import pytest
from hypothesis import given
from hypothesis import strategies as st

from pushtoknow.common.random import STREAM_NAMES, stream, stream_seed


@given(st.integers(0, 2**32))
def test_each_purpose_has_its_own_reproducible_sequence(seed):
    draws = {p: stream(seed, p).random(4).tolist() for p in STREAM_NAMES}
    assert draws == {p: stream(seed, p).random(4).tolist() for p in STREAM_NAMES}
    assert len({tuple(d) for d in draws.values()}) == len(STREAM_NAMES)
    # no purpose shares the bare seed's sequence (what every consumer drew before)
    bare = np.random.default_rng(seed).random(4).tolist()
    assert bare not in draws.values()
    seeds = [stream_seed(seed, p) for p in STREAM_NAMES]
    assert len(set(seeds)) == len(seeds) and all(0 <= s < 2**63 for s in seeds)


def test_an_unknown_purpose_is_named():
    with pytest.raises(ValueError, match="^purpose: one of simulator, policy, estimator"):
        stream(0, "noise")  # type: ignore[arg-type]
