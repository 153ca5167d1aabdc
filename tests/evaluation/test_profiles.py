"""Speed-profile ablation on the tiny model: conditions, release shares, resume,
and the fold summary against a hand computation."""

import json

import numpy as np
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.evaluation.heldout import HeldoutRun, heldout_object_ids
from pushtoknow.evaluation.metrics import nrmse
from pushtoknow.evaluation.profiles import parse_condition, summarise_condition
from pushtoknow.testbed.objects import catalogue_split
from tiny_training import tiny_run

runner = CliRunner()


def test_parse_condition():
    assert parse_condition("active-entropy:constant,release") == (
        "active-entropy",
        ("constant", "release"),
    )
    assert parse_condition("uniform") == ("uniform", ("constant",))


def test_heldout_object_ids_are_nested_test_objects():
    test = set(catalogue_split()[1])
    few, more = heldout_object_ids(5, seed=3), heldout_object_ids(20, seed=3)
    assert more[:5] == few and len(set(more)) == 20
    assert all(int(i.split(":")[1]) in test for i in more)


def test_summary_folds_and_release_share():
    rng = np.random.default_rng(0)
    truth = rng.uniform([0.2, 0.35, -0.02, -0.02, 5e-4], [1.2, 0.7, 0.02, 0.03, 1.5e-3], (6, 5))
    mean = np.stack([np.tile(truth.mean(0), (6, 1)), truth + rng.normal(0, 0.01, truth.shape)], 1)
    run = HeldoutRun(
        mean=mean,
        std=np.full_like(mean, 0.01),
        zscore=(truth[:, None] - mean) / 0.01,
        product=mean[..., 0] * mean[..., 1],
        truth=truth,
        ids=[str(i) for i in range(6)],
        seconds=[1.0] * 6,
        profiles=[["constant"], ["release"], ["constant"], ["constant"], ["release"], ["release"]],
    )
    folds = [np.array([0, 1, 2]), np.array([3, 4, 5])]
    s = summarise_condition(run, folds)
    per_fold = [nrmse(mean[f, 1], truth[f])["mass"] for f in folds]
    assert s.nrmse["mass"]["mean"] == np.mean(per_fold)
    assert s.nrmse["mass"]["std"] == np.std(per_fold)
    assert s.nrmse["overall"]["all"] == nrmse(mean[:, 1], truth)["overall"]
    assert s.release_share == 0.5
    inside = np.abs(truth - mean[:, 1]) <= 1.6448536 * 0.01
    assert s.coverage90 == inside.mean()
    assert s.prior_nrmse == nrmse(mean[:, 0], truth)
    assert list(s.to_json()) == [
        "nrmse", "mu_m", "coverage90", "release_share", "seconds_per_object_median",
        "prior_nrmse",
    ]  # fmt: skip


def test_ablate_profiles_end_to_end_and_resume(tmp_path, tmp_path_factory):
    run = tiny_run(tmp_path_factory)
    out = tmp_path / "profiles"
    args = [
        "ablate-profiles", "--model", str(run), "--out", str(out), "--objects", "4",
        "--pushes", "2", "--condition", "uniform:constant", "--condition",
        "uniform:constant,release", "--folds", "2", "--workers", "1",
        "--markdown", str(tmp_path / "section.md"),
    ]  # fmt: skip
    result = runner.invoke(app, args)
    assert result.exit_code == 0, (result.output, result.exception)
    report = json.loads((out / "profiles.json").read_text())
    conds = report["conditions"]
    assert list(conds) == ["uniform+constant", "uniform+constant+release"]
    assert conds["uniform+constant"]["release_share"] == 0.0
    assert conds["uniform+constant+release"]["release_share"] == 0.5  # push 2 of 2
    for s in conds.values():
        assert all(np.isfinite(v["mean"]) for v in s["nrmse"].values())
    section = (tmp_path / "section.md").read_text()
    assert "| uniform | constant, release |" in section and "prior mean" in section
    # a rerun with the same settings reads the saved conditions instead of pushing again
    before = (out / "uniform+constant.json").stat().st_mtime_ns
    again = runner.invoke(app, args)
    assert again.exit_code == 0
    assert (out / "uniform+constant.json").stat().st_mtime_ns == before
    assert json.loads((out / "profiles.json").read_text())["conditions"] == conds


def test_ablate_profiles_bad_condition(tmp_path):
    result = runner.invoke(
        app,
        ["ablate-profiles", "--model", str(tmp_path), "--out", str(tmp_path / "o"),
         "--condition", "uniform:constant,warp"],
    )  # fmt: skip
    assert result.exit_code == 2 and "warp" in result.output
