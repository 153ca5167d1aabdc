"""Dataset generation: shards, resume, corruption and schema errors, torch Dataset."""

import json

import h5py
import numpy as np
import pytest

from pushtoknow.common.errors import DatasetError, ObjectSpecError
from pushtoknow.datasets.generate import GenerationConfig, generate_dataset, select_objects
from pushtoknow.datasets.shards import dataset_info, open_shard, read_shard, shard_path
from pushtoknow.datasets.torch_dataset import PushDataset
from pushtoknow.testbed.sim_config import PushConfig, SimConfig

# Short pushes keep the tests fast; physics is tested elsewhere.
FAST = SimConfig(push=PushConfig(horizon=2.0))


def cfg(**kw):
    base = {"objects": 3, "pushes": 2, "seed": 1, "objects_per_shard": 2, "sim": FAST}
    return GenerationConfig(**{**base, **kw})


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    out = tmp_path_factory.mktemp("ds")
    generate_dataset(out, cfg(), workers=1, progress=False)
    return out


def test_info_counts(dataset):
    info = dataset_info(dataset)
    assert info.schema_version == 1
    assert info.objects == 3 and info.pushes == 6
    assert info.steps == 6 * 21  # 2 s at 10 Hz + the t = 0 sample
    assert info.shards == 2
    assert list(info.to_json()) == [
        "schema_version", "testbed_version", "path", "shards", "objects", "expected_objects",
        "complete", "pushes", "steps", "profiles", "image_shape", "bytes",
    ]  # fmt: skip


def test_round_trip_matches_direct_simulation(dataset):
    from pushtoknow.datasets.generate import simulate_object

    eps = read_shard(shard_path(dataset, 0))
    specs = select_objects("catalogue", 3, 1)
    direct = simulate_object(specs[1], 1, cfg())
    stored = eps[1]
    assert stored.spec == specs[1]
    for a, b in zip(stored.records, direct.records):
        assert np.array_equal(a.pose, b.pose)
        assert np.array_equal(a.tactile, b.tactile)
        assert np.array_equal(a.rgb, b.rgb)
        assert np.allclose(a.depth, b.depth, atol=1e-3)  # stored as float16
        assert a.push == b.push
        assert a.outline_mask_end is not None
        assert np.array_equal(a.outline_mask_end, b.outline_mask_end)


def test_workers_do_not_change_the_data(tmp_path, dataset):
    generate_dataset(tmp_path, cfg(), workers=2, progress=False)
    for i in range(2):
        a = read_shard(shard_path(tmp_path, i))
        b = read_shard(shard_path(dataset, i))
        for ea, eb in zip(a, b):
            for ra, rb in zip(ea.records, eb.records):
                assert np.array_equal(ra.pose, rb.pose) and np.array_equal(ra.rgb, rb.rgb)


def test_resume_skips_finished_shards(tmp_path):
    generate_dataset(tmp_path, cfg(), progress=False)
    first = shard_path(tmp_path, 0)
    mtime = first.stat().st_mtime_ns
    shard_path(tmp_path, 1).unlink()  # as if interrupted before the second shard landed
    (tmp_path / "shard-00001.h5.tmp").write_bytes(b"partial")
    res = generate_dataset(tmp_path, cfg(), progress=False)
    assert (res.shards_written, res.shards_skipped, res.objects) == (1, 1, 3)
    assert res.to_json() == {"shards_written": 1, "shards_skipped": 1, "objects": 3}
    assert first.stat().st_mtime_ns == mtime
    assert not list(tmp_path.glob("*.tmp"))
    assert dataset_info(tmp_path).pushes == 6


def test_resume_with_other_settings_is_refused(tmp_path):
    generate_dataset(tmp_path, cfg(), progress=False)
    with pytest.raises(DatasetError, match="other settings"):
        generate_dataset(tmp_path, cfg(seed=2), progress=False)


def test_corrupt_shard_error_names_file(tmp_path, dataset):
    bad = tmp_path / "shard-00000.h5"
    bad.write_bytes(b"\x89HDF garbage" * 10)
    with pytest.raises(DatasetError, match="shard-00000.h5"):
        dataset_info(tmp_path)


def test_wrong_schema_version_error_names_file(tmp_path, dataset):
    import shutil

    p = tmp_path / "shard-00000.h5"
    shutil.copy(shard_path(dataset, 0), p)
    with h5py.File(p, "a") as f:
        f.attrs["schema_version"] = 99
    with pytest.raises(DatasetError, match=r"shard-00000.h5.*schema version 99"):
        open_shard(p)


def test_missing_dataset_in_shard(tmp_path, dataset):
    import shutil

    p = tmp_path / "shard-00000.h5"
    shutil.copy(shard_path(dataset, 0), p)
    with h5py.File(p, "a") as f:
        del f["objects/0/pushes/0/pose"]
    with pytest.raises(DatasetError, match="pose"):
        read_shard(p)


def test_torch_dataset_items(dataset):
    ds = PushDataset(dataset)
    assert len(ds) == 6
    item = ds[3]
    assert item["rgb"].shape == (21, 3, 64, 64) and item["rgb"].max() <= 1.0
    assert item["depth"].shape == (21, 1, 64, 64)
    assert item["pose"].shape == (21, 3) and item["tactile"].shape == (21, 3)
    assert item["params_norm"].abs().max() <= 1.0 + 1e-6
    import torch

    loader = torch.utils.data.DataLoader(ds, batch_size=2, num_workers=0)
    batch = next(iter(loader))
    assert batch["s0"].shape == (2, 1, 64, 64)


def test_objects_from_file(tmp_path):
    f = tmp_path / "objs.yaml"
    f.write_text(
        json.dumps(
            {
                "objects": [
                    "catalogue:3",
                    {
                        "shape": "hex",
                        "mass": 0.3,
                        "friction": 0.4,
                        "com": [0, 0],
                        "inertia": 0.4e-3,
                    },
                ]
            }
        )
    )
    specs = select_objects(str(f), 2, 0)
    assert specs[1].shape == "hex"
    with pytest.raises(ValueError, match="exceeds"):
        select_objects(str(f), 3, 0)


def test_verify_counts_intact_shards(dataset):
    info = dataset_info(dataset, verify=True)
    assert info.verified_shards == info.shards == 2
    plain = dataset_info(dataset)
    assert plain.verified_shards is None and "verified_shards" not in plain.to_json()


def _flip_byte_in(path, dataset_name: str) -> None:
    """Corrupt one byte inside a dataset's stored (checksummed) chunk."""
    with h5py.File(path, "r") as f:
        offset = f[dataset_name].id.get_chunk_info(0).byte_offset
    with open(path, "r+b") as fh:
        fh.seek(offset + 3)
        b = fh.read(1)
        fh.seek(offset + 3)
        fh.write(bytes([b[0] ^ 0xFF]))


@pytest.mark.parametrize("where", ["bytes", "attribute"])
def test_corruption_inside_a_shard_is_found_by_verify_and_resume(tmp_path, dataset, where):
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    bad = shard_path(copy, 1)
    if where == "bytes":
        _flip_byte_in(bad, "objects/2/pushes/1/pose")
    else:
        with h5py.File(bad, "a") as f:
            f["objects/2"].attrs["params"] = f["objects/2"].attrs["params"] * 1.01
    dataset_info(copy)  # a summary does not read the arrays
    with pytest.raises(DatasetError, match="shard-00001.h5") as e:
        dataset_info(copy, verify=True)
    assert ("digest" in str(e.value)) or ("pose" in str(e.value))
    before = bad.read_bytes()
    with pytest.raises(DatasetError, match="shard-00001.h5"):
        generate_dataset(copy, cfg(), progress=False)  # resume refuses to build on it
    assert bad.read_bytes() == before  # and leaves it as it was


def test_a_refused_resume_writes_no_provenance_record(tmp_path, dataset):
    """Without its generation.json, a folder's shards decide: a run with other settings is
    refused before it writes a record of its own (which would then refuse the original run)."""
    import shutil

    copy = tmp_path / "ds"
    shutil.copytree(dataset, copy)
    (copy / "generation.json").unlink()
    with pytest.raises(DatasetError, match="other settings"):
        generate_dataset(copy, cfg(seed=2), progress=False)
    assert not (copy / "generation.json").exists()
    assert generate_dataset(copy, cfg(), progress=False).shards_skipped == 2
    info = dataset_info(copy, verify=True)
    assert info.verified_shards == 2


def test_novel_objects_are_the_evaluations_kind():
    """`--objects-from novel`: the evaluation's novel objects for the seed, unseen shapes among
    them, each a valid object with continuous parameters."""
    from pushtoknow.testbed.objects import NOVEL_SHAPES, novel_objects

    specs = select_objects("novel", 6, 23)
    assert [s.to_dict() for s in specs] == [s.to_dict() for s in novel_objects(6, 23)]
    assert any(s.name.split(":")[-1] in NOVEL_SHAPES for s in specs)
    assert specs != select_objects("novel", 6, 24)
    with pytest.raises(ObjectSpecError, match="'novel'"):
        select_objects("novle", 2, 0)


def test_random_objects_for_the_dataset_seed_or_their_own():
    """`--objects-from random` draws the random-shape objects of the dataset's seed,
    `random:SEED` those of SEED; anything else after `random:` is refused in one line."""
    from pushtoknow.testbed.random_shapes import random_objects

    assert [s.to_dict() for s in select_objects("random", 3, 5)] == [
        s.to_dict() for s in random_objects(3, 5)
    ]
    assert select_objects("random:9", 3, 5) == random_objects(3, 9)
    for bad in ("random:", "random:x", "random:-1", "random:1:2"):
        with pytest.raises(ObjectSpecError, match="random:SEED needs"):
            select_objects(bad, 2, 0)


def test_sources_joined_by_plus_take_turns():
    """`A+B+C` takes its objects from each source in turn, each source's objects its own first
    ones for the seed; the shipped recipe's `catalogue-train+continuous` is the two-source case
    (its first object the catalogue's, its second a continuous one)."""
    from pushtoknow.testbed.random_shapes import random_objects

    def dicts(specs):
        return [s.to_dict() for s in specs]

    got = select_objects("catalogue-train+continuous+random:7", 7, 3)
    assert dicts(got[0::3]) == dicts(select_objects("catalogue-train", 3, 3))
    assert dicts(got[1::3]) == dicts(select_objects("continuous", 2, 3))
    assert dicts(got[2::3]) == dicts(random_objects(2, 7))
    pair = select_objects("catalogue-train+continuous", 5, 3)
    assert dicts(pair[0::2]) == dicts(select_objects("catalogue-train", 3, 3))
    assert dicts(pair[1::2]) == dicts(select_objects("continuous", 2, 3))
    assert GenerationConfig(objects_from="continuous+random:7").fingerprint()  # not a file
    with pytest.raises(ObjectSpecError, match="continuous\\+nothing"):
        select_objects("continuous+nothing", 2, 0)
