"""`pushtoknow train` and `pushtoknow infer` (in process, typer's CliRunner; errors that
`main` turns into exit code 2 through `main` itself)."""

import json
import sys

import pytest
import torch
from typer.testing import CliRunner

from pushtoknow.cli.main import app, main
from pushtoknow.common.errors import CheckpointError
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.training.pipeline import TrainConfig, visnet_config_for
from pushtoknow.training.push_tensors import dataset_camera
from tiny_training import DATA_OBJECTS, tiny_dataset, tiny_train_config

STAGES = ("visnet", "supervised", "end_to_end", "calibration")


def invoke(*args):
    return CliRunner().invoke(app, [str(a) for a in args])


def run_main(monkeypatch, capsys, *args):
    """`pushtoknow ARGS` through the console-script entry point: (exit code, stdout, stderr)."""
    monkeypatch.setattr(sys, "argv", ["pushtoknow", *map(str, args)])
    with pytest.raises(SystemExit) as e:
        main()
    out = capsys.readouterr()
    return e.value.code, out.out, out.err


@pytest.fixture(scope="module")
def tiny_yaml(tmp_path_factory):
    path = tmp_path_factory.mktemp("cfg") / "tiny.yaml"
    tiny_train_config().to_yaml(path)
    return path


@pytest.fixture(scope="module")
def trained(tmp_path_factory, tiny_yaml):
    """(CliRunner result, run directory) of `pushtoknow train` on the tiny dataset."""
    data = tiny_dataset(tmp_path_factory)
    run = tmp_path_factory.mktemp("cli-run") / "R"
    result = invoke(
        "train", "--data", data, "--out", run, "--variant", "vt-addf", "--config", tiny_yaml,
        "--seed", "0",
    )  # fmt: skip
    return result, run


def test_train_writes_the_run(trained, tmp_path_factory):
    result, run = trained
    data = tiny_dataset(tmp_path_factory)
    assert result.exit_code == 0, (result.output, result.exception)
    assert f"wrote {run / 'model.pt'}" in result.stdout.replace("\n", "")
    for name in ("model.pt", "config.yaml", "training.json", *(f"{s}.csv" for s in STAGES)):
        assert (run / name).is_file(), name
    for stage in STAGES:
        lines = (run / f"{stage}.csv").read_text().splitlines()
        assert len(lines) >= 2, stage  # a header and at least one row
        assert stage in result.stderr  # each logged row is echoed
    # config.yaml is the config as run: VisNet reads the orientation marker of the data
    expected = tiny_train_config()
    expected = expected.model_copy(
        update={"visnet": visnet_config_for(expected.visnet, dataset_camera(data)[1])}
    )
    assert expected.visnet.net.marker_channel
    assert TrainConfig.from_yaml(run / "config.yaml") == expected
    info = json.loads((run / "training.json").read_text())
    assert info["variant"] == "vt-addf" and info["seed"] == 0
    assert info["train_objects"] + info["val_objects"] == DATA_OBJECTS
    assert info["timings"]["total_s"] > 0


def train_reusing_visnet(variant, data, tiny_yaml, run, out):
    return invoke(
        "train", "--data", data, "--out", out, "--variant", variant, "--config", tiny_yaml,
        "--visnet-from", run,
    )  # fmt: skip


def test_train_variant_from_the_command_line_and_visnet_reuse(
    tmp_path, tmp_path_factory, tiny_yaml, trained
):
    """--variant overrides the config's; --visnet-from skips VisNet's training."""
    _, run = trained
    data = tiny_dataset(tmp_path_factory)  # cached: the one `trained` used
    out = tmp_path / "joint"
    result = train_reusing_visnet("vt-jdf", data, tiny_yaml, run, out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert TrainConfig.from_yaml(out / "config.yaml").variant == "vt-jdf"
    info = json.loads((out / "training.json").read_text())
    assert info["variant"] == "vt-jdf"
    assert info["visnet_val"] == {"reused_from": str(run)}
    assert not (out / "visnet.csv").exists()
    # the reused VisNet is the first run's, bit for bit
    a = torch.load(run / "model.pt", weights_only=True)["visnet_state"]
    b = torch.load(out / "model.pt", weights_only=True)["visnet_state"]
    assert a.keys() == b.keys() and all(torch.equal(a[k], b[k]) for k in a)


def test_train_vision_only_variant(tmp_path, tmp_path_factory, tiny_yaml, trained):
    _, run = trained
    out = tmp_path / "vision-only"
    result = train_reusing_visnet("v-ddf", tiny_dataset(tmp_path_factory), tiny_yaml, run, out)
    assert result.exit_code == 0, (result.output, result.exception)
    assert json.loads((out / "training.json").read_text())["variant"] == "v-ddf"
    assert "force_mse" not in (out / "end_to_end.csv").read_text()


def test_train_bogus_variant(tmp_path):
    result = invoke("train", "--data", tmp_path, "--out", tmp_path / "R", "--variant", "bogus")
    assert result.exit_code == 2
    assert "--variant must be vt-addf, vt-jdf or v-ddf, got 'bogus'" in result.stderr
    assert "Traceback" not in result.output
    assert not (tmp_path / "R").exists()


def test_train_missing_data(tmp_path, monkeypatch, capsys):
    code, _, err = run_main(
        monkeypatch, capsys, "train", "--data", tmp_path / "nope", "--out", tmp_path / "R"
    )
    assert code == 2
    assert "nope" in err and "does not exist" in err and "Traceback" not in err


def test_infer_json(trained, tmp_path):
    _, run = trained
    out = tmp_path / "X"
    result = invoke(
        "infer", "--model", run, "--object", "catalogue:117", "--pushes", "1", "--json",
        "--out", out, "--estimator", "vt-addf",
    )  # fmt: skip
    assert result.exit_code == 0, (result.output, result.exception)
    report = json.loads(result.stdout)  # stdout is the JSON only (tables go to stderr)
    assert set(report) >= {"pushes", "truth"}
    assert len(report["pushes"]) == 1
    estimate = report["pushes"][0]["estimate"]
    assert set(estimate) == set(PARAM_NAMES) == {"mass", "friction", "com_x", "com_y", "inertia"}
    assert all(set(v) == {"mean", "std", "interval90"} and v["std"] > 0 for v in estimate.values())
    truth = load_object_spec("catalogue:117").params
    assert report["truth"] == {n: getattr(truth, n) for n in PARAM_NAMES}
    assert json.loads((out / "estimates.json").read_text()) == report
    assert (out / "estimates.png").stat().st_size > 1000
    assert "after push 1" in result.stderr
    # the executed pushes are kept for `identify --pushes RUN`
    from pushtoknow.identification.recordings import load_recorded_objects

    (kept,) = load_recorded_objects(out)
    assert len(kept.records) == 1 and kept.truth.tolist() == truth.as_array().tolist()
    # the Python calls of docs/guide/infer-and-evaluate.md give the same result as the command
    from pushtoknow.common.random import stream_seed
    from pushtoknow.inference import InferenceConfig, infer_object, infer_simulated
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.testbed.executor import SimulatedExecutor

    model = load_checkpoint(run)
    spec = load_object_spec("catalogue:117")
    config = InferenceConfig(
        estimator="vt-addf", pushes=1, policy="uniform", profiles=model.profiles
    )
    res = infer_simulated(model, spec, config, seed=0)
    assert json.loads(json.dumps(res.to_json())) == report
    # the run's seed feeds the simulator its own stream (`common.random`)
    executor = SimulatedExecutor(
        spec, model.sim_config, seed=stream_seed(0, "simulator"), recentre=True
    )
    res = infer_object(model, executor, config, seed=0, initial_pose=executor.initial_pose,
                       truth=spec.params.as_array(), object_name=spec.name)  # fmt: skip
    executor.close()
    assert json.loads(json.dumps(res.to_json())) == report


def test_infer_missing_model(tmp_path, monkeypatch, capsys):
    args = ["infer", "--model", "/nonexistent", "--object", "catalogue:117", "--out", tmp_path]
    result = invoke(*args)
    assert isinstance(result.exception, CheckpointError)  # left to `main`
    code, out, err = run_main(monkeypatch, capsys, *args)
    assert code == 2
    assert "no checkpoint" in err and "/nonexistent" in err and "Traceback" not in err
    assert out == ""


def test_infer_refuses_a_profile_the_model_never_saw(trained, tmp_path, monkeypatch, capsys):
    from pushtoknow.models.checkpoint import load_checkpoint, save_checkpoint

    # the tiny model, as if it had been trained on constant pushes only
    model = load_checkpoint(trained[1])
    model.info["profiles"] = ["constant"]
    constant_only = save_checkpoint(model, tmp_path / "constant-only")
    args = ["infer", "--model", constant_only, "--object", "catalogue:117", "--pushes", "1"]
    args += ["--profiles", "constant,release", "--out", tmp_path / "X", "--estimator", "vt-addf"]
    code, out, err = run_main(monkeypatch, capsys, *args)
    assert code == 2 and "after push" not in out + err  # refused before any push
    assert "profiles release" in err and "constant pushes only" in err
    assert "Traceback" not in err and not (tmp_path / "X").exists()


def test_infer_bad_policy(tmp_path):
    result = invoke(
        "infer", "--model", tmp_path, "--object", "catalogue:117", "--policy", "bogus",
        "--out", tmp_path / "X",
    )  # fmt: skip
    assert result.exit_code == 2
    assert "'--policy'" in result.stderr and "'bogus'" in result.stderr


def test_infer_bad_profile(tmp_path):
    result = invoke(
        "infer", "--model", tmp_path, "--object", "catalogue:117", "--profiles", "constant,fast",
        "--out", tmp_path / "X",
    )  # fmt: skip
    assert result.exit_code == 2
    assert "--profiles" in result.stderr and "fast" in result.stderr and "release" in result.stderr
