"""The real-data benchmark (`pushtoknow.evaluation.real_benchmark`, `pushtoknow evaluate-real`):
rows against hand-computed cases, the MIT file checks, the JSON on synthetic MIT Push files and
a simulated dataset, and the one-line errors."""

from __future__ import annotations

import json
import math
import shutil
from pathlib import Path

import h5py
import numpy as np
import pytest
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import GRAVITY, PARAM_NAMES, PARAM_RANGES
from pushtoknow.datasets.mit_push import PUSHER_RADIUS, check_mit_push, read_mit_push
from pushtoknow.evaluation.real_benchmark import (
    Z90,
    estimate_rows,
    evaluate_real,
    gaussian_rows,
)
from pushtoknow.inference.estimator import belief_to_estimate
from tiny_training import tiny_dataset, tiny_run

T0 = 1_476_729_000.0  # Unix s, like the real files
MU, RECT1_MASS, RECT1_HALF = 0.3, 0.8374, 0.045  # the synthetic surface's μ; rect1 (kg, m)
V, T_MOVE, T_STOP, T_END = 0.05, 0.5, 2.5, 3.0  # m/s, s, s, s
TREES = 5


# ------------------------------------------------------------------------------------------
# synthetic MIT Push files
# ------------------------------------------------------------------------------------------
def _name(surface="abs", shape="rect1", v="50", t="0.000", ext="json") -> str:
    return f"motion_surface={surface}_shape={shape}_a=0_v={v}_i=0.000_s=0.500_t={t}.{ext}"


def _streams(seed=0, touch=True, sign=1.0, frozen=False, late_force=False) -> dict:
    """rect1 at rest (yaw 0.4 rad) pushed through its centre at V from T_MOVE to T_STOP: it
    translates with the probe (a pure translation) against μ·m·g of friction; the probe reads
    −F (the dataset's sign; `sign` −1 flips it) with 0.05 N noise, 0 N + noise at rest.
    frozen: one reading throughout; late_force: the force clock starts at T_STOP."""
    rng = np.random.default_rng(seed)
    th = 0.4
    u = np.array([math.cos(th), math.sin(th)])
    c0 = np.array([0.35, 0.02])
    t_tip, t_obj = (np.arange(int(T_END * r) + 1) / r for r in (250, 200))
    t_ft = (np.arange(int(T_END * 500)) + 0.5) / 500
    if late_force:
        t_ft = t_ft[t_ft >= T_STOP]
    d_tip = V * np.clip(t_tip - T_MOVE, 0.0, T_STOP - T_MOVE)
    tip = c0 - (RECT1_HALF + PUSHER_RADIUS) * u + d_tip[:, None] * u
    d_obj = V * np.clip(t_obj - T_MOVE, 0.0, T_STOP - T_MOVE) * (1.0 if touch else 0.0)
    obj = c0 + d_obj[:, None] * u
    f = np.where((t_ft >= T_MOVE) & (t_ft < T_STOP) & touch, MU * RECT1_MASS * GRAVITY, 0.0)
    reading = -sign * f[:, None] * u + rng.normal(0.0, 0.05, (len(t_ft), 2))
    if frozen:
        reading[:] = [-1.2, 0.4]
    return {
        "tip_pose": np.column_stack([T0 + t_tip, tip, 0 * t_tip]),
        "object_pose": np.column_stack([T0 + t_obj, obj, th + 0 * t_obj]),
        "ft_wrench": np.column_stack([T0 + t_ft, reading, 0 * t_ft]),
    }


def _write(path: Path, streams: dict) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix == ".json":
        path.write_text(json.dumps({k: v.tolist() for k, v in streams.items()}))
    else:
        with h5py.File(path, "w") as h5:
            for k, v in streams.items():
                h5.create_dataset(k, data=v)
    return path


@pytest.fixture(scope="module")
def mit_dir(tmp_path_factory) -> Path:
    """abs:rect1, two pushes in two sub-folders (json, h5) and one that misses the object."""
    d = tmp_path_factory.mktemp("mit-bench")
    _write(d / "a" / _name(), _streams(0))
    _write(d / "b" / "deep" / _name(t="0.349", ext="h5"), _streams(1))
    _write(d / "b" / _name(t="1.396"), _streams(2, touch=False))
    return d


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return tiny_run(tmp_path_factory)


@pytest.fixture(scope="module")
def forest_dir(tmp_path_factory) -> Path:
    return tiny_dataset(tmp_path_factory)


@pytest.fixture(scope="module")
def bench(mit_dir, run_dir, forest_dir):
    return evaluate_real(
        mit_dir, forest_dir, 0, ("vt-addf",), model=run_dir, forest_trees=TREES
    ).to_json()


# ------------------------------------------------------------------------------------------
# rows: hand-computed cases
# ------------------------------------------------------------------------------------------
def test_gaussian_rows_hand_computed():
    mean = np.array([1.0, 0.5, 0.001, -0.002, 0.001])
    std = np.array([0.5, 0.1, 0.002, 0.001, 2e-4])
    truth = np.array([2.0, 0.5, 0.0, np.nan, 0.0016])
    rows = gaussian_rows(mean, std, truth)
    assert rows["mass"]["z"] == pytest.approx(2.0)  # (2 − 1) / 0.5
    assert rows["mass"]["interval90"] == pytest.approx([1 - 0.5 * 1.6448536, 1 + 0.5 * 1.6448536])
    assert rows["mass"]["covered"] is False  # 2 > 1.822
    assert rows["friction"]["z"] == 0.0 and rows["friction"]["covered"] is True
    assert rows["com_x"]["z"] == pytest.approx(-0.5) and rows["com_x"]["covered"] is True
    assert rows["com_y"]["z"] is None and rows["com_y"]["covered"] is None  # truth unknown
    assert rows["inertia"]["z"] == pytest.approx(3.0) and rows["inertia"]["covered"] is False
    assert set(rows) == set(PARAM_NAMES)
    assert set(rows["mass"]) == {"mean", "std", "interval90", "z", "covered"}


def _normalised_log(value: float, name: str) -> float:
    lo, hi = PARAM_RANGES[name]
    return 2 * (math.log(value) - math.log(lo)) / (math.log(hi) - math.log(lo)) - 1


def test_estimate_rows_hand_computed():
    """A log-normal m: z in the normalised (log) space, interval the exp of mean ± 1.645 σ."""
    mean = np.array([0.1, -0.2, 0.0, 0.0, 0.3])
    sd = np.array([0.2, 0.1, 0.5, 0.4, 0.3])
    est = belief_to_estimate(1, mean, np.diag(sd**2))
    truth = np.array([0.9, 0.45, 0.004, np.nan, 1.1e-3])
    rows = estimate_rows(est, truth)
    z_m = (_normalised_log(0.9, "mass") - 0.1) / 0.2
    assert rows["mass"]["z"] == pytest.approx(z_m)
    lo, hi = PARAM_RANGES["mass"]
    to_si = lambda z: math.exp(math.log(lo) + (z + 1) / 2 * (math.log(hi) - math.log(lo)))  # noqa: E731
    interval = [to_si(0.1 - Z90 * 0.2), to_si(0.1 + Z90 * 0.2)]
    assert rows["mass"]["interval90"] == pytest.approx(interval, rel=1e-9)
    for n in ("mass", "friction", "com_x", "inertia"):
        r = rows[n]
        assert r["covered"] == (abs(r["z"]) <= Z90), n
        assert r["covered"] == (
            r["interval90"][0] <= truth[PARAM_NAMES.index(n)] <= r["interval90"][1]
        )
    c_lo, c_hi = PARAM_RANGES["com_x"]
    z_c = ((0.004 - c_lo) / (c_hi - c_lo) * 2 - 1) / 0.5
    assert rows["com_x"]["z"] == pytest.approx(z_c)
    assert rows["com_y"]["z"] is None and rows["com_y"]["covered"] is None


# ------------------------------------------------------------------------------------------
# file checks (datasets.mit_push.check_mit_push)
# ------------------------------------------------------------------------------------------
@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"frozen": True}, r"ft_wrench: frozen, \(f_x, f_y\) = \[-1.2, 0.4\] N"),
        ({"sign": -1.0}, "sign flipped"),
        ({"touch": False}, "no contact"),
        ({"late_force": True}, "clocks overlap"),
    ],
)
def test_check_refuses_bad_files_naming_them(tmp_path, kwargs, match):
    path = _write(tmp_path / _name(), _streams(**kwargs))
    with pytest.raises(DatasetError, match=match) as e:
        check_mit_push(read_mit_push(path))
    assert path.name in str(e.value) and "\n" not in str(e.value)


def test_check_accepts_a_good_push_and_a_miss_when_asked(tmp_path):
    check_mit_push(read_mit_push(_write(tmp_path / _name(), _streams())))
    miss = read_mit_push(_write(tmp_path / _name(t="1.396"), _streams(touch=False)))
    check_mit_push(miss, contact=False)


# ------------------------------------------------------------------------------------------
# the benchmark's JSON
# ------------------------------------------------------------------------------------------
def test_json_keys_truth_and_skipped_push(bench):
    assert list(bench["objects"]) == ["abs:rect1"]
    o = bench["objects"]["abs:rect1"]
    assert o["pushes"] == 2 and len(o["files"]) == 2
    assert [s["file"] for s in o["skipped"]] == ["b/" + _name(t="1.396")]
    assert "no contact" in o["skipped"][0]["reason"]
    assert o["truth"]["mass"] == RECT1_MASS and o["truth"]["com_x"] == 0.0
    assert o["truth"]["friction"] == pytest.approx(MU, rel=0.05)  # measured, pure translation
    ref = o["friction_reference"]
    assert [p["file"] for p in ref["pushes"]] == o["files"]
    # the pooled pure translations' μ is a mean of pushes' means: never above their largest
    assert ref["lower_bound"] >= o["truth"]["friction"] * (1 - 1e-12)
    assert set(o["methods"]) == {"vt-addf", "prior", "forest"}
    assert o["prior_of"] == "vt-addf"
    for rows in o["methods"].values():
        assert set(rows) == set(PARAM_NAMES)
        for r in rows.values():
            assert set(r) == {"mean", "std", "interval90", "z", "covered"}
            assert r["interval90"][0] <= r["mean"] <= r["interval90"][1]
            assert isinstance(r["covered"], bool) and math.isfinite(r["z"])
    mm = o["mu_m"]
    assert mm["truth"] == pytest.approx(o["truth"]["friction"] * RECT1_MASS)
    for r in mm["methods"].values():
        assert r["rel_error"] == pytest.approx(r["mean"] / mm["truth"] - 1)
    f = bench["surfaces"]["abs"]["friction"]
    assert set(f) == {"measured", "vt-addf", "prior", "forest"}
    assert f["vt-addf"]["mean"] == o["methods"]["vt-addf"]["friction"]["mean"]
    assert f["vt-addf"]["std"] == 0.0 and f["vt-addf"]["spread"] is None  # one object


def test_force_balance_rows(bench):
    """m from force and acceleration: one row per object and per used push. The synthetic
    probe is never clear of the outline (the missed push runs through it), so its own mass is
    unknown and m is not identified, saying so."""
    assert bench["probe_mass"] == {"mass": None, "std": None, "samples": 0, "pushes": []}
    fb = bench["objects"]["abs:rect1"]["force_balance"]
    o = fb["object"]
    assert set(o) >= {"mass", "std", "identified", "reason", "band_hz", "z", "covered", "rel_error"}
    assert not o["identified"] and o["mass"] is None and "probe's mass" in o["reason"]
    assert [p["file"] for p in fb["pushes"]] == bench["objects"]["abs:rect1"]["files"]
    assert all(not p["identified"] for p in fb["pushes"])


def test_surface_spread_and_deterministic(mit_dir, run_dir, tmp_path, bench):
    """Two objects on one surface: μ's mean, std and spread across them; same seed, same JSON."""
    d = tmp_path / "two"
    shutil.copytree(mit_dir, d)
    _write(d / _name(shape="rect2"), _streams(3))
    got = evaluate_real(d, None, 0, ("vt-addf",), model=run_dir).to_json()
    assert list(got["objects"]) == ["abs:rect1", "abs:rect2"]
    f = got["surfaces"]["abs"]["friction"]["vt-addf"]
    v = np.array([got["objects"][k]["methods"]["vt-addf"]["friction"]["mean"] for k in f["values"]])
    assert f["mean"] == pytest.approx(v.mean()) and f["std"] == pytest.approx(v.std())
    assert f["spread"] == pytest.approx(np.ptp(v) / v.mean())
    assert got["objects"]["abs:rect1"]["methods"] == {
        k: v for k, v in bench["objects"]["abs:rect1"]["methods"].items() if k != "forest"
    }


def test_a_simulated_dataset_is_an_object_folder(forest_dir, run_dir):
    got = evaluate_real(forest_dir, None, 0, ("vt-addf",), max_pushes=1, model=run_dir)
    data = got.to_json()
    assert len(data["objects"]) == 6 and data["surfaces"] == {}
    for key, o in data["objects"].items():
        assert key.startswith("unknown:") and o["source"] == "dataset" and o["pushes"] == 1
        assert all(o["truth"][n] is not None for n in PARAM_NAMES)  # the simulator's truth
        assert set(o["methods"]) == {"vt-addf", "prior"}
    assert "| μ·m (kg) |" in got.table()


def test_physics_row_on_one_push(mit_dir, run_dir):
    """The physics filter with the known outline and tracked poses, no images (~10 s)."""
    report = evaluate_real(mit_dir, None, 0, ("physics",), max_pushes=1, model=run_dir)
    got = report.to_json()
    o = got["objects"]["abs:rect1"]
    assert set(o["methods"]) == {"physics", "prior"} and o["prior_of"] == "physics"
    assert len(o["physics"]["updates"]) == 1
    r = o["mu_m"]["methods"]["physics"]
    assert abs(r["rel_error"]) < 0.3  # the steady force of a pure translation: μ·m·g
    # a real object starts from everyday objects' prior: μ 0.05–1.2, wide in m
    assert o["physics"]["prior"]["friction"] == [0.05, 1.2]
    prior_m = o["methods"]["prior"]["mass"]["interval90"]
    assert prior_m[1] > 3.0  # the catalogue prior ends at 1.2 kg
    section = report.results_section("pushtoknow evaluate-real DIR")
    assert section.startswith("## Real objects (`evaluate-real`)")
    assert "    pushtoknow evaluate-real DIR" in section and "| abs:rect1 | m (kg) |" in section
    assert "abs:rect1: physics filter, 1 updates, reduced χ²" in section
    assert "abs:rect1: its pushes' mean contact force / (m g) reaches" in section


# ------------------------------------------------------------------------------------------
# CLI and its one-line errors
# ------------------------------------------------------------------------------------------
def _invoke(*args):
    return CliRunner().invoke(app, ["evaluate-real", *map(str, args)])


def _one_line_error(res, *texts):
    assert res.exit_code == 2, (res.output, res.exception)
    assert res.exception is None or isinstance(res.exception, SystemExit)
    lines = [ln for ln in res.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("error:"), res.output
    for t in texts:
        assert t in res.output.replace("\n", ""), (t, res.output)


def test_cli_json_and_atomic_out(mit_dir, run_dir, tmp_path, bench):
    out = tmp_path / "r" / "bench.json"
    res = _invoke(mit_dir, "--model", run_dir, "--estimators", "vt-addf", "--json", "--out", out)
    assert res.exit_code == 0, (res.output, res.exception)
    got = json.loads(res.stdout)
    assert json.loads(out.read_text()) == got
    assert not list(out.parent.glob("*.tmp"))
    assert (
        got["objects"]["abs:rect1"]["methods"]["vt-addf"]
        == (bench["objects"]["abs:rect1"]["methods"]["vt-addf"])
    )
    res = _invoke(mit_dir, "--model", run_dir, "--estimators", "vt-addf")
    assert res.exit_code == 0, (res.output, res.exception)
    for text in ("abs:rect1", "μ·m (kg)", "vt-addf", "prior", "no contact"):
        assert text in res.stdout, text


def test_cli_errors_are_one_line(tmp_path, mit_dir, run_dir, forest_dir):
    (tmp_path / "empty" / "sub").mkdir(parents=True)
    _one_line_error(_invoke(tmp_path / "empty", "--model", run_dir), "no objects found")
    bad = tmp_path / "bad"
    frozen = _write(bad / _name(), _streams(frozen=True))
    _one_line_error(_invoke(bad, "--model", run_dir), frozen.name, "frozen")
    flipped = tmp_path / "flipped"
    path = _write(flipped / _name(), _streams(sign=-1.0))
    _one_line_error(_invoke(flipped, "--model", run_dir), path.name, "sign flipped")
    unreadable = tmp_path / "unreadable"
    path = unreadable / _name()
    path.parent.mkdir()
    path.write_text("{not json")
    _one_line_error(_invoke(unreadable, "--model", run_dir), path.name, "corrupt JSON")
    partial = tmp_path / "partial"
    shutil.copytree(forest_dir, partial)
    gen = json.loads((partial / "generation.json").read_text())
    gen["config"]["objects"] = 99
    (partial / "generation.json").write_text(json.dumps(gen))
    _one_line_error(
        _invoke(mit_dir, "--model", run_dir, "--forest-data", partial), "forest data incomplete"
    )
    _one_line_error(
        _invoke(mit_dir, "--model", run_dir, "--forest-data", tmp_path / "empty"), "shard"
    )
    res = _invoke(mit_dir, "--estimators", "physics,magic")
    assert res.exit_code == 2 and "--estimators" in res.output


def test_a_recording_file_is_an_object(forest_dir, run_dir, tmp_path):
    """A recording (`datasets.recording`) in a sub-folder: the physics filter replays it with
    its stored outline; vt-addf is skipped with its reason (no camera model)."""
    from dataclasses import replace

    from pushtoknow.datasets.recording import recording_meta, write_recording
    from pushtoknow.datasets.shards import list_shards, read_shard
    from tiny_training import SIM

    ep = read_shard(list_shards(forest_dir)[0], images=False)[0]
    meta = replace(recording_meta(ep.spec, SIM), surface="wood")
    (tmp_path / "robot").mkdir()
    write_recording(tmp_path / "robot" / "pushes.h5", ep.records, meta)
    got = evaluate_real(tmp_path, None, 0, max_pushes=1, model=run_dir).to_json()
    (key,) = got["objects"]
    o = got["objects"][key]
    assert key == f"wood:{meta.name}" and o["source"] == "recording" and o["pushes"] == 1
    assert o["files"] == ["robot/pushes.h5"]
    assert set(o["methods"]) == {"physics", "prior"}
    assert "vt-addf needs RGB-D" in o["skipped_methods"]["vt-addf"]
    assert o["truth"]["mass"] == pytest.approx(ep.spec.params.mass)
    assert list(got["surfaces"]["wood"]["friction"]) == ["physics", "prior"]
