"""`pushtoknow identify` as a user runs it: estimates as JSON, one-line errors (exit 2)."""

import json
import os
import subprocess
import sys
from pathlib import Path

import h5py

sys.path.insert(0, str(Path(__file__).parents[1] / "identification"))
from identify_data import write_tiny_dataset

EXE = [sys.executable, "-m", "pushtoknow.cli"]


def run(*args):
    return subprocess.run(
        [*EXE, *args], capture_output=True, text=True, env=dict(os.environ), check=False
    )


def _one_line_error(r, *words):
    assert r.returncode == 2, r.stderr
    assert "Traceback" not in r.stderr
    lines = [x for x in r.stderr.strip().splitlines() if x.strip()]
    assert len(lines) == 1, r.stderr
    for w in words:
        assert w in lines[0], lines[0]


def test_identify_prints_estimates_as_json(tmp_path):
    ds = write_tiny_dataset(tmp_path / "ds")
    r = run("identify", "--pushes", str(ds), "--workers", "1", "--seed", "0", "--json")
    assert r.returncode == 0, r.stderr
    out = json.loads(r.stdout)
    (obj,) = out["objects"]
    p = obj["parameters"]
    assert set(p) == {"mass", "friction", "com_x", "com_y", "inertia"}
    lo, hi = obj["mu_m"]["interval"]
    assert lo <= 0.25 <= hi  # μ·m of the tiny object
    assert obj["rollouts"] > 0 and obj["profiles"] == ["constant"]
    assert any("inertia" in d for d in obj["unidentified"])
    assert obj["prior"]["friction"] == [0.35, 0.7]  # a testbed object: the catalogue's


def test_identify_takes_the_prior_ranges_given(tmp_path):
    ds = write_tiny_dataset(tmp_path / "ds")
    r = run("identify", "--pushes", str(ds), "--workers", "1", "--json",
            "--prior-friction", "0.05,1.2", "--prior-mass", "0.1,3")  # fmt: skip
    assert r.returncode == 0, r.stderr
    (obj,) = json.loads(r.stdout)["objects"]
    assert obj["prior"]["friction"] == [0.05, 1.2] and obj["prior"]["mass"] == [0.1, 3.0]
    _one_line_error(
        run("identify", "--pushes", str(ds), "--prior-mass", "3,0.1"), "--prior-mass", "3–0.1"
    )
    _one_line_error(run("identify", "--pushes", str(ds), "--prior-friction", "x"), "LOW,HIGH")


def test_identify_exports_the_identified_object_for_mujoco(tmp_path):
    """--export mjcf PATH writes the identified object: MuJoCo loads it with the identified
    mass and CoM; a bad kind or folder is refused before any work."""
    import mujoco
    import numpy as np

    ds = write_tiny_dataset(tmp_path / "ds")
    xml = tmp_path / "object.xml"
    r = run(
        "identify", "--pushes", str(ds), "--workers", "1", "--json", "--export", "mjcf", str(xml)
    )
    assert r.returncode == 0, r.stderr
    (obj,) = json.loads(r.stdout)["objects"]
    m = mujoco.MjModel.from_xml_path(str(xml))
    body = m.nbody - 1
    assert m.body_mass[body] == np.float64(obj["parameters"]["mass"]["mean"])
    np.testing.assert_allclose(
        m.body_ipos[body][:2],
        [obj["parameters"]["com_x"]["mean"], obj["parameters"]["com_y"]["mean"]],
        atol=1e-9,
    )
    _one_line_error(
        run("identify", "--pushes", str(ds), "--export", "sdf", str(xml)), "--export", "sdf"
    )
    _one_line_error(
        run("identify", "--pushes", str(ds), "--export", "urdf", str(tmp_path / "no" / "o.urdf")),
        "folder does not exist",
    )


def test_bad_inputs_give_one_line_errors(tmp_path):
    empty = tmp_path / "empty"
    empty.mkdir()
    _one_line_error(run("identify", "--pushes", str(empty)), "empty dataset")
    bad = tmp_path / "bad"
    bad.mkdir()
    with h5py.File(bad / "shard-00000.h5", "w") as f:
        f.attrs["schema_version"] = 7
    _one_line_error(run("identify", "--pushes", str(bad)), "schema version 7")
    ds = write_tiny_dataset(tmp_path / "ds")
    _one_line_error(
        run("identify", "--pushes", str(ds), "--shape", "missing.json"),
        "no such file or shape name",
    )


def test_identify_bench_reports_accuracy_coverage_and_compute(tmp_path):
    out = tmp_path / "bench.json"
    args = ["--objects", "1", "--pushes", "1", "--profiles", "constant", "--workers", "1"]
    r = run("identify-bench", *args, "--seed", "3", "--out", str(out), "--json")
    assert r.returncode == 0, r.stderr
    res = json.loads(r.stdout)
    assert json.loads(out.read_text())["nrmse"] == res["nrmse"]
    assert set(res["coverage90"]) == {"mass", "friction", "com_x", "com_y", "inertia", "overall"}
    assert res["mu_m_relative_error"]["max"] < 0.02  # one constant push measures μ·m
    assert res["rollouts_per_object"]["median"] > 0 and res["seconds_per_object"]["median"] > 0
    assert res["profiles"] == ["constant"]
