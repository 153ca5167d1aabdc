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
    (["identify", "--pushes", "{tmp}/nowhere"], "no such dataset directory"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/missing.yaml"], "missing.yaml"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/broken.yaml"], "not valid YAML"),
    (["identify", "--pushes", "{tmp}", "--config", "{tmp}/unknown.yaml"], "huber_k"),
    (["simulate", "--objects", "1", "--out", "{tmp}/taken"], "file exists"),
    (["simulate", "--objects", "1", "--out", "/proc/no/such"], "no such file or directory"),
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
    (tmp_path / "unknown.yaml").write_text("huber_k: 3\n")
    taken = tmp_path / "taken"
    taken.write_text("keep me")
    code, text = _run(monkeypatch, capsys, [a.replace("{tmp}", str(tmp_path)) for a in args])
    assert code == 2, text
    assert needle in text and "Traceback" not in text
    assert taken.read_text() == "keep me"


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
