"""`pushtoknow bench physics`: the fidelity report, quick mode, through the CLI."""

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from pushtoknow.bench.physics_fidelity import render_markdown, summary_rows

EXE = [sys.executable, "-m", "pushtoknow.cli"]
V1 = Path(__file__).parents[2] / "docs" / "physics-v1.json"


def run(*args, check=True):
    env = {**os.environ, "MUJOCO_GL": os.environ.get("MUJOCO_GL", "egl")}
    return subprocess.run([*EXE, *args], capture_output=True, text=True, env=env, check=check)


@pytest.mark.slow
def test_quick_report_beside_version_1(tmp_path):
    md = tmp_path / "PHYSICS.md"
    r = run("bench", "physics", "--quick", "--json", "--before", str(V1), "--markdown", str(md))
    report = json.loads(r.stdout)
    assert report["testbed_version"] == 2
    centred = [c for c in report["chaos"] if c["offset_m"] == 0.0]
    assert centred and all(c["final_mm"] <= 1.0 for c in centred)
    assert all(abs(s["ratio"] - 1.0) < 0.01 for s in report["steady"])
    assert report["realtime_factor"] > 0
    page = md.read_text()
    assert "| figure | testbed v1 | testbed v2 | target |" in page
    # One row per figure, each with a v1 value, a v2 value and a target.
    assert page.count("\n| ") - 1 == len(summary_rows(report))


def test_rendered_table_names_what_was_not_measured():
    report = json.loads(V1.read_text())
    page = render_markdown(report)
    assert "| release: least table reaction / (m·g) | not measured |" in page


def test_unreadable_before_file_is_a_one_line_error(tmp_path):
    bad = tmp_path / "bad.json"
    bad.write_text("{not json")
    r = run("bench", "physics", "--quick", "--before", str(bad), check=False)
    assert r.returncode == 2
    assert "--before" in r.stderr and "Traceback" not in r.stderr
