"""Bad input through the installed entry point (`pushtoknow.cli.main.main`, in process): each
case ends in exit status 2 with a message naming the option or file and the problem, never a
traceback, and nothing already written is touched."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

from pushtoknow.cli.main import error_message, main

CASES = [
    # (arguments, text the message must contain)
    (["infer", "--object", "catalogue:3", "--sigma-points", "3"], "--sigma-points"),
    (["infer", "--object", "catalogue:3", "--seed", "-1"], "--seed"),
    (["push", "--profile", "fast"], "--profile"),
    (["evaluate-heldout", "--objects", "0"], "--objects"),
    (
        [
            "push",
            "--object",
            '{"shape": "rect1", "mass": 1e6, "friction": 0.5, "com": [0, 0], "inertia": 1.0}',
            "--out",
            "{tmp}/p.png",
        ],
        "mass=1000000.0",
    ),
    (
        [
            "push",
            "--object",
            '{"shape": {"type": "rectangle", "width": 4, "height": 4}, "mass": 0.5, '
            '"friction": 0.5, "com": [0, 0], "inertia": 1.0}',
        ],
        "radius 2.828 m",
    ),
    (
        [
            "push",
            "--object",
            '{"shape": {"type": "polygon", "vertices": [[0, 0], [0.1, 0], [0, 0.1]]}, '
            '"mass": 0.5, "friction": 0.5, "com": [0.03, 0.03], "inertia": 1e-4}',
        ],
        "centroid at (33.333, 33.333) mm",
    ),
    (["dataset", "info", "{tmp}/garbage", "--verify"], "shard-00000.h5"),
    (
        ["evaluate", "--data", "{tmp}/empty", "--models", "pretrained", "--out", "{tmp}/e"],
        "no shard",
    ),
    (
        ["evaluate", "--models", "pretrained,{tmp}/no-run", "--out", "{tmp}/e"],
        "no-run: no such run folder or checkpoint",
    ),
    (["infer", "--object", "{tmp}/taken.txt"], "holds a str, not a mapping"),
    (["evaluate-heldout", "--objects", "2", "--policy", "greedy"], "'--policy'"),
    (["infer", "--object", "catalogue:3", "--model", "{tmp}/taken"], "not a readable pushtoknow"),
    (["infer", "--object", "{tmp}/broken.yaml"], "line 2"),
    (["import-mit", "{tmp}", "--out", "{tmp}/m", "--rate", "-5"], "'--rate'"),
    (["import-mit", "{tmp}", "--out", "{tmp}/m", "--as-speed", "-20"], "'--as-speed'"),
    (["push", "--out", "{tmp}/taken.txt"], "unsupported image format 'txt'"),
    (["push", "--out", "{tmp}"], "is a folder"),
    (
        [
            "push",
            "--object",
            '{"shape": "rect1", "mass": 0.5, "friction": 0.5, "com": [0, 0.01], '
            '"inertia": 0.5e-3, "height": 1000}',
        ],
        "height=1000",
    ),
    (
        [
            "push",
            "--object",
            '{"shape": "rect1", "mass": 0.5, "friction": 0.5, "com": [0, 0.01], "inertia": 1e-12}',
        ],
        "inertia=1e-12",
    ),
    (["infer", "--object", "catalogue:3", "--out", "{tmp}/taken"], "is a file"),
    (["evaluate-heldout", "--objects", "1", "--out", "{tmp}"], "is a folder"),
    (["train", "--data", "{tmp}", "--out", "{tmp}/run"], "holds a trained model"),
    (["simulate", "--objects", "1", "--out", "{tmp}/gen"], "generation.json"),
    (["simulate", "--objects", "1", "--out", "{tmp}/s", "--profiles", "foo"], "'foo'"),
    (["identify", "--pushes", "{tmp}/nowhere"], "no such dataset directory"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/missing.yaml"], "missing.yaml"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/broken.yaml"], "not valid YAML"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/unknown.yaml"], "huber_k"),
    (["simulate", "--objects", "1", "--out", "{tmp}/taken"], "file exists"),
    (["simulate", "--objects", "1", "--out", "/proc/no/such"], "no such file or directory"),
    (["simulate", "--objects", "1", "--out", "{tmp}/r", "--ray", "127.0.0.1:1"], "no Ray cluster"),
    (["evaluate-heldout", "--objects", "1", "--ray", "nowhere"], "expected auto, HOST:PORT"),
    (["simulate", "--out", "{tmp}/rs", "--objects-from", "random:x"], "random:SEED needs"),
    (["push", "--object", "random:1"], "must be random:SEED:I"),
    # issue 37: brackets in a message are text, not rich markup
    (
        [
            "push",
            "--object",
            '{"shape": {"type": "polygon", "vertices": [[0, 0], [0.1, 0]]}, "mass": 0.5, '
            '"friction": 0.5, "com": [0, 0], "inertia": 1e-4}',
        ],
        "needs at least 3 [x, y] vertices",
    ),
    # the documented minimum of --sigma-points is the one the filter works with
    (["infer", "--object", "catalogue:3", "--sigma-points", "10"], "--sigma-points"),
    # YAML/JSON files that are not UTF-8 text
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/latin1.yaml"], "not UTF-8 text"),
    (["simulate", "--out", "{tmp}/sb", "--objects-from", "{tmp}/binary.yaml"], "not UTF-8 text"),
]


NOT_UTF8 = {  # object spec files a user may pass by mistake
    "binary": b"\x89PNG\r\n\x1a\n\x00\x00\x00\rIHDR\xff\xfe",
    "latin1": 'shape: rect1\nname: "caf\u00e9"\n'.encode("latin-1"),
    "utf16": "shape: rect1\nmass: 0.5\n".encode("utf-16"),
}


def _run(monkeypatch, capsys, args) -> tuple[int, str]:
    monkeypatch.setattr(sys, "argv", ["pushtoknow", *args])
    with pytest.raises(SystemExit) as exit_info:
        main()
    captured = capsys.readouterr()
    return exit_info.value.code, captured.out + captured.err


@pytest.mark.parametrize(("args", "needle"), CASES, ids=[" ".join(c[0][:3]) for c in CASES])
def test_bad_input_exits_2_with_a_message_not_a_traceback(
    args, needle, tmp_path, monkeypatch, capsys
):
    (tmp_path / "broken.yaml").write_text("a: [\n")
    (tmp_path / "garbage").mkdir()
    (tmp_path / "empty").mkdir()
    (tmp_path / "taken.txt").write_text("keep me too")
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "model.pt").write_text("a finished run")
    (tmp_path / "gen").mkdir()
    (tmp_path / "gen" / "generation.json").write_text("{broken")
    (tmp_path / "garbage" / "shard-00000.h5").write_bytes(b"\x89HDF garbage" * 10)
    (tmp_path / "unknown.yaml").write_text("huber_k: 3\n")
    for name, data in NOT_UTF8.items():
        (tmp_path / f"{name}.yaml").write_bytes(data)
    taken = tmp_path / "taken"
    taken.write_text("keep me")
    code, text = _run(monkeypatch, capsys, [a.replace("{tmp}", str(tmp_path)) for a in args])
    assert code == 2, text
    assert needle in text and "Traceback" not in text
    errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1 and needle in errors[0], text  # one line, usage errors too
    assert taken.read_text() == "keep me"
    assert (tmp_path / "taken.txt").read_text() == "keep me too"
    assert (tmp_path / "run" / "model.pt").read_text() == "a finished run"


def test_version(monkeypatch, capsys):
    from pushtoknow import __version__

    code, text = _run(monkeypatch, capsys, ["--version"])
    assert code == 0 and text.strip() == f"pushtoknow {__version__}"


def test_only_user_errors_become_messages():
    """A bug keeps its traceback: only the project's errors and file-system errors (with an
    OS reason) are turned into one-line messages."""
    assert error_message(FileExistsError(17, "File exists", "out")) == "out: file exists"
    assert error_message(KeyError("x")) is None
    assert error_message(ZeroDivisionError()) is None


def test_a_full_disk_ends_in_a_message_and_loses_nothing(tmp_path, monkeypatch, capsys):
    """`simulate` on a full disk: one line naming the file and the reason, exit 2; the shard
    being written leaves no file behind, no finished file is touched."""
    import errno

    import h5py

    import pushtoknow.datasets.shards  # noqa: F401 (its h5py.File subclass, before the patch)

    real_file = h5py.File

    def full(name, mode="r", *a, **kw):
        if mode == "w":
            raise OSError(errno.ENOSPC, "No space left on device", str(name))
        return real_file(name, mode, *a, **kw)

    out = tmp_path / "ds"
    out.mkdir()
    keep = out / "notes.txt"
    keep.write_text("mine")
    monkeypatch.setattr(h5py, "File", full)
    args = ["simulate", "--objects", "1", "--pushes", "1", "--out", str(out), "--workers", "1"]
    code, text = _run(monkeypatch, capsys, args)
    assert code == 2 and "no space left on device" in text and "Traceback" not in text
    assert "shard-00000.h5" in text
    assert keep.read_text() == "mine" and not list(out.glob("shard-*.h5"))


def test_training_on_a_single_object_is_refused_before_any_work(tmp_path, monkeypatch, capsys):
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
    from pushtoknow.testbed.sim_config import PushConfig, SimConfig

    cfg = GenerationConfig(objects=1, pushes=1, seed=0, sim=SimConfig(push=PushConfig(horizon=1.0)))
    generate_dataset(tmp_path / "one", cfg, progress=False)
    code, text = _run(monkeypatch, capsys, ["train", "--data", str(tmp_path / "one"), "--out",
                                            str(tmp_path / "run")])  # fmt: skip
    assert code == 2 and "1 object(s); training needs at least 2" in text
    assert not (tmp_path / "run").exists()  # nothing written


# ---- issue 37: damaged files, non-UTF-8 specs, runaway sizes, Ray, the Python API -------------


def _one_error(code: int, text: str, *needles: str) -> str:
    """The one 'error:' line of a run that ended in exit status 2; it holds every needle."""
    assert code == 2 and "Traceback" not in text, text
    errors = [ln for ln in text.splitlines() if ln.startswith("error:")]
    assert len(errors) == 1, text
    for needle in needles:
        assert needle in errors[0], errors[0]
    return errors[0]


@pytest.fixture(scope="module")
def two_shards(tmp_path_factory):
    """What `simulate --objects 2 --pushes 1 --objects-per-shard 1` writes (same fingerprint)."""
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset

    out = tmp_path_factory.mktemp("two") / "ds"
    cfg = GenerationConfig(objects=2, pushes=1, objects_per_shard=1)
    generate_dataset(out, cfg, progress=False)
    return out


def _damaged_copy(src, dst, where: float | str):
    """A copy of the dataset `src` with 2 KB of random bytes written into shard 0 at `where`: a
    fraction of its size (chunk data, mostly), or "header", the object header of its first
    push's group (HDF5 metadata, which a fraction may miss for unused space)."""
    import shutil

    import h5py
    import numpy as np

    shutil.copytree(src, dst)
    shard = dst / "shard-00000.h5"
    if where == "header":
        with h5py.File(shard, "r") as f:
            first = f["objects"][sorted(f["objects"])[0]]["pushes"]["0"]
            offset = h5py.h5o.get_info(first.id).addr
    else:
        offset = int(shard.stat().st_size * where)
    with open(shard, "r+b") as f:
        f.seek(offset)
        f.write(np.random.default_rng(37).bytes(2048))
    return dst


SHARD_PER_OBJECT = ["--objects-per-shard", "1"]


@pytest.mark.parametrize("where", [0.5, "header"])
@pytest.mark.parametrize(
    "args",
    [
        ["dataset", "info", "{ds}", "--verify"],
        ["simulate", "--out", "{ds}", *["--objects", "2", "--pushes", "1"], *SHARD_PER_OBJECT],
        ["identify", "--pushes", "{ds}", "--workers", "1"],
    ],
    ids=["info", "resume", "identify"],
)
def test_damaged_hdf5_metadata_is_named_in_one_line(
    args, where, two_shards, tmp_path, monkeypatch, capsys
):
    """Damaged metadata is reported like damaged chunk data: one line naming the shard. A resume
    refuses it the same way (`check_digest`): the file is left as it is, for the user to move
    away, and the other shard is not touched."""
    ds = _damaged_copy(two_shards, tmp_path / "ds", where)
    before = {p.name: p.read_bytes() for p in ds.glob("shard-*.h5")}
    code, text = _run(monkeypatch, capsys, [a.replace("{ds}", str(ds)) for a in args])
    _one_error(code, text, "shard-00000.h5")
    assert {p.name: p.read_bytes() for p in ds.glob("shard-*.h5")} == before


@pytest.mark.parametrize("kind", sorted(NOT_UTF8))
@pytest.mark.parametrize(
    "args",
    [
        ["push", "--object", "{f}", "--out", "{tmp}/p.png"],
        ["infer", "--object", "{f}", "--out", "{tmp}/run"],
        ["identify", "--pushes", "{ds}", "--shape", "{f}", "--workers", "1"],
    ],
    ids=["push", "infer", "identify"],
)
def test_object_spec_files_that_are_not_utf8_text(
    args, kind, two_shards, tmp_path, monkeypatch, capsys
):
    spec = tmp_path / f"{kind}.yaml"
    spec.write_bytes(NOT_UTF8[kind])
    fill = {"{f}": str(spec), "{tmp}": str(tmp_path), "{ds}": str(two_shards)}
    args = [fill.get(a, a).replace("{tmp}", str(tmp_path)) for a in args]
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, f"{kind}.yaml", "not UTF-8 text")


@pytest.fixture
def no_work(monkeypatch):
    """The work of `infer`, `simulate` and `estimate-real` fails loudly: a check must come
    before it."""
    import pushtoknow.datasets.generate as generate
    import pushtoknow.evaluation.real_object as real
    import pushtoknow.inference as inference

    def work(*args, **kwargs):
        raise AssertionError("the work started before the check")

    monkeypatch.setattr(inference, "infer_simulated", work)
    monkeypatch.setattr(generate, "generate_dataset", work)
    monkeypatch.setattr(real, "prepare_real_data", work)


def _sys_is_writable() -> bool:
    import tempfile

    try:
        tempfile.TemporaryFile(dir="/sys").close()
    except OSError:
        return False
    return True


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["infer", "--object", "catalogue:3", "--pushes", "1000", "--out", "{tmp}/i"], "--pushes"),
        (["simulate", "--objects", "1", "--pushes", "1000", "--out", "{tmp}/s"], "--pushes"),
        (["infer", "--object", "catalogue:3", "--out", "{tmp}/file/run"], "is a file"),
        (["infer", "--object", "catalogue:3", "--out", "/sys/pushtoknow/run"], "cannot write"),
        (["estimate-real", "{tmp}", "--forest-data", "{tmp}/nowhere"], "nowhere"),
    ],
    ids=["infer-pushes", "simulate-pushes", "infer-out-file", "infer-out-read-only", "forest"],
)
def test_checked_before_any_work(args, needle, no_work, tmp_path, monkeypatch, capsys):
    if "/sys/pushtoknow/run" in args and (not Path("/sys").is_dir() or _sys_is_writable()):
        pytest.skip("no read-only /sys here")
    (tmp_path / "file").write_text("a file, not a folder")
    code, text = _run(monkeypatch, capsys, [a.replace("{tmp}", str(tmp_path)) for a in args])
    _one_error(code, text, needle)


def test_the_minimum_sigma_points_work(tmp_path, monkeypatch, capsys):
    """`--sigma-points` at its documented minimum runs a whole push (10 used to fail inside
    the covariance)."""
    from pushtoknow.common.params import MIN_SIGMA_POINTS

    args = ["infer", "--object", "catalogue:3", "--pushes", "1", "--out", str(tmp_path / "run"),
            "--sigma-points", str(MIN_SIGMA_POINTS), "--json",
            "--estimator", "vt-addf"]  # fmt: skip
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text


def test_a_stale_ray_address_fails_in_seconds(tmp_path, monkeypatch, capsys):
    """`--ray auto` with RAY_ADDRESS where nothing listens: ray.init would retry for minutes;
    the address is checked first (5 s at most) and named."""
    ray = pytest.importorskip("ray")

    def init(*args, **kwargs):
        raise AssertionError("ray.init reached: it retries for minutes on a dead address")

    monkeypatch.setattr(ray, "init", init)
    monkeypatch.setattr(ray, "is_initialized", lambda: False)
    monkeypatch.setenv("RAY_ADDRESS", "127.0.0.1:1")
    args = ["simulate", "--objects", "1", "--pushes", "1", "--out", str(tmp_path / "r"), "--ray",
            "auto"]  # fmt: skip
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, "RAY_ADDRESS=127.0.0.1:1", "no Ray cluster")


def test_a_ray_client_address_names_the_missing_package(tmp_path, monkeypatch, capsys):
    """ray://HOST:PORT needs Ray Client (`ray[client]`), not just Ray: said as such, with the
    brackets printed."""
    import importlib.util
    import socket

    pytest.importorskip("ray")
    if importlib.util.find_spec("grpc") is not None:
        pytest.skip("Ray Client is installed")
    with socket.socket() as server:  # something listens: only the package is missing
        server.bind(("127.0.0.1", 0))
        server.listen()
        address = f"ray://127.0.0.1:{server.getsockname()[1]}"
        args = ["simulate", "--objects", "1", "--pushes", "1", "--out", str(tmp_path / "r"),
                "--ray", address]  # fmt: skip
        code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, address, "ray[client]")


@pytest.fixture(scope="module")
def pretrained():
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.pretrained import resolve_model_path

    return load_checkpoint(resolve_model_path("pretrained"))


API_CASES = [  # (arguments changed, error, start of its message)
    ({"model": None}, TypeError, "model: expected TrainedModel, got NoneType"),
    ({"spec": 117}, TypeError, "spec: expected ObjectSpec, got int 117"),
    ({"config": {"pushes": 1}}, TypeError, "config: expected InferenceConfig, got dict"),
    ({"policy": "uniform"}, TypeError, "policy: expected PushPolicy or None, got str"),
    ({"seed": -1}, ValueError, "seed: must be ≥ 0"),
    ({"seed": 1.5}, TypeError, "seed: expected an integer ≥ 0, got float 1.5"),
]


def test_too_few_sigma_points_are_refused_by_the_config():
    """Below `MIN_SIGMA_POINTS` the covariance loses rank within a push: the settings refuse
    it, naming the field."""
    import pydantic

    from pushtoknow.common.params import MIN_SIGMA_POINTS
    from pushtoknow.inference import InferenceConfig

    with pytest.raises(pydantic.ValidationError, match="num_sigma_points"):
        InferenceConfig(num_sigma_points=MIN_SIGMA_POINTS - 2)
    assert InferenceConfig(num_sigma_points=MIN_SIGMA_POINTS).num_sigma_points == MIN_SIGMA_POINTS


@pytest.mark.parametrize(("change", "error", "start"), API_CASES, ids=lambda c: str(c)[:24])
def test_the_python_api_names_a_wrong_argument(pretrained, change, error, start):
    """`infer_simulated` / `infer_object` check their arguments before any simulation and
    raise one line naming the bad one (the project's error, a TypeError or ValueError)."""
    from pushtoknow.common.errors import PushToKnowError
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.testbed.object_refs import load_object_spec

    config = InferenceConfig(estimator="vt-addf", pushes=1)
    args = {"model": pretrained, "spec": load_object_spec("catalogue:117"), "config": config,
            "seed": 0, **change}  # fmt: skip
    with pytest.raises(error) as info:
        infer_simulated(**args)
    message = str(info.value)
    assert isinstance(info.value, PushToKnowError) and "\n" not in message
    assert message.startswith(start), message


def test_infer_object_names_a_wrong_executor(pretrained):
    from pushtoknow.inference import infer_object

    with pytest.raises(TypeError, match="^executor: expected PushExecutor, got str 'catalogue:"):
        infer_object(pretrained, "catalogue:117")


def test_a_spec_may_be_given_by_reference(pretrained):
    from pushtoknow.inference import InferenceConfig, infer_simulated
    from pushtoknow.testbed.object_refs import load_object_spec

    result = infer_simulated(
        pretrained, "catalogue:117", InferenceConfig(estimator="vt-addf", pushes=1), 0
    )
    assert result.object_name == load_object_spec("catalogue:117").name
    assert len(result.estimates) == 1


# ---- issue 37, round two: changed inputs, run folders, overlaps, rates, locks, full disks ----

SHORT_SIM = "push:\n  horizon: 1.0\n"  # 11 samples a push: the physics is tested elsewhere


def _simulate_args(out, *extra) -> list[str]:
    return ["simulate", "--out", str(out), "--pushes", "1", "--objects-per-shard", "1",
            "--config", str(out.parent / "sim.yaml"), *map(str, extra)]  # fmt: skip


def _shard_specs(out) -> list[str]:
    from pushtoknow.datasets.shards import read_shard

    return [ep.spec.name for p in sorted(out.glob("shard-*.h5")) for ep in read_shard(p, False)]


def test_an_edited_objects_file_is_refused_not_skipped_or_mixed(tmp_path, monkeypatch, capsys):
    """`--objects-from FILE` counts by the file's bytes: after an edit, a rerun (finished or
    interrupted) is refused naming the file, instead of skipping the old objects or mixing
    old and new; the same bytes under another path resume."""
    (tmp_path / "sim.yaml").write_text(SHORT_SIM)
    objects = tmp_path / "objects.yaml"
    objects.write_text("- catalogue:3\n- catalogue:5\n")
    out = tmp_path / "ds"
    args = _simulate_args(out, "--objects", "2", "--objects-from", objects)
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text
    before = {p.name: p.read_bytes() for p in out.glob("shard-*.h5")}
    objects.write_text("- catalogue:7\n- catalogue:9\n")
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, str(objects), "holds a run of other inputs", "another --out")
    assert {p.name: p.read_bytes() for p in out.glob("shard-*.h5")} == before
    (out / "shard-00001.h5").unlink()  # interrupted before the second shard: still refused
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, str(objects), "holds a run of other inputs")
    assert sorted(p.name for p in out.glob("shard-*.h5")) == ["shard-00000.h5"]
    moved = tmp_path / "elsewhere.yaml"  # the original bytes under another path: resumed
    moved.write_text("- catalogue:3\n- catalogue:5\n")
    args = _simulate_args(out, "--objects", "2", "--objects-from", moved)
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0 and "wrote 1 shards, skipped 1" in text, text
    assert {p.name: p.read_bytes() for p in out.glob("shard-*.h5")} == before


MIT_SAMPLE = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets" / "mit-push-sample"


@pytest.fixture(scope="module")
def mit_sample() -> Path:
    if not MIT_SAMPLE.is_dir():
        pytest.skip(f"MIT Push sample files not found at {MIT_SAMPLE}")
    return MIT_SAMPLE.resolve()


def test_an_import_of_changed_source_files_is_refused(mit_sample, tmp_path, monkeypatch, capsys):
    """`import-mit SRC --out D` counts the source files by their bytes: rerun after one of
    them changed, it names that file instead of keeping the old shard."""
    import json
    import shutil

    src = tmp_path / "src"
    shutil.copytree(mit_sample, src)
    out = tmp_path / "imported"
    code, text = _run(monkeypatch, capsys, ["import-mit", str(src), "--out", str(out), "--json"])
    assert code == 0, text
    shard = (out / "shard-00000.h5").read_bytes()
    changed = sorted(src.glob("*.json"))[1]
    data = json.loads(changed.read_text())
    data["ft_wrench"] = [[t, fx + 0.5, fy, tz] for t, fx, fy, tz in data["ft_wrench"]]
    changed.write_text(json.dumps(data))
    code, text = _run(monkeypatch, capsys, ["import-mit", str(src), "--out", str(out)])
    _one_error(code, text, changed.name, "holds an import of other inputs")
    assert (out / "shard-00000.h5").read_bytes() == shard


def test_a_run_folder_of_another_object_is_refused_unless_overwrite(tmp_path, monkeypatch, capsys):
    """`infer --out RUN` onto the run of another object: refused before any work unless
    --overwrite, which replaces every file of the run (no old pushes left beside new
    estimates, so `identify --pushes RUN` sees the new object)."""
    import json

    import pushtoknow.inference as inference
    from pushtoknow.datasets.shards import read_shard

    run = tmp_path / "run"
    args = ["infer", "--pushes", "1", "--estimator", "vt-addf", "--out", str(run), "--json"]
    code, text = _run(monkeypatch, capsys, [*args, "--object", "catalogue:3"])
    assert code == 0, text
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}
    first = json.loads((run / "estimates.json").read_text())["object"]
    with monkeypatch.context() as m:
        m.setattr(inference, "infer_simulated", lambda *a, **k: pytest.fail("work started"))
        code, text = _run(monkeypatch, capsys, [*args, "--object", "catalogue:5"])
    _one_error(code, text, str(run), f"another object ({first})", "--overwrite")
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before
    code, text = _run(monkeypatch, capsys, [*args, "--object", "catalogue:5", "--overwrite"])
    assert code == 0, text
    second = json.loads((run / "estimates.json").read_text())["object"]
    (ep,) = read_shard(run / "pushes" / "shard-00000.h5", images=False)
    assert second != first and ep.spec.name == second
    assert not list(run.rglob("*.tmp"))
    code, text = _run(monkeypatch, capsys, [*args, "--object", "catalogue:5", "--seed", "1"])
    assert code == 0, text  # the same object again: its run is replaced


def test_a_full_disk_while_writing_a_run_leaves_the_previous_one(tmp_path, monkeypatch, capsys):
    """The disk fills while `infer` writes its last file (the pushes): one line naming it, and
    the previous run's files are left as they were (written as a set: temporary names first,
    renamed only when all are written); no temporary file is left."""
    import errno

    import pushtoknow.datasets.shards as shards

    run = tmp_path / "run"
    args = ["infer", "--object", "catalogue:3", "--pushes", "1", "--estimator", "vt-addf",
            "--out", str(run), "--json"]  # fmt: skip
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text
    (run / "push-1.png").write_bytes(b"an earlier demo's strip")
    before = {p: p.read_bytes() for p in run.rglob("*") if p.is_file()}

    def full(run_dir, spec, records, sim_json, path=None):
        path.write_bytes(b"\x89HDF half a shard")
        raise OSError(errno.ENOSPC, "No space left on device", str(path))

    monkeypatch.setattr(shards, "write_run_pushes", full)
    code, text = _run(monkeypatch, capsys, [*args, "--seed", "1"])
    _one_error(code, text, f"disk full writing {run / 'pushes' / 'shard-00000.h5'}")
    assert {p: p.read_bytes() for p in run.rglob("*") if p.is_file()} == before


@pytest.fixture(scope="module")
def mit_import(mit_sample, tmp_path_factory):
    """The MIT Push sample pushes (plywood:rect1) imported as `estimate-real` imports them."""
    from pushtoknow.datasets.mit_import import import_mit_dataset

    out = tmp_path_factory.mktemp("mit") / "rect1"
    import_mit_dataset(mit_sample, out, as_speed=0.02, progress=False)
    return out


REAL = ["--model", "pretrained", "--trees", "5", "--no-identify", "--json"]


def _warnings(text: str) -> list[str]:
    return [ln for ln in text.splitlines() if ln.startswith("warning:")]


def test_forest_data_holding_the_object_under_test_is_named(
    mit_import, tmp_path, monkeypatch, capsys
):
    """`estimate-real --forest-data` given an import of the very pushes under test: a warning
    line naming the object and the dataset (the forest would report the truth ± 0)."""
    import json

    args = ["estimate-real", str(mit_import), "--forest-data", str(mit_import), *REAL]
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text
    (line,) = _warnings(text)
    assert f"--forest-data {mit_import} holds the object under test (mit:plywood:rect1)" in line
    assert "3 of its pushes shared" in line
    report = json.loads(next(ln for ln in text.splitlines() if ln.startswith("{")))
    assert any("holds the object under test" in n for n in report["notes"])


@pytest.fixture
def incomplete(two_shards, tmp_path):
    """`two_shards` interrupted after its first shard: generation.json plans 2 objects."""
    import shutil

    out = tmp_path / "incomplete"
    shutil.copytree(two_shards, out)
    (out / "shard-00001.h5").unlink()
    return out


def test_an_incomplete_forest_dataset_is_warned(
    mit_import, incomplete, monkeypatch, capsys
):  # fmt: skip
    args = ["estimate-real", str(mit_import), "--forest-data", str(incomplete), *REAL]
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text
    (line,) = _warnings(text)
    assert f"--forest-data {incomplete} is incomplete: 1 of 2 objects written" in line


def test_training_on_an_incomplete_dataset_is_warned(incomplete, tmp_path, monkeypatch, capsys):
    """The warning comes first (here the one object left is then too few to train on)."""
    args = ["train", "--data", str(incomplete), "--out", str(tmp_path / "run")]
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, "training needs at least 2")
    (line,) = _warnings(text)
    assert f"--data {incomplete} is incomplete: 1 of 2 objects written" in line


def test_real_pushes_at_another_rate_get_a_note(
    mit_sample, two_shards, tmp_path, monkeypatch, capsys
):
    """Pushes imported at 50 Hz for a 10 Hz model: the report says so (the filter steps once a
    sample, and its intervals assume the model's rate)."""
    import json

    out = tmp_path / "at50"
    code, text = _run(monkeypatch, capsys, ["import-mit", str(mit_sample), "--out", str(out),
                                            "--rate", "50", "--json"])  # fmt: skip
    assert code == 0, text
    args = ["estimate-real", str(out), "--forest-data", str(two_shards), *REAL]
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0, text
    report = json.loads(next(ln for ln in text.splitlines() if ln.startswith("{")))
    (note,) = [n for n in report["notes"] if n.startswith("rate:")]
    assert "imported at 50 Hz, the model runs at 10 Hz" in note
    assert "intervals assume 10 Hz samples" in note and "--rate 10" in note
    args = [a for a in args if a != "--json"]
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0 and "note: rate: the pushes were imported at 50 Hz" in text, text


def test_a_second_simulate_into_the_same_folder_is_refused(tmp_path, monkeypatch, capsys):
    """A lock file with the writer's PID: a second `simulate` into the folder is refused in one
    line naming the other run (instead of calling its half-written shard corrupt); a lock
    whose process is gone is taken over."""
    import json
    import os
    import socket
    import subprocess

    from pushtoknow.datasets.lock import LOCK_FILE

    (tmp_path / "sim.yaml").write_text(SHORT_SIM)
    out = tmp_path / "ds"
    out.mkdir()
    lock = out / LOCK_FILE
    host = socket.gethostname()
    lock.write_text(json.dumps({"pid": os.getppid(), "host": host}))  # a live process
    args = _simulate_args(out, "--objects", "1")
    code, text = _run(monkeypatch, capsys, args)
    _one_error(code, text, str(out), f"in use by another run (PID {os.getppid()} on {host}")
    assert not list(out.glob("shard-*")) and not (out / "generation.json").exists()
    ended = subprocess.Popen(["true"])
    ended.wait()
    lock.write_text(json.dumps({"pid": ended.pid, "host": host}))  # its process is gone
    code, text = _run(monkeypatch, capsys, args)
    assert code == 0 and "wrote 1 shards" in text, text
    assert not lock.exists()  # released


def test_a_full_disk_during_simulate_names_the_shard_and_resumes(tmp_path, monkeypatch, capsys):
    """The disk fills while the second shard is written: one line "disk full writing SHARD",
    exit 2, no traceback; no temporary file is left, the first shard is kept, and the
    resumed dataset is bit-identical to one written without interruption."""
    import errno

    import pushtoknow.datasets.shards as shards

    (tmp_path / "sim.yaml").write_text(SHORT_SIM)
    real_write = shards.atomic_write

    def filling(path, content):
        if path.name != "shard-00001.h5":
            return real_write(path, content)

        def half(tmp):
            tmp.write_bytes(b"\x89HDF" * 1000)
            raise OSError(errno.ENOSPC, "No space left on device", str(tmp))

        return real_write(path, half)

    out, whole = tmp_path / "ds", tmp_path / "whole"
    with monkeypatch.context() as m:
        m.setattr(shards, "atomic_write", filling)
        code, text = _run(monkeypatch, capsys, _simulate_args(out, "--objects", "2"))
    _one_error(code, text, f"disk full writing {out / 'shard-00001.h5'}")
    assert sorted(p.name for p in out.iterdir()) == ["generation.json", "shard-00000.h5"]
    code, text = _run(monkeypatch, capsys, _simulate_args(out, "--objects", "2"))
    assert code == 0 and "wrote 1 shards, skipped 1" in text, text
    code, text = _run(monkeypatch, capsys, _simulate_args(whole, "--objects", "2"))
    assert code == 0, text
    for name in ("shard-00000.h5", "shard-00001.h5", "generation.json"):
        assert (out / name).read_bytes() == (whole / name).read_bytes(), name
