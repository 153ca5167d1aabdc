"""`pushtoknow collect` (training data pushed by a policy with the current model) and
`combine_datasets` (training on several dataset directories together)."""

import json

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.collection.collect import (
    collect_dataset,
    combine_datasets,
    dataset_policies,
    file_sha256,
)
from pushtoknow.common.errors import DatasetError
from pushtoknow.datasets.generate import GENERATION_FILE, GenerationConfig, generate_dataset
from pushtoknow.datasets.shards import dataset_info, list_shards, read_shard
from pushtoknow.testbed.sim_config import PushConfig, SimConfig
from pushtoknow.training.pipeline import train_model
from pushtoknow.training.push_tensors import load_push_tensors
from tiny_training import DATA_OBJECTS, DATA_PUSHES, DATA_SEED, SIGMA_POINTS, tiny_train_config

FIRST = DATA_OBJECTS  # collected objects continue the tiny dataset's seeded order


def collect(out, run, policy, objects=2, pushes=2, seed=DATA_SEED, workers=1, **kw):
    kw.setdefault("num_sigma_points", SIGMA_POINTS)
    kw.setdefault("candidates", 4)
    return collect_dataset(
        out, run, policy, "catalogue-train", objects, pushes, seed, workers, FIRST,
        progress=False, **kw,
    )  # fmt: skip


def episodes(root):
    return [ep for s in list_shards(root) for ep in read_shard(s, images=False)]


def actions(root):
    return [[r.push.as_array() for r in ep.records] for ep in episodes(root)]


@pytest.fixture(scope="module")
def uniform_data(tmp_path_factory, tiny_run_dir):
    out = tmp_path_factory.mktemp("collect") / "uniform"
    res = collect(out, tiny_run_dir, "uniform", objects=3)
    return out, res


def test_collected_shards_read_back(uniform_data, tiny_run_dir, tiny_data):
    out, res = uniform_data
    assert res["shards_written"] == 1 and res["shards_skipped"] == 0
    info = dataset_info(out)
    assert (info.objects, info.pushes) == (3, 6)
    eps = episodes(out)
    assert [ep.object_index for ep in eps] == [FIRST, FIRST + 1, FIRST + 2]
    assert all(len(ep.records) == 2 for ep in eps)
    # the model's testbed settings: 2 s pushes at 10 Hz
    assert {len(r.time) for ep in eps for r in ep.records} == {21}
    # provenance: the policy and the model, in generation.json and in every shard
    gen = json.loads((out / GENERATION_FILE).read_text())
    sha = file_sha256(tiny_run_dir / "model.pt")
    assert gen["kind"] == "collect"
    assert gen["config"]["policy"] == "uniform" and gen["config"]["model_sha256"] == sha
    assert gen["config"]["model"] == str(tiny_run_dir) and gen["config"]["seed"] == DATA_SEED
    assert dataset_policies(out) == {"uniform": 6}
    with h5py.File(list_shards(out)[0], "r") as f:
        assert f.attrs["collection_policy"] == "uniform" and f.attrs["model_sha256"] == sha
    # the objects continue the order of `simulate` with the same seed and source
    simulated = [ep.spec.name for ep in episodes(tiny_data)]
    from pushtoknow.datasets.generate import select_objects

    order = [s.name for s in select_objects("catalogue-train", FIRST + 3, DATA_SEED)]
    assert order[:FIRST] == simulated
    assert [ep.spec.name for ep in eps] == order[FIRST:]


def test_collection_resumes_and_refuses_other_settings(uniform_data, tiny_run_dir):
    out, _ = uniform_data
    again = collect(out, tiny_run_dir, "uniform", objects=3)
    assert again["shards_written"] == 0 and again["shards_skipped"] == 1
    with pytest.raises(DatasetError, match="other settings, policy or model"):
        collect(out, tiny_run_dir, "random", objects=3)


def test_active_collection_same_seed_same_actions_any_workers(tmp_path, tiny_run_dir):
    """Active selection with a tiny model; object-seeded: 2 processes (one object per shard)
    give the same pushes and data as 1; another seed gives other pushes."""
    a = collect(tmp_path / "a", tiny_run_dir, "active-entropy", objects_per_shard=1)
    b = collect(tmp_path / "b", tiny_run_dir, "active-entropy", objects_per_shard=1, workers=2)
    assert a["shards_written"] == b["shards_written"] == 2
    assert dataset_policies(tmp_path / "b") == {"active-entropy": 4}
    ea, eb = episodes(tmp_path / "a"), episodes(tmp_path / "b")
    for x, y in zip(ea, eb, strict=True):
        assert x.spec == y.spec
        for ra, rb in zip(x.records, y.records, strict=True):
            np.testing.assert_array_equal(ra.push.as_array(), rb.push.as_array())
            np.testing.assert_array_equal(ra.pose, rb.pose)
            np.testing.assert_array_equal(ra.tactile, rb.tactile)
    collect(tmp_path / "c", tiny_run_dir, "active-entropy", seed=DATA_SEED + 1)
    other = actions(tmp_path / "c")
    assert not all(
        np.array_equal(u, v) for x, y in zip(actions(tmp_path / "a"), other) for u, v in zip(x, y)
    )


def test_active_kl_and_random_policies(tmp_path, tiny_run_dir):
    for policy in ("active-kl", "random"):
        res = collect(tmp_path / policy, tiny_run_dir, policy, objects=1, pushes=1)
        assert res["pushes"] == 1
        assert dataset_policies(tmp_path / policy) == {policy: 1}


def test_bad_policy_is_a_clear_error(tmp_path, tiny_run_dir):
    with pytest.raises(ValueError, match="policy must be one of uniform, random, active-kl"):
        collect(tmp_path / "x", tiny_run_dir, "bogus")
    assert not (tmp_path / "x").exists()
    result = CliRunner().invoke(
        app,
        ["collect", "--model", str(tiny_run_dir), "--policy", "bogus", "--out", str(tmp_path)],
    )
    assert result.exit_code == 2
    assert "'--policy'" in result.stderr and "'bogus'" in result.stderr
    assert "Traceback" not in result.output


def test_collect_cli(tmp_path, tiny_run_dir):
    out = tmp_path / "cli"
    args = [
        "collect", "--model", tiny_run_dir, "--policy", "random", "--objects", 1, "--pushes", 1,
        "--seed", 5, "--out", out, "--sigma-points", SIGMA_POINTS, "--candidates", 4,
    ]  # fmt: skip
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert result.exit_code == 0, (result.output, result.exception)
    assert "wrote 1 shards" in result.stdout
    gen = json.loads((out / GENERATION_FILE).read_text())["config"]
    assert (gen["policy"], gen["objects"], gen["pushes"], gen["seed"]) == ("random", 1, 1, 5)
    assert gen["objects_from"] == "catalogue-train"


def test_combined_dataset_trains(tmp_path, tiny_data, uniform_data):
    collected, _ = uniform_data
    union = tmp_path / "union"
    res = combine_datasets([tiny_data, collected], union)
    n_obj = DATA_OBJECTS + 3
    assert (res.objects, res.pushes) == (n_obj, DATA_OBJECTS * DATA_PUSHES + 6)
    info = dataset_info(union)
    assert (info.objects, info.pushes) == (res.objects, res.pushes)
    assert dataset_policies(union) == {"simulate": DATA_OBJECTS * DATA_PUSHES, "uniform": 6}
    gen = json.loads((union / GENERATION_FILE).read_text())
    assert gen["kind"] == "combined" and len(gen["sources"]) == 2
    assert gen["config"]["objects"] == n_obj and gen["config"]["pushes"] == 2
    pt = load_push_tensors(union)
    assert sorted(set(pt.object_index.tolist())) == list(range(n_obj))
    # idempotent
    assert combine_datasets([tiny_data, collected], union) == res
    assert len(list_shards(union)) == len(list_shards(tiny_data)) + 1
    model = train_model(union, tmp_path / "run", tiny_train_config(), seed=0, progress=False)
    info = json.loads((tmp_path / "run" / "training.json").read_text())
    assert info["train_objects"] + info["val_objects"] == n_obj
    assert info["objects"] == n_obj and model.info["train_pushes"] > 0


def test_combine_refuses_clashes(tmp_path, tiny_data):
    with pytest.raises(DatasetError, match="object index 0 also occurs"):
        combine_datasets([tiny_data, tiny_data], tmp_path / "twice")
    other = tmp_path / "short"
    cfg = GenerationConfig(
        objects=1,
        pushes=1,
        seed=DATA_SEED,
        objects_from="catalogue-test",
        sim=SimConfig(push=PushConfig(horizon=1.0)),
    )
    generate_dataset(other, cfg, progress=False)
    with pytest.raises(DatasetError, match="other testbed settings"):
        combine_datasets([tiny_data, other], tmp_path / "mixed")
    with pytest.raises(DatasetError, match="is one of the datasets"):
        combine_datasets([tiny_data], tiny_data)
