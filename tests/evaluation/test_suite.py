"""The evaluation suite end to end on the tiny model (configs/evaluate-ci.yaml), and its
fold statistics against hand computations."""

import json
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.evaluation.metrics import MethodRun, nrmse
from pushtoknow.evaluation.suite import (
    EvaluationConfig,
    fold_indices,
    summarise_method,
)
from pushtoknow.identification.prior import CATALOGUE_PRIOR, RANDOM_SHAPE_PRIOR
from tiny_training import tiny_dataset, tiny_run

CI_CONFIG = Path(__file__).parents[2] / "configs" / "evaluate-ci.yaml"
runner = CliRunner()


def test_fold_indices_partition_and_error():
    folds = fold_indices(11, 3, seed=0)
    assert sorted(np.concatenate(folds).tolist()) == list(range(11))
    assert [len(f) for f in folds] == [4, 4, 3]
    assert [f.tolist() for f in fold_indices(11, 3, 0)] == [f.tolist() for f in folds]
    with pytest.raises(ValueError, match="2 objects cannot be split into 3 folds"):
        fold_indices(2, 3, 0)


def test_summary_matches_hand_computation():
    rng = np.random.default_rng(1)
    truth = rng.uniform([0.2, 0.35, -0.02, -0.02, 5e-4], [1.2, 0.7, 0.02, 0.03, 1.5e-3], (6, 5))
    mean = np.stack([truth + rng.normal(0, 0.01, truth.shape) * k for k in (3, 2, 1)], 1)
    std = np.full_like(mean, 0.01)
    folds = [np.array([0, 1, 2]), np.array([3, 4, 5])]
    s = summarise_method(MethodRun(mean, std, truth, [str(i) for i in range(6)]), folds)
    per_fold = [nrmse(mean[g, -1], truth[g])["com_x"] for g in folds]
    assert s["nrmse"]["com_x"] == pytest.approx(np.mean(per_fold))
    assert s["nrmse_std"]["com_x"] == pytest.approx(np.std(per_fold))
    assert s["nrmse_all"] == nrmse(mean[:, -1], truth)
    assert [r["overall"] for r in s["per_push"]] == [
        nrmse(mean[:, k], truth)["overall"] for k in range(3)
    ]
    inside = np.abs(truth - mean[:, -1]) <= 1.6448536 * std[:, -1]
    assert s["coverage90"] == pytest.approx(inside.mean())
    for k in range(3):  # after every push, per parameter; the last is the final coverage
        inside_k = np.abs(truth - mean[:, k]) <= 1.6448536 * std[:, k]
        cov = s["per_push"][k]["coverage90"]
        assert cov["overall"] == pytest.approx(inside_k.mean())
        assert cov["com_x"] == pytest.approx(inside_k[:, 2].mean())
    assert s["per_push"][0]["coverage90"]["overall"] < s["per_push"][2]["coverage90"]["overall"]
    assert s["per_push"][2]["coverage90"] == s["coverage90_per_param"]
    assert s["profile_share"] is None
    chosen = [["constant", "release"], ["release", "release"], ["constant", "constant"]] * 2
    run = MethodRun(mean, std, truth, [str(i) for i in range(6)], profiles=chosen)
    assert summarise_method(run, folds)["profile_share"] == {"constant": 0.5, "release": 0.5}


def test_method_names_mark_a_structure_other_than_the_first_models():
    from types import SimpleNamespace

    from pushtoknow.evaluation.suite import _variant_names
    from pushtoknow.models.learned import LearnedModelsConfig

    def ckpt(variant, structure, quasi_static="network"):
        cfg = LearnedModelsConfig(structure=structure, quasi_static=quasi_static)
        return SimpleNamespace(variant=variant, models_config=cfg)

    loaded = [
        ckpt("vt-addf", "physics", "limit-surface"),
        ckpt("vt-addf", "black-box"),
        ckpt("v-ddf", "physics", "limit-surface"),
        ckpt("vt-addf", "physics"),
    ]
    assert _variant_names(loaded) == [
        "vt-addf",
        "vt-addf-black-box",
        "v-ddf",
        "vt-addf-physics",
    ]
    assert _variant_names(loaded[:1] * 2) == ["vt-addf", "vt-addf#1"]
    # a repeated name takes its run folder's where given and free
    runs = ["pretrained", "runs/vt-addf-random-shapes/model.pt", "runs/vt-addf-random-shapes"]
    assert _variant_names(loaded[:1] * 3, runs) == [
        "vt-addf",
        "vt-addf-random-shapes",
        "vt-addf#2",
    ]


def test_config_rejects_unknown_keys(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text("folds: 5\nheldout: 3\n")
    with pytest.raises(Exception, match="heldout"):
        EvaluationConfig.from_yaml(bad)


@pytest.mark.slow
def test_evaluate_cli_reduced_config(tmp_path_factory, tmp_path):
    data, run = tiny_dataset(tmp_path_factory), tiny_run(tmp_path_factory)
    out = tmp_path / "report"
    args = ["evaluate", "--data", str(data), "--models", str(run), "--out", str(out)]
    args += ["--config", str(CI_CONFIG), "--json", "--physics-sets", "novel"]
    result = runner.invoke(app, args)
    assert result.exit_code == 0, result.output
    printed = json.loads(result.stdout.strip().splitlines()[-1])
    methods = printed["methods"]  # the held-out set's: no physics rows (--physics-sets)
    expected = {"vt-addf:uniform", "vt-addf:active-kl", "prior-mean", "forest", "forest-visnet"}
    assert set(methods) == expected
    for name, m in methods.items():
        assert set(m["nrmse"]) == {"mass", "friction", "com_x", "com_y", "inertia", "overall"}
        assert all(np.isfinite(v) for v in m["nrmse"].values()), name
        assert 0.0 <= m["coverage90"] <= 1.0
        assert len(m["per_push"]) == 3  # prior + 2 pushes
        assert 0 <= m["impossible_estimates"] <= m["estimates"] == 4 * 3  # objects × (1 + pushes)
        assert m["outside_interval"] == 0, name  # every mean inside its own interval (§2)
    # every method starts from the same prior-mean estimate at k = 0 except the filter's prior
    assert methods["forest"]["per_push"][0] == methods["prior-mean"]["per_push"][0]
    full = json.loads((out / "results.json").read_text())
    assert set(full["sets"]) == {"heldout", "novel"}
    assert len(full["sets"]["novel"]["objects"]) == 2
    novel = full["sets"]["novel"]["methods"]  # the physics estimator on the same pushes
    assert set(novel) == expected | {"physics:uniform"}
    assert novel["physics:uniform"]["outside_interval"] == 0
    assert all((Path(p).stat().st_size > 1000) for p in full["figures"].values())
    report = (out / "RESULTS.md").read_text()
    assert "| forest-visnet |" in report and "Novel objects (2 objects)" in report
    header = next(line for line in report.splitlines() if line.startswith("| method"))
    assert "| impossible | outside interval |" in header
    # a second run reads the cached inference runs and gives identical numbers
    again = runner.invoke(app, args)
    assert again.exit_code == 0, again.output
    assert json.loads(again.stdout.strip().splitlines()[-1])["methods"] == methods


def test_evaluate_cli_errors(tmp_path_factory, tmp_path):
    data = tiny_dataset(tmp_path_factory)
    args = ["evaluate", "--data", str(data), "--models", str(tmp_path / "nope")]
    result = runner.invoke(app, [*args, "--out", str(tmp_path / "r")])
    assert result.exit_code != 0
    assert "nope" in result.output or "nope" in str(result.exception)


def test_cache_key_follows_the_checkpoint_contents(tmp_path):
    from pushtoknow.evaluation.suite import _cache_key

    run = tmp_path / "run"
    run.mkdir()
    (run / "model.pt").write_bytes(b"first model")
    cfg = EvaluationConfig()
    c = ("constant",)
    key = _cache_key(run, "uniform", ["catalogue:1"], cfg, c)
    assert _cache_key(run, "uniform", ["catalogue:1"], cfg, c) == key
    assert _cache_key(run, "random", ["catalogue:1"], cfg, c) != key
    assert _cache_key(run, "uniform", ["catalogue:1"], cfg, ("constant", "release")) != key
    (run / "model.pt").write_bytes(b"retrained model")  # same path, new weights
    assert _cache_key(run, "uniform", ["catalogue:1"], cfg, c) != key


def test_summary_counts_estimates_outside_their_interval():
    from pushtoknow.evaluation.suite import gaussian_run

    truth = np.tile([0.5, 0.5, 0.0, 0.0, 1e-3], (4, 1))
    mean = np.repeat(truth[:, None], 3, 1)
    std = np.full_like(mean, 0.01)
    folds = [np.array([0, 1]), np.array([2, 3])]
    ids = [str(i) for i in range(4)]
    assert summarise_method(MethodRun(mean, std, truth, ids), folds)["outside_interval"] is None
    lower, upper = mean - 0.02, mean + 0.03
    lower[1, 2, [0, 4]] = mean[1, 2, [0, 4]] + 1e-3  # two parameters, one estimate
    lower[3, 0, 2] = mean[3, 0, 2]  # at its bound: inside
    run = MethodRun(mean, std, truth, ids, lower=lower, upper=upper)
    s = summarise_method(run, folds)
    assert s["outside_interval"] == 1 and s["estimates"] == 12
    # the forest and the prior: Gaussian in SI, mean ± 1.645·std, symmetric, so 0
    g = gaussian_run(mean, std, truth, ids)
    np.testing.assert_allclose(g.upper - g.mean, 1.6448536 * std)
    assert summarise_method(g, folds)["outside_interval"] == 0


def test_an_inference_cache_without_intervals_is_recomputed(tmp_path, monkeypatch):
    """A run cached before intervals were recorded (under the key of that format) is not read as
    if it had them: it is recomputed, and the new cache keeps them."""
    import hashlib

    from pushtoknow.evaluation import suite
    from pushtoknow.evaluation.heldout import HeldoutRun

    def run(intervals: bool) -> HeldoutRun:
        z = np.zeros((1, 2, 5))
        return HeldoutRun(z, z, z, np.zeros((1, 2)), np.zeros((1, 5)), ["o"], [1.0],
                          np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), [["constant"]],
                          lower=z - 1 if intervals else None,
                          upper=z + 1 if intervals else None)  # fmt: skip

    calls = []
    monkeypatch.setattr(suite, "evaluate_heldout", lambda *a, **k: calls.append(1) or run(True))
    cfg = suite.EvaluationConfig(heldout_objects=1, novel_objects=0)
    model = tmp_path / "model.pt"
    model.write_bytes(b"weights")
    cache = tmp_path / "run.npz"
    old = hashlib.sha256(b"weights")  # the key before the cache format was part of it
    old.update(json.dumps(["uniform", cfg.pushes, cfg.seed, None, ["o"], ["constant"]]).encode())
    suite._save_run(cache, old.hexdigest()[:16], run(False))
    args = (model, "uniform", ["o"], cfg, ("constant",), cache, None)
    got = suite._inference_run(*args)
    assert len(calls) == 1 and got.lower is not None
    again = suite._inference_run(*args)  # from the new cache, intervals included
    assert len(calls) == 1
    np.testing.assert_array_equal(again.lower, -np.ones((1, 2, 5)))
    np.testing.assert_array_equal(again.upper, np.ones((1, 2, 5)))
    key = suite._cache_key(model, "uniform", ["o"], cfg, ("constant",))
    suite._save_run(cache, key, run(False))  # a run without intervals: None, never guessed
    assert suite._load_run(cache, key).lower is None


# --- the physics estimator's rows, the random set and merging (--keep) ---------------------

TINY_EVAL = {
    "heldout_objects": 1,
    "novel_objects": 0,
    "pushes": 1,
    "policies": ["uniform"],
    "folds": 2,
    "workers": 1,
    "forest_trees": 5,
    "random_objects": 1,
}


@pytest.fixture(scope="module")
def physics_eval(tmp_path_factory):
    """A tiny evaluation with the physics rows and a random set of one object: (results, the
    model, the out folder)."""
    from pushtoknow.evaluation.suite import run_evaluation

    data, run = tiny_dataset(tmp_path_factory), tiny_run(tmp_path_factory)
    out = tmp_path_factory.mktemp("physics-eval")
    cfg = EvaluationConfig.model_validate(TINY_EVAL)
    return run_evaluation(data, [run], cfg, out), run, out


def test_physics_rows_beside_the_learned_ones(physics_eval):
    results, _, out = physics_eval
    assert EvaluationConfig().physics_policies == ("uniform",)
    assert results.primary == "vt-addf:uniform"
    for set_name in ("heldout", "random"):
        methods = results.sets[set_name]["methods"]
        assert list(methods)[:2] == ["vt-addf:uniform", "physics:uniform"]
        physics, learned = methods["physics:uniform"], methods["vt-addf:uniform"]
        assert set(physics) == set(learned)  # the same summary, field for field
        assert physics["profile_share"] is not None and physics["outside_interval"] == 0
        assert all(np.isfinite(v) for v in physics["nrmse"].values())
        assert physics["nrmse"] != learned["nrmse"]  # the physics filter's own estimates
        # the same pushes: the physics run replayed the learned run's
        cached = ("vt-addf_uniform", "physics_uniform")
        runs = {m: np.load(out / "cache" / set_name / f"{m}.npz") for m in cached}
        np.testing.assert_array_equal(
            runs["physics_uniform"]["pushes_action"], runs["vt-addf_uniform"]["pushes_action"]
        )  # the pushes' fields by name (`testbed.sim.stack_records`, `suite.PUSH_PREFIX`)
        assert "replayed" in results.sets[set_name]["notes"]["physics:uniform"]
    written = json.loads((out / "results.json").read_text())
    assert written == json.loads(json.dumps(results.to_json(), default=float))
    assert list(written)[:3] == ["sets", "methods", "primary"] and "kept" not in written


def test_physics_sets_must_be_sets_the_evaluation_makes(tmp_path):
    from pushtoknow.common.errors import ConfigError
    from pushtoknow.evaluation.suite import run_evaluation

    cfg = EvaluationConfig.model_validate(TINY_EVAL | {"physics_sets": ["novel"]})
    with pytest.raises(ConfigError, match=r"physics_sets: \['novel'\]: sets this evaluation"):
        run_evaluation(None, [tmp_path / "model.pt"], cfg, tmp_path / "out")
    assert not (tmp_path / "out").exists()  # refused before any work


def test_the_cache_key_names_the_estimator(tmp_path):
    from pushtoknow.evaluation.suite import _cache_key

    (tmp_path / "model.pt").write_bytes(b"weights")
    args = (tmp_path, "uniform", ["catalogue:1"], EvaluationConfig(), ("constant",))
    pushes = np.zeros((1, 1, 5))
    keys = {
        _cache_key(*args),
        _cache_key(*args, "physics"),
        _cache_key(*args, "physics", pushes),
        _cache_key(*args, "physics", pushes + 1),
    }
    assert len(keys) == 4
    assert _cache_key(*args, "vt-addf") == _cache_key(*args)


@pytest.mark.parametrize("estimator", ["vt-addf", "physics"])
def test_the_cache_key_follows_the_code_that_reports_the_estimates(
    tmp_path, monkeypatch, estimator
):
    """A changed `common.estimate` (belief → reported numbers) or run loop (`inference.session`:
    when each estimate is reported) must not reuse old runs, for either estimator; a changed
    registration must not reuse the physics estimator's."""
    from pushtoknow.common import estimate
    from pushtoknow.evaluation.suite import _cache_key
    from pushtoknow.inference import session
    from pushtoknow.perception import registration

    (tmp_path / "model.pt").write_bytes(b"weights")
    args = (tmp_path, "uniform", ["catalogue:1"], EvaluationConfig(), ("constant",), estimator)
    before = _cache_key(*args)
    for module in (estimate, session, registration):
        copy = tmp_path / f"{module.__name__}.py"
        copy.write_bytes(Path(module.__file__).read_bytes() + b"\n# changed\n")
        with monkeypatch.context() as m:
            m.setattr(module, "__file__", str(copy))
            changed = _cache_key(*args) != before
        assert changed == (module is not registration or estimator == "physics"), module.__name__


def test_each_objects_physics_run_is_under_the_prior_the_testbed_draws_it_from(monkeypatch):
    """The evaluation's physics filter on a random shape runs under the random shapes' prior
    (their I_z any m·k²), on a catalogue object under the catalogue's."""
    from pushtoknow.evaluation.heldout import _run_one
    from pushtoknow.inference import physics_filter
    from pushtoknow.pretrained import resolve_model_path

    seen = []

    class Stop(Exception):
        pass

    def fake(model, cfg, seed, filter_config):
        seen.append(filter_config.prior)
        raise Stop

    monkeypatch.setattr(physics_filter, "PhysicsFilterEstimator", fake)
    model = str(resolve_model_path("pretrained"))
    for ref in ("random:3:0", "catalogue:5"):
        with pytest.raises(Stop):
            _run_one((model, ref, 1, "uniform", 0, None, ("constant",), "physics", None))
    assert seen == [RANDOM_SHAPE_PRIOR, CATALOGUE_PRIOR]


def test_a_random_set_of_one_object(physics_eval):
    results, _, _ = physics_eval
    s = results.sets["random"]
    assert s["objects"] == ["random:9001:0"] and s["folds"] == 1
    assert set(s["methods"]) == {
        "vt-addf:uniform", "physics:uniform", "prior-mean", "forest", "forest-visnet"
    }  # fmt: skip
    assert all(m["objects"] == 1 for m in s["methods"].values())
    assert results.config.random_objects == 1
    assert results.config.random_seed == 9001


def test_merge_keeps_rows_and_computes_only_missing_ones(physics_eval, tmp_path, monkeypatch):
    """Rows of the kept results stay as they are (one is altered here, to show it is not
    recomputed); the missing physics row and the missing random set are computed, the latter
    without training data: no forest rows, the estimators' prior as prior-mean."""
    from pushtoknow.common.params import si_moments
    from pushtoknow.evaluation import suite
    from pushtoknow.evaluation.metrics import nrmse
    from pushtoknow.identification.prior import prior_moments
    from pushtoknow.testbed.object_refs import load_object_spec

    results, run, _ = physics_eval
    kept = json.loads(json.dumps(results.to_json(), default=float))
    full_physics = kept["sets"]["heldout"]["methods"].pop("physics:uniform")
    del kept["sets"]["random"]
    kept["sets"]["heldout"]["methods"]["vt-addf:uniform"]["nrmse"]["overall"] = 123.0
    # a kept row's note stays; a recomputed row's note, of the run before, goes
    kept["sets"]["heldout"]["notes"] = {"vt-addf:uniform": "kept", "physics:uniform": "stale"}
    keep = tmp_path / "kept.json"
    keep.write_text(json.dumps(kept))
    calls = []
    real = suite.evaluate_heldout

    def counting(model, objects, *a, estimator="vt-addf", push_actions=None, **k):
        calls.append((estimator, tuple(objects), push_actions is not None))
        return real(model, objects, *a, estimator=estimator, push_actions=push_actions, **k)

    monkeypatch.setattr(suite, "evaluate_heldout", counting)
    cfg = EvaluationConfig.model_validate(TINY_EVAL)
    merged = suite.run_evaluation(None, [run], cfg, tmp_path / "out", keep=keep)
    held, old_held = merged.methods, kept["sets"]["heldout"]["methods"]
    for name, row in old_held.items():
        assert held[name] == row, name  # bit-identical
    assert held["vt-addf:uniform"]["nrmse"]["overall"] == 123.0
    notes = merged.sets["heldout"]["notes"]
    assert notes["physics:uniform"] != "stale" and "replayed" in notes["physics:uniform"]
    assert notes["vt-addf:uniform"].startswith("kept row; its run, recomputed")
    assert list(held) == ["vt-addf:uniform", "physics:uniform", "prior-mean", "forest",
                          "forest-visnet"]  # fmt: skip
    same = {k for k in full_physics if held["physics:uniform"][k] == full_physics[k]}
    assert set(full_physics) - same <= {"seconds_per_object"}  # the same run, recomputed
    # heldout: the learned run again (its pushes, its row kept), then the physics run
    assert calls == [
        ("vt-addf", ("catalogue:10",), False),
        ("physics", ("catalogue:10",), True),
        ("vt-addf", ("random:9001:0",), False),
        ("physics", ("random:9001:0",), True),
    ]
    rnd = merged.sets["random"]
    assert set(rnd["methods"]) == {"vt-addf:uniform", "physics:uniform", "prior-mean"}
    assert rnd["notes"]["forest"] == rnd["notes"]["forest-visnet"] == suite.NO_DATA
    assert "prior_moments" in rnd["notes"]["prior-mean"]
    mean, _ = si_moments(*prior_moments())
    truth = load_object_spec("random:9001:0").params.as_array()[None]
    assert rnd["methods"]["prior-mean"]["nrmse_all"] == nrmse(mean[None], truth)
    assert merged.kept["rows"] == {"heldout": list(old_held)}
    assert merged.data == kept["data"] and merged.primary == "vt-addf:uniform"
    # physics rows on the random set only: the held-out set gains none and runs nothing
    calls.clear()
    only_random = cfg.model_copy(update={"physics_sets": ("random",)})
    part = suite.run_evaluation(None, [run], only_random, tmp_path / "part", keep=keep)
    assert "physics:uniform" not in part.methods
    assert "physics:uniform" in part.sets["random"]["methods"]
    assert calls == [
        ("vt-addf", ("random:9001:0",), False),
        ("physics", ("random:9001:0",), True),
    ]


def test_merge_refuses_rows_of_another_config(physics_eval, tmp_path):
    from pushtoknow.cli.main import error_message
    from pushtoknow.common.errors import ConfigError
    from pushtoknow.evaluation.suite import run_evaluation

    results, run, _ = physics_eval
    cfg = EvaluationConfig.model_validate(TINY_EVAL)
    for key, value in (("pushes", 3), ("policies", ["uniform", "random"]), ("seed", 1)):
        kept = json.loads(json.dumps(results.to_json(), default=float))
        kept["config"][key] = value
        keep = tmp_path / f"{key}.json"
        keep.write_text(json.dumps(kept))
        with pytest.raises(ConfigError) as e:
            run_evaluation(None, [run], cfg, tmp_path / key, keep=keep)
        assert f"computed with {key} = " in str(e.value) and "\n" not in str(e.value)
        assert not (tmp_path / key).exists()  # refused before any work
    # through the command: one line naming the setting
    args = ["evaluate", "--models", str(run), "--out", str(tmp_path / "cli"), "--keep", str(keep)]
    args += ["--config", str(CI_CONFIG)]
    result = runner.invoke(app, args)
    assert result.exit_code != 0
    message = error_message(result.exception)
    assert message is not None and "\n" not in message
    assert "its rows were computed with pushes = 1, this run has 2" in message
