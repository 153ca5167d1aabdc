"""`pushtoknow bench sysid`: the summary arithmetic on hand-made rows, a one-line error, and a
tiny run through the CLI (1 object, 1 push, 1 sysid iteration: ~15 s; the real numbers come
from the CLI)."""

import json
import math
import os
import subprocess
import sys

import pytest

from pushtoknow.bench.sysid import SCENE_NOTE, SysidObjectRow, summarise
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.identification.sysid_baseline import FD_STEP

EXE = [sys.executable, "-m", "pushtoknow.cli"]


def run(*args, check=True):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([*EXE, *args], capture_output=True, text=True, env=env, check=check)


def _row(i, fit_s, errors, zscores, bounded=None, mu_m=0.0, evaluations=10):
    def per(values):
        return dict(zip(PARAM_NAMES, values))

    return SysidObjectRow(
        ref=f"random:1:{i}",
        name=f"random:1:{i}:box",
        fit_s=fit_s,
        object_s=fit_s + 1.0,
        error_norm=per(errors),
        zscore=per(zscores),
        interval_bounded=per(bounded or [True] * 5),
        mu_m_rel_error=mu_m,
        estimate=per([1.0] * 5),
        truth=per([1.0] * 5),
        evaluations=evaluations,
        rollouts=5 * evaluations,
        iterations=3,
        reduced_chi2=1.0,
        status="Terminated after 3 iterations: norm(dx) < tol.",
        profiles_chosen=["constant"],
    )


def test_summary_pools_the_rows():
    rows = [
        _row(0, 10.0, [0.1, 0.0, 0.2, 0.3, 0.4], [0.5, 1.64, -1.0, 0.0, 3.0], mu_m=0.02),
        _row(1, 30.0, [0.3, 0.3, 0.2, 0.0, 0.4], [-2.0, 1.65, 1.0, 0.0, 0.1], mu_m=-0.04),
        _row(
            2,
            20.0,
            [0.2, 0.6, 0.2, 0.0, 0.1],
            [1.0, math.nan, -1.7, 0.0, 0.0],
            [True, True, True, True, False],
            evaluations=40,
        ),
    ]
    s = summarise(rows)
    assert s.objects == 3
    assert s.fit_s_median == 20.0 and s.object_s_median == 21.0
    assert s.evaluations_median == 10.0
    want = {"mass": 0.2, "friction": 0.3, "com_x": 0.2, "com_y": 0.1, "inertia": 0.3}
    assert s.error_norm_mean == pytest.approx(want)
    assert s.error_norm_overall == pytest.approx(1.1 / 5)
    assert s.mu_m_rel_error_mean_abs == pytest.approx(0.02)
    # |z| ≤ 1.645 covers; NaN (no covariance) does not; 0 (an unbounded interval) does
    assert s.coverage90 == pytest.approx(
        {"mass": 2 / 3, "friction": 1 / 3, "com_x": 2 / 3, "com_y": 1.0, "inertia": 2 / 3}
    )
    assert s.unbounded_intervals == 1


def test_summary_of_nothing_is_nan():
    s = summarise([])
    assert s.objects == 0 and s.unbounded_intervals == 0
    assert math.isnan(s.fit_s_median) and math.isnan(s.coverage90["mass"])


def test_bad_object_is_a_one_line_error():
    r = run("bench", "sysid", "--object", "random:x:0", check=False)
    assert r.returncode == 2 and r.stdout == ""
    assert "random:x:0" in r.stderr and "Traceback" not in r.stderr


def test_tiny_run_through_the_cli(tmp_path):
    out = tmp_path / "bench.json"
    r = run(
        "bench", "sysid", "--objects", "1", "--pushes", "1", "--max-iterations", "1",
        "--objects-seed", "2026", "--threads", "1", "--json", "--out", out,
    )  # fmt: skip
    report = json.loads(r.stdout)  # nothing else on stdout
    assert json.loads(out.read_text()) == report
    assert "object 1/1" in r.stderr and "known outline" in r.stderr
    assert report["scene"] == SCENE_NOTE and report["policy"] == "uniform"
    assert report["pushes"] == 1 and report["max_iterations"] == 1 and report["threads"] == 1
    assert report["fd_step"] == FD_STEP
    [obj] = report["objects"]
    assert obj["ref"] == "random:2026:0" and obj["name"].startswith("random:2026:0:")
    assert obj["profiles_chosen"] == [report["profiles"][0]]  # uniform: the first profile
    assert obj["evaluations"] >= 6 and obj["rollouts"] == obj["evaluations"]
    assert 0 < obj["fit_s"] <= obj["object_s"]
    assert obj["iterations"] == 1 and obj["status"].startswith("Terminated")
    for key in ("error_norm", "zscore", "interval_bounded", "estimate", "truth"):
        assert set(obj[key]) == set(PARAM_NAMES), key
    s = report["summary"]
    assert s["objects"] == 1 and s["fit_s_median"] == obj["fit_s"]
    assert s["error_norm_mean"] == pytest.approx(obj["error_norm"])
