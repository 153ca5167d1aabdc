"""The top-level Python API (`pushtoknow.api`, re-exported by `import pushtoknow`)."""

import dataclasses

import mujoco
import numpy as np
import pytest

import pushtoknow
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import product_moments
from pushtoknow.datasets.recording import recording_meta, write_recording
from pushtoknow.datasets.shards import write_run_pushes


def test_every_api_name_resolves_and_nothing_else_does():
    for name in pushtoknow.api.__all__:
        assert getattr(pushtoknow, name) is getattr(pushtoknow.api, name)
    assert set(pushtoknow.api.__all__) <= set(dir(pushtoknow))
    with pytest.raises(AttributeError, match="no attribute 'infer_simulated'"):
        pushtoknow.infer_simulated  # noqa: B018 - a deep name is not re-exported


@pytest.mark.parametrize(
    ("kwargs", "error", "names"),
    [
        ({"obj": None}, TypeError, "obj"),
        ({"obj": 117}, TypeError, "obj"),
        ({"seed": -1}, ValueError, "seed"),
        ({"seed": 1.5}, ValueError, "seed"),
        ({"pushes": 0}, ValueError, "pushes"),
        ({"estimator": "kalman"}, ValueError, "estimator"),
        ({"policy": "greedy"}, ValueError, "policy"),
    ],
)
def test_bad_arguments_are_named_before_any_work(kwargs, error, names):
    model = object()  # never used: the arguments are checked first
    args = {"obj": "catalogue:117", "model": model, **kwargs}
    obj = args.pop("obj")
    with pytest.raises(error, match=f"^{names}: "):
        pushtoknow.estimate_simulated(obj, **args)


def test_export_refuses_a_result_without_pushes(tmp_path):
    from pushtoknow.inference.estimator import InferenceResult

    empty = InferenceResult(prior=None, estimates=[], truth=None)  # type: ignore[arg-type]
    with pytest.raises(ValueError, match="^result: no push"):
        pushtoknow.export_object(empty, "mjcf", tmp_path / "o.xml")
    with pytest.raises(TypeError, match="^result: "):
        pushtoknow.export_object({"mean": [1]}, "mjcf", tmp_path / "o.xml")


@pytest.mark.slow
def test_readme_tour_simulated_push_recording_and_export(tmp_path):
    """The README's Python example: estimate a random-shape object from one push with the
    physics estimator, export it to MJCF (MuJoCo loads the estimate), then estimate the same
    push again from its recording on disk, once with its images and once from the tracked
    poses and stored outline alone."""
    result = pushtoknow.estimate_simulated("random:5:0", pushes=1, estimator="physics", seed=0)
    last = result.estimates[-1]
    lo, hi = last.interval()
    assert np.all((lo <= last.mean) & (last.mean <= hi))
    assert result.outline is not None and result.outline.shape[1] == 2 and result.height > 0
    (xml,) = pushtoknow.export_object(result, "mjcf", tmp_path / "object.xml")
    m = mujoco.MjModel.from_xml_path(str(xml))
    body = m.nbody - 1
    assert m.body_mass[body] == pytest.approx(last.mean[0])
    assert result.to_json()["outline"] is not None

    spec = pushtoknow.load_object("random:5:0")
    sim_json = pushtoknow.load_model().sim_config.model_dump_json()
    write_run_pushes(tmp_path, spec, result.records, sim_json)
    (again,) = pushtoknow.estimate_recording(tmp_path, estimator="physics", seed=0)
    assert again.truth is not None and len(again.estimates) == 1
    np.testing.assert_allclose(again.truth, spec.params.as_array())
    # before any push the belief is already the recorded outline's prior (the CoM uniform
    # over its hull), not the catalogue's
    catalogue = result.prior  # the traced-outline run's, before its first view
    assert not np.allclose(again.prior.std[2:4], catalogue.std[2:4])
    (learned,) = pushtoknow.estimate_recording(tmp_path, estimator="vt-addf", seed=0)
    assert learned.estimator == "vt-addf" and len(learned.estimates) == 1

    # a recording of tracked poses, force and the outline, without images (a real robot's;
    # docs/RECORDING.md)
    model = pushtoknow.load_model()
    blind = [dataclasses.replace(r, rgb=None, depth=None) for r in result.records]
    path = write_recording(tmp_path / "pushes.h5", blind, recording_meta(spec, model.sim_config))
    (tracked,) = pushtoknow.estimate_recording(path, estimator="physics")
    e = tracked.estimates[-1]
    # the true outline and tracked poses: μ·m, the quasi-static reading, within 10 % (the
    # product's own mean: a recording starts from everyday objects' wide prior, where m and μ
    # alone stay uncertain and the product of their means is not μ·m's)
    mu_m, _ = product_moments(e.mean_norm, e.cov_norm)
    assert mu_m == pytest.approx(spec.params.mass * spec.params.friction, rel=0.1)
    assert tracked.prior.std[0] > 2 * again.prior.std[0]  # everyday prior: wider in m
    with pytest.raises(DatasetError, match="without images"):
        pushtoknow.estimate_recording(path, estimator="vt-addf")


@pytest.mark.slow
def test_the_readme_python_example_runs_as_written(tmp_path, monkeypatch):
    """The README's Python block, verbatim, in a folder holding a recording `pushes.h5` (one
    simulated push of another object, docs/RECORDING.md)."""
    import re
    from pathlib import Path

    readme = (Path(__file__).parents[1] / "README.md").read_text()
    (block,) = re.findall(r"```python\n(.*?)```", readme, flags=re.S)
    spec = pushtoknow.load_object("random:5:1")
    model = pushtoknow.load_model()
    seen = pushtoknow.estimate_simulated(spec, pushes=1, estimator="vt-addf")
    write_recording(tmp_path / "pushes.h5", seen.records, recording_meta(spec, model.sim_config))
    monkeypatch.chdir(tmp_path)
    exec(compile(block, "README.md", "exec"), {})
    assert (tmp_path / "object.xml").stat().st_size > 0
