"""`pushtoknow bench estimator`: the summary arithmetic on hand-made rows, and a tiny run
through the CLI (1 object, 1 push, 1 torch thread: ~10 s; the real numbers come from the CLI)."""

import json
import math
import os
import subprocess
import sys

import pytest

from pushtoknow.bench.estimator_accuracy import Z90, ObjectRow, default_objects, summarise
from pushtoknow.common.params import PARAM_NAMES

EXE = [sys.executable, "-m", "pushtoknow.cli"]


def run(*args, check=True):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([*EXE, *args], capture_output=True, text=True, env=env, check=check)


def _row(i, update_s, object_s, errors, zscores, inside=None, replays=None):
    return ObjectRow(
        ref=f"random:1:{i}",
        name=f"random:1:{i}:box",
        update_s=update_s,
        object_s=object_s,
        error_norm=dict(zip(PARAM_NAMES, errors)),
        zscore=dict(zip(PARAM_NAMES, zscores)),
        mean_inside_interval=dict(zip(PARAM_NAMES, inside or [True] * 5)),
        profiles_chosen=["constant"] * len(update_s),
        replays=replays or [0] * len(update_s),
    )


def test_summary_pools_the_rows():
    rows = [
        _row(
            0,
            [1.0, 2.0],
            10.0,
            [0.1, 0.0, 0.2, 0.3, 0.4],
            [0.5, 1.64, -1.0, 0.0, 3.0],
            replays=[40, 300],
        ),
        _row(1, [3.0], 20.0, [0.3, 0.3, 0.2, 0.0, 0.4], [-2.0, 1.65, 1.0, 0.0, 0.1], replays=[50]),
        _row(
            2,
            [4.0, 5.0, 6.0],
            90.0,
            [0.2, 0.6, 0.2, 0.0, 0.1],
            [1.0, -1.7, -1.7, 0.0, -0.2],
            [True, False, True, False, True],
            [60, 45, 55],
        ),
    ]
    s = summarise(rows)
    assert s.objects == 3 and s.updates == 6
    # every update pooled: median of 1..6 (the median of the objects' medians would be 3)
    assert s.update_s_median == pytest.approx(3.5)
    assert s.update_s_max == 6.0
    assert s.object_s_median == 20.0  # the median, not the mean (40)
    assert s.replays_median == 52.5  # of every update: 40 45 50 | 55 60 300
    assert s.replays_object_median == 160  # the objects' sums: 340, 50, 160
    want = {"mass": 0.2, "friction": 0.3, "com_x": 0.2, "com_y": 0.1, "inertia": 0.3}
    assert s.error_norm_mean == pytest.approx(want)
    assert s.error_norm_overall == pytest.approx(1.1 / 5)
    # |z| ≤ 1.645: a large negative z is a miss, 1.64 a hit, 1.65 a miss
    assert s.coverage90 == pytest.approx(
        {"mass": 2 / 3, "friction": 1 / 3, "com_x": 2 / 3, "com_y": 1.0, "inertia": 2 / 3}
    )
    assert s.means_outside_interval == 2
    assert Z90 == pytest.approx(1.6449, abs=1e-4)


def test_summary_of_nothing_is_nan():
    s = summarise([])
    assert s.objects == 0 and s.updates == 0 and s.means_outside_interval == 0
    assert math.isnan(s.update_s_median) and math.isnan(s.coverage90["mass"])


def test_default_objects_are_random_refs():
    assert default_objects(3, 7) == ["random:7:0", "random:7:1", "random:7:2"]


def test_bad_profiles_are_a_one_line_error():
    r = run("bench", "estimator", "--profiles", "bogus", check=False)
    assert r.returncode == 2 and r.stdout == ""
    assert "--profiles" in r.stderr and "Traceback" not in r.stderr


def test_tiny_run_through_the_cli(tmp_path):
    out = tmp_path / "bench.json"
    r = run(
        "bench", "estimator", "--estimator", "vt-addf", "--objects", "1", "--pushes", "1",
        "--objects-seed", "2026", "--threads", "1", "--json", "--out", out,
    )  # fmt: skip
    report = json.loads(r.stdout)  # nothing else on stdout
    assert json.loads(out.read_text()) == report
    assert "object 1/1" in r.stderr
    assert report["estimator"] == "vt-addf" and report["pushes"] == 1 and report["seed"] == 0
    assert report["policy"] == "uniform" and report["profiles"]
    assert report["cpu_count"] >= 1 and report["torch_threads"] == 1
    assert isinstance(report["machine"], str) and report["machine"]
    [obj] = report["objects"]
    assert obj["ref"] == "random:2026:0" and obj["name"].startswith("random:2026:0:")
    assert len(obj["update_s"]) == 1 and obj["update_s"][0] > 0
    assert obj["object_s"] >= obj["update_s"][0]
    assert len(obj["profiles_chosen"]) == 1 and obj["profiles_chosen"][0] in report["profiles"]
    for key in ("error_norm", "zscore", "mean_inside_interval"):
        assert set(obj[key]) == set(PARAM_NAMES), key
    s = report["summary"]
    assert s["objects"] == 1 and s["updates"] == 1
    assert s["update_s_median"] == s["update_s_max"] == obj["update_s"][0]
    assert s["object_s_median"] == obj["object_s"]
    assert obj["replays"] == [0] and s["replays_median"] == 0  # the learned filter replays none
    assert s["error_norm_mean"] == pytest.approx(obj["error_norm"])
    assert s["error_norm_overall"] == pytest.approx(sum(obj["error_norm"].values()) / 5)
    for p in PARAM_NAMES:
        assert obj["error_norm"][p] >= 0
        assert s["coverage90"][p] == float(abs(obj["zscore"][p]) <= Z90)
    outside = sum(not v for v in obj["mean_inside_interval"].values())
    assert s["means_outside_interval"] == outside == 0
