"""CLI end to end (subprocess, as a user runs it)."""

import json
import os
import subprocess
import sys

import pytest

EXE = [sys.executable, "-m", "pushtoknow.cli"]


def run(*args, env=None, check=True):
    e = {**os.environ, **(env or {})}
    return subprocess.run([*EXE, *args], capture_output=True, text=True, env=e, check=check)


@pytest.mark.slow
def test_simulate_then_info(tmp_path):
    out = tmp_path / "ds"
    r = run("simulate", "--objects", "4", "--pushes", "2", "--out", str(out), "--seed", "0")
    assert "wrote 1 shards" in r.stdout
    info = json.loads(run("dataset", "info", str(out), "--json").stdout)
    assert info["schema_version"] == 1 and info["testbed_version"] == 2
    assert (info["objects"], info["pushes"], info["steps"]) == (4, 8, 8 * 61)  # 6 s at 10 Hz
    assert info["expected_objects"] == 4 and info["complete"] is True
    # an interrupted run: its record plans more objects than the shards hold
    import shutil

    cut = tmp_path / "cut"
    shutil.copytree(out, cut)
    gen = json.loads((cut / "generation.json").read_text())
    gen["config"]["objects"] = 8
    (cut / "generation.json").write_text(json.dumps(gen))
    r = run("dataset", "info", str(cut), "--json")
    assert json.loads(r.stdout)["complete"] is False
    assert "incomplete: 4 of 8 objects" in r.stderr
    # Re-running resumes: nothing to do.
    r = run("simulate", "--objects", "4", "--pushes", "2", "--out", str(out), "--seed", "0")
    assert "wrote 0 shards, skipped 1" in r.stdout


def test_bad_object_gives_clean_error(tmp_path):
    r = run(
        "push",
        "--object",
        '{"shape": "rect1", "mass": -1, "friction": 0.5, "com": [0, 0], "inertia": 0.001}',
        "--out",
        str(tmp_path / "x.png"),
        check=False,
    )
    assert r.returncode == 2
    assert "mass=-1" in r.stderr and "Traceback" not in r.stderr


def test_corrupt_dataset_gives_clean_error(tmp_path):
    (tmp_path / "shard-00000.h5").write_text("nope")
    r = run("dataset", "info", str(tmp_path), check=False)
    assert r.returncode == 2 and "shard-00000.h5" in r.stderr and "Traceback" not in r.stderr


def test_missing_gl_names_packages_and_setting(tmp_path):
    r = run("push", "--out", str(tmp_path / "x.png"), env={"MUJOCO_GL": "bogus"}, check=False)
    assert r.returncode == 2
    assert "libegl1" in r.stderr and "MUJOCO_GL" in r.stderr and "Traceback" not in r.stderr


def test_push_json(tmp_path):
    r = run("push", "--object", "catalogue:5", "--json", "--out", str(tmp_path / "s.png"))
    s = json.loads(r.stdout)
    assert s["samples"] == 61 and s["displacement_m"] > 0.0  # 6 s at 10 Hz
    assert (tmp_path / "s.png").stat().st_size > 10_000
