"""`pushtoknow ablate-efficiency` on configs/efficiency-ci.yaml (a miniature of the paper's
Fig. 4b ablation) and its config."""

import csv
import json
from pathlib import Path

import pytest
from pydantic import ValidationError
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.collection.efficiency import (
    EfficiencyConfig,
    figure_series,
    run_efficiency,
    summarise,
)
from pushtoknow.common.errors import DatasetError

ROOT = Path(__file__).resolve().parents[2]
CI_CONFIG = ROOT / "configs" / "efficiency-ci.yaml"
ROW_KEYS = {
    "round", "pushes", "seeds", "val_nll", "val_rmse", "val_nll_median", "mean", "std",
    "rmse_mean", "rmse_std",
}  # fmt: skip


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


@pytest.fixture(scope="module")
def ablation(tmp_path_factory):
    out = tmp_path_factory.mktemp("efficiency") / "ci"
    result = invoke(
        "ablate-efficiency", "--config", CI_CONFIG, "--out", out, "--seed", 0, "--json",
        "--markdown", out.parent / "section.md",
    )  # fmt: skip
    return result, out


def test_the_report_section_is_written_by_the_command(ablation):
    _, out = ablation
    text = (out.parent / "section.md").read_text()
    assert text.startswith("## Learning efficiency")
    assert "pushtoknow ablate-efficiency --config" in text  # how to reproduce it


def test_ci_ablation_writes_json_csv_png(ablation):
    result, out = ablation
    assert result.exit_code == 0, (result.output, result.exception)
    cfg = EfficiencyConfig.from_yaml(CI_CONFIG)
    results = json.loads(result.stdout)
    assert results == json.loads((out / "efficiency.json").read_text())
    assert list(results) == list(cfg.policies)
    n0 = cfg.initial.objects * cfg.initial.pushes
    step = cfg.round.objects * cfg.round.pushes
    for rows in results.values():
        assert [r["pushes"] for r in rows] == [n0 + r * step for r in range(cfg.rounds + 1)]
        for r in rows:
            assert set(r) == ROW_KEYS
            assert len(r["val_nll"]) == len(r["val_rmse"]) == len(cfg.seeds)
            assert r["seeds"] == list(cfg.seeds)
            assert r["std"] >= 0 and r["rmse_mean"] > 0
    # round 0 is M0, shared by every policy
    first = [rows[0] for rows in results.values()]
    assert all(r["val_nll"] == first[0]["val_nll"] for r in first)
    with open(out / "efficiency.csv") as f:
        rows = list(csv.DictReader(f))
    assert len(rows) == len(cfg.policies) * (cfg.rounds + 1) * len(cfg.seeds)
    assert (out / "efficiency.png").stat().st_size > 1000
    run = json.loads((out / "efficiency-run.json").read_text())
    assert run["seeds"] == list(cfg.seeds) and len(run["models"]) == len(cfg.seeds) * (
        1 + cfg.rounds * len(cfg.policies)
    )
    for policy in cfg.policies:
        data = out / "seed-0" / policy / "round-1" / "data"
        gen = json.loads((data / "generation.json").read_text())
        assert gen["kind"] == "combined" and len(gen["sources"]) == 2
        assert gen["sources"][1]["config"]["policy"] == policy


def test_ci_ablation_resumes_without_retraining(ablation):
    _, out = ablation
    models = sorted(out.glob("seed-*/**/model.pt"))
    stamps = [p.stat().st_mtime_ns for p in models]
    cfg = EfficiencyConfig.from_yaml(CI_CONFIG)
    before = json.loads((out / "efficiency.json").read_text())
    assert run_efficiency(cfg, out, seed=0).to_json() == before
    assert [p.stat().st_mtime_ns for p in models] == stamps
    timings = json.loads((out / "efficiency-run.json").read_text())["timings_this_call"]
    assert "train_s" not in timings
    other = cfg.model_copy(update={"rounds": 2})
    with pytest.raises(DatasetError, match="another config or seed"):
        run_efficiency(other, out, seed=0)


def test_bad_policy_in_config(tmp_path):
    bad = tmp_path / "bad.yaml"
    bad.write_text(CI_CONFIG.read_text().replace("[random, active-entropy]", "[random, greedy]"))
    result = invoke("ablate-efficiency", "--config", bad, "--out", tmp_path / "out")
    assert result.exit_code == 2
    assert "policy must be one of uniform, random, active-kl, active-entropy" in result.stderr
    assert "'greedy'" in result.stderr and "Traceback" not in result.output
    assert not (tmp_path / "out").exists()
    with pytest.raises(ValidationError, match="without repeats"):
        EfficiencyConfig(seeds=(0, 0))


def test_real_config_loads():
    cfg = EfficiencyConfig.from_yaml(ROOT / "configs" / "efficiency.yaml")
    assert cfg.validation.objects_from == "catalogue-test"
    assert set(cfg.policies) == {"uniform", "random", "active-entropy"}


def test_summarise_spread_over_seeds():
    rows = [
        {"policy": "random", "round": r, "seed": s, "pushes": 10 + 4 * r, "val_nll": v,
         "val_rmse": v / 10, "val_nll_median": v}
        for r, s, v in [(0, 0, 2.0), (0, 1, 4.0), (1, 1, 1.0), (1, 0, 3.0)]
    ]  # fmt: skip
    out = summarise(rows, ["random"], [0, 1])
    first, second = out.policies["random"]
    assert first.val_nll == [2.0, 4.0] and second.val_nll == [3.0, 1.0]  # by seed
    assert first.mean == 3.0 and first.std == pytest.approx(2**0.5)  # ddof = 1
    assert set(out.to_json()["random"][0]) == ROW_KEYS
    assert figure_series(out)["random"] == [(10.0, 3.0, pytest.approx(2**0.5))] * 1 + [
        (14.0, 2.0, pytest.approx(2**0.5))
    ]
    assert figure_series(out, "rmse")["random"][0][1] == pytest.approx(0.3)
