"""The m-against-μ ridge misfit: which parts of a model can tell m from μ at fixed μ·m."""

import json

import numpy as np
import pytest
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.evaluation.ridge import RIDGE_PARTS, ridge_misfit
from pushtoknow.models.checkpoint import load_checkpoint
from pushtoknow.pretrained import pretrained_dir
from pushtoknow.training.push_tensors import load_push_tensors
from tiny_training import tiny_dataset, tiny_run

DELTAS = np.array([-0.3, 0.0, 0.3])


@pytest.fixture(scope="module")
def pushes(tmp_path_factory):
    return load_push_tensors(tiny_dataset(tmp_path_factory))


def test_shipped_model_separates_m_from_mu_only_where_physics_does(pushes):
    """The shipped structure: every motion step but the free slide is the same all along the
    ridge; the slide and the accelerating pad's force are not. A steady force moves only by
    m·J·a of the pad's residual acceleration (|a| ≤ 0.05 m/s²), next to nothing."""
    r = ridge_misfit(load_checkpoint(pretrained_dir()), pushes, DELTAS)
    assert r.release.any() and (~r.release).any()
    for part in ("dynamic_motion", "steady_motion"):
        assert r.best_delta(part) is None, part
        assert r.rise(part) == 0.0
    for part in ("slide", "dynamic_force"):
        assert r.rise(part, r.release) > 1.0, part
        assert r.best_delta(part, r.release) is not None
    assert r.rise("steady_force") < 0.01 * r.rise("dynamic_force")
    assert r.best_delta("steady_force") is None
    # constant pushes never release: no slide misfit at all
    assert np.all(r.misfit["slide"][~r.release] == 0.0)
    assert set(r.misfit) == set(RIDGE_PARTS)
    assert all(v.shape == (len(pushes), len(DELTAS)) for v in r.misfit.values())


def test_a_black_box_model_lets_steady_pushes_tell_m_from_mu(pushes, tmp_path_factory):
    """The paper's black-box TacNet sees m and μ as two features: nothing keeps a steady
    push's force on the ridge's level line, which is what the physics structure fixes."""
    model = load_checkpoint(tiny_run(tmp_path_factory))
    assert model.models_config.structure == "black-box"
    r = ridge_misfit(model, pushes, DELTAS)
    assert r.best_delta("steady_force") is not None
    assert r.rise("slide") == 0.0  # no free slide written down: its steps count as dynamic


def test_ridge_command_prints_each_part_and_rejects_a_missing_dataset(tmp_path_factory, tmp_path):
    runner = CliRunner()
    data = tiny_dataset(tmp_path_factory)
    res = runner.invoke(app, ["ridge", "--data", str(data), "--json"])
    assert res.exit_code == 0, res.output
    out = json.loads(res.stdout)
    parts = {(p["pushes"], p["part"]): p for p in out["parts"]}
    assert len(parts) == 2 * len(RIDGE_PARTS)
    assert parts[("constant", "slide")]["best_delta"] is None
    assert parts[("release", "slide")]["rise_nats"] > 1.0
    missing = runner.invoke(app, ["ridge", "--data", str(tmp_path / "none")])
    assert missing.exit_code == 2
    assert "no such dataset directory" in missing.output and "Traceback" not in missing.output
