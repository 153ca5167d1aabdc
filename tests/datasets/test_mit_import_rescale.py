"""`import_mit_dataset(as_speed=...)`: time rescaling of MIT pushes to the training speed."""

from __future__ import annotations

import json
from pathlib import Path

import h5py
import numpy as np
import pytest

from pushtoknow.common.errors import DatasetError
from pushtoknow.datasets.mit_import import (
    IMPORT_FILE,
    TIME_SCALE_CONVENTION,
    import_mit_dataset,
)
from pushtoknow.datasets.shards import read_shard, shard_path

SAMPLE_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets" / "mit-push-sample"


@pytest.fixture(scope="module")
def sample_dir() -> Path:
    if not SAMPLE_DIR.is_dir():
        pytest.skip(f"MIT Push sample files not found at {SAMPLE_DIR} (real-data tests skipped)")
    return SAMPLE_DIR.resolve()


@pytest.fixture(scope="module")
def imports(sample_dir, tmp_path_factory):
    plain = tmp_path_factory.mktemp("plain")
    slow = tmp_path_factory.mktemp("as20")
    import_mit_dataset(sample_dir, plain, progress=False)
    import_mit_dataset(sample_dir, slow, as_speed=0.02, progress=False)
    return plain, slow


def test_rescaled_push_is_the_same_path_at_the_training_speed(imports):
    plain, slow = imports
    (ep0,) = read_shard(shard_path(plain, 0))
    (ep1,) = read_shard(shard_path(slow, 0))
    for a, b in zip(ep0.records, ep1.records, strict=True):
        assert a.push.speed == 0.1 and b.push.speed == pytest.approx(0.02)
        # 5× the samples, still 10 Hz labels: the push lasts 5× longer.
        assert len(b.time) >= 5 * len(a.time) - 5
        np.testing.assert_allclose(b.time, np.arange(len(b.time)) / 10.0, atol=1e-12)
        # Sample 5k of the rescaled push is recorded time k/10: the same pose and pusher.
        k = np.arange(len(a.time))
        k = k[5 * k < len(b.time)]
        np.testing.assert_allclose(b.pose[5 * k], a.pose[k], atol=1e-9)
        np.testing.assert_allclose(b.pusher[5 * k], a.pusher[k], atol=1e-9)
        # Pusher displacement per sample: ≤ 2 mm (20 mm/s at 10 Hz) instead of ≤ 10 mm.
        assert np.linalg.norm(np.diff(b.pusher, axis=0), axis=1).max() < 0.0025
        assert np.linalg.norm(np.diff(a.pusher, axis=0), axis=1).max() > 0.009
        # The action's geometry is unchanged.
        assert b.push.direction == pytest.approx(a.push.direction, abs=0.01)
        np.testing.assert_allclose(b.push.contact, a.push.contact, atol=1e-3)
        # Forces keep their size (time averages over shorter windows).
        fa = np.linalg.norm(a.tactile[:, :2], axis=1)
        fb = np.linalg.norm(b.tactile[:, :2], axis=1)
        assert fb.max() >= fa.max() and fa.max() > 1.5


def test_rescaling_is_recorded_and_default_unchanged(imports, sample_dir, tmp_path):
    plain, slow = imports
    info0 = json.loads((plain / IMPORT_FILE).read_text())
    info1 = json.loads((slow / IMPORT_FILE).read_text())
    assert "as_speed_m_per_s" not in info0 and "time_scale_convention" not in info0
    assert info1["as_speed_m_per_s"] == 0.02
    assert info1["time_scale_convention"] == TIME_SCALE_CONVENTION
    assert info0["fingerprint"] != info1["fingerprint"]
    for d, scale in ((plain, 1.0), (slow, 5.0)):
        with h5py.File(shard_path(d, 0)) as f:
            for p in f["objects/0/pushes"].values():
                assert p.attrs["mit_time_scale"] == pytest.approx(scale)
                assert json.loads(p.attrs["mit_meta"])["speed_m_per_s"] == 0.1  # the file's
    # Re-running with the other setting into the same directory is refused.
    with pytest.raises(DatasetError, match="other files or settings"):
        import_mit_dataset(sample_dir, plain, as_speed=0.02, progress=False)
    with pytest.raises(ValueError, match="as_speed"):
        import_mit_dataset(sample_dir, tmp_path / "x", as_speed=0.0, progress=False)
