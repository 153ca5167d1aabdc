"""Bad input through the installed entry point (`pushtoknow.cli.main.main`, in process): each
case ends in exit status 2 with a message naming the option or file and the problem, never a
traceback, and nothing already written is touched."""

from __future__ import annotations

import sys

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
]


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
    being written is left as a *.tmp that the next run discards, no finished file is touched."""
    import errno

    import h5py

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
    from pushtoknow.testbed.config import PushConfig, SimConfig

    cfg = GenerationConfig(objects=1, pushes=1, seed=0, sim=SimConfig(push=PushConfig(horizon=1.0)))
    generate_dataset(tmp_path / "one", cfg, progress=False)
    code, text = _run(monkeypatch, capsys, ["train", "--data", str(tmp_path / "one"), "--out",
                                            str(tmp_path / "run")])  # fmt: skip
    assert code == 2 and "1 object(s); training needs at least 2" in text
    assert not (tmp_path / "run").exists()  # nothing written
