"""Estimates on real pushes (`pushtoknow.evaluation.real_object`, `pushtoknow estimate-real`):
the three MIT Push sample files of rect1, the tiny trained model and the tiny simulated
dataset."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from pushtoknow.cli.main import app
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.params import GRAVITY, PARAM_NAMES, PARAM_RANGES
from pushtoknow.datasets.mit_import import import_mit_dataset
from pushtoknow.datasets.mit_push import mit_object
from pushtoknow.evaluation.real_object import (
    REPORT_KEYS,
    estimate_real_object,
    friction_reference,
    load_real_object,
)
from pushtoknow.reporting.real_report import RealReport, markdown_table
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord
from tiny_training import SIGMA_POINTS, tiny_dataset, tiny_run

SAMPLE_DIR = Path(__file__).resolve().parents[2] / ".." / "shared" / "datasets" / "mit-push-sample"
CENTRE = "motion_surface=plywood_shape=rect1_a=0_v=100_i=1.000_s=0.500_t=0.000.json"
TREES = 10


@pytest.fixture(scope="module")
def sample_dir() -> Path:
    if not SAMPLE_DIR.is_dir():
        pytest.skip(f"MIT Push sample files not found at {SAMPLE_DIR} (real-data tests skipped)")
    return SAMPLE_DIR.resolve()


@pytest.fixture(scope="module")
def real_dir(sample_dir, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("real-rect1")
    import_mit_dataset(sample_dir, out, progress=False)
    return out


@pytest.fixture(scope="module")
def real_dir_rescaled(sample_dir, tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("real-rect1-as20")
    import_mit_dataset(sample_dir, out, as_speed=0.02, progress=False)
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory) -> Path:
    return tiny_run(tmp_path_factory)


@pytest.fixture(scope="module")
def forest_dir(tmp_path_factory) -> Path:
    return tiny_dataset(tmp_path_factory)


@pytest.fixture(scope="module")
def report(real_dir, run_dir, forest_dir) -> RealReport:
    return estimate_real_object(
        real_dir, run_dir, forest_dir, seed=0, forest_trees=TREES, identify=False
    )


def _record(force: float, rotation: float, contact=(2, 6), dropout: int | None = None):
    """A 10-sample push: |F| = force (N) along +x on samples contact[0]..contact[1], except
    `dropout` (F = 0, no contact: the probe bounced off), θ turning by `rotation` (rad);
    contact None: never touched."""
    T = 10
    tac = np.zeros((T, 3))
    if contact is not None:
        tac[contact[0] : contact[1] + 1] = (force, 0.0, 1.0)
    if dropout is not None:
        tac[dropout] = 0.0
    pose = np.zeros((T, 3))
    pose[:, 0] = np.linspace(0, 0.05, T)
    pose[:, 2] = np.linspace(0, rotation, T)
    return PushRecord(
        push=Push((0.0, 0.0), 0.0, "constant", 0.02),
        time=np.arange(T) / 10.0,
        pose=pose,
        tactile=tac,
        force_clean=tac[:, :2].copy(),
        pusher=np.zeros((T, 2)),
        rgb=None,
        depth=None,
        s0=None,
    )


# ------------------------------------------------------------------------------------------
# reference friction
# ------------------------------------------------------------------------------------------
def test_friction_reference_rule_on_synthetic_records():
    m = 0.8
    mu_m_g = 0.3 * m * GRAVITY
    # pure translation (1° turn) at 0.3·m·g; a 10° turn at another force is left out.
    recs = [_record(mu_m_g, math.radians(1.0)), _record(2 * mu_m_g, math.radians(10.0))]
    ref = friction_reference(recs, m)
    assert ref["value"] == pytest.approx(0.3, rel=1e-12)
    assert [p["pure_translation"] for p in ref["pushes"]] == [True, False]
    assert ref["pushes"][1]["mu_contact_phase"] == pytest.approx(0.6)
    assert ref["pushes"][0]["rotation_deg"] == pytest.approx(1.0)
    # the turning push's force exceeds the pure translation's: μ ≥ 0.6 bounds the reference
    assert ref["lower_bound"] == pytest.approx(0.6) and ref["lower_bound_push"] == 1
    # A bounce inside the contact phase counts as F = 0 (time average), so μ drops by 1/5.
    ref = friction_reference([_record(mu_m_g, 0.0, dropout=4)], m)
    assert ref["value"] == pytest.approx(0.3 * 4 / 5)
    assert ref["pushes"][0]["contact_samples"] == 5
    # Samples pooled over pure translations: 5 at 0.3 and 3 at 0.5 → (1.5 + 1.5) / 8.
    recs = [_record(mu_m_g, 0.0), _record(mu_m_g * 5 / 3, 0.0, contact=(1, 3))]
    assert friction_reference(recs, m)["value"] == pytest.approx(3.0 / 8)
    # No pure translation, or no contact at all: no reference.
    ref = friction_reference(
        [_record(mu_m_g, math.radians(-3.0)), _record(1.0, 0.0, contact=None)], m
    )
    assert ref["value"] is None
    assert ref["pushes"][1]["mu_contact_phase"] is None
    assert ref["lower_bound"] == pytest.approx(0.3) and ref["lower_bound_push"] == 0
    no_contact = friction_reference([_record(1.0, 0.0, contact=None)], m)
    assert no_contact["lower_bound"] is None and no_contact["lower_bound_push"] is None
    # A glancing push that moved the object 2 mm is no friction reference (it did not slide
    # far enough to balance the full friction); the 5 cm one is.
    glancing = _record(0.1 * mu_m_g, 0.0)
    glancing.pose[:, 0] = np.linspace(0, 0.002, len(glancing.pose))
    ref = friction_reference([glancing, _record(mu_m_g, 0.0)], m)
    assert ref["value"] == pytest.approx(0.3)
    assert [p["pure_translation"] for p in ref["pushes"]] == [False, True]
    assert ref["pushes"][0]["travel_m"] == pytest.approx(0.002)
    assert friction_reference([glancing], m)["value"] is None


def test_friction_reference_on_the_real_pushes(real_dir, real_dir_rescaled):
    """Only the centre push is a pure translation; its μ is plausible for steel on plywood and
    the same at 10 Hz and at 50 Hz of recorded time (the contact-phase rule)."""
    values = []
    for d in (real_dir, real_dir_rescaled):
        real = load_real_object(d)
        files = [a["mit_file"] for a in real.attrs]
        ref = friction_reference(real.records, mit_object("rect1").mass)
        pure = [p["pure_translation"] for p in ref["pushes"]]
        assert pure == [f == CENTRE for f in files] and sum(pure) == 1
        assert 0.15 < ref["value"] < 0.35
        assert ref["value"] == ref["pushes"][files.index(CENTRE)]["mu_contact_phase"]
        for p in ref["pushes"]:
            if not p["pure_translation"]:
                assert abs(p["rotation_deg"]) > 20
        values.append(ref["value"])
    assert values[0] == pytest.approx(values[1], abs=0.01)


# ------------------------------------------------------------------------------------------
# the estimates
# ------------------------------------------------------------------------------------------
def test_report_estimates_are_finite_with_positive_std(report):
    assert tuple(report.to_json()) == REPORT_KEYS
    assert report.object == "plywood:rect1"
    assert len(report.pushes) == len(report.filter["per_push"]) == 3
    assert len(report.forest["per_push"]) == 3
    assert report.filter["sigma_points"] == SIGMA_POINTS
    filt, forest = report.filter, report.forest
    for est in [filt["prior"], *filt["per_push"], *forest["per_push"]]:
        assert set(est) == set(PARAM_NAMES)
        for p in PARAM_NAMES:
            assert math.isfinite(est[p]["mean"]) and est[p]["std"] > 0, (p, est[p])
    # The filter learns something from each push: its belief changes.
    means = [[e[p]["mean"] for p in PARAM_NAMES] for e in report.filter["per_push"]]
    prior = [report.filter["prior"][p]["mean"] for p in PARAM_NAMES]
    assert not np.allclose(means[0], prior) and not np.allclose(means[1], means[0])
    for p in report.pushes:
        assert p["speed_m_per_s"] == p["file_speed_m_per_s"] == 0.1 and p["time_scale"] == 1.0
        assert math.isfinite(p["filter_pose_error_end"]["xy_mm"])
    assert report.forest["trees"] == TREES
    assert report.forest["training_pushes"] == 12  # tiny dataset: 6 objects × 2 pushes


def test_report_truth_and_errors(report, forest_dir):
    obj = mit_object("rect1")
    t = report.truth
    assert (t["mass"], t["inertia"], t["com_x"], t["com_y"]) == (obj.mass, obj.inertia, 0, 0)
    assert 0.15 < t["friction"] < 0.35
    assert report.friction_reference["value"] == t["friction"]
    rng = {p: PARAM_RANGES[p][1] - PARAM_RANGES[p][0] for p in PARAM_NAMES}
    for k, est in enumerate(report.filter["per_push"]):
        err = report.errors["filter"][k]
        for p in PARAM_NAMES:
            assert err[p] == pytest.approx(abs(est[p]["mean"] - t[p]) / rng[p])
        assert err["overall"] == pytest.approx(np.mean([err[p] for p in PARAM_NAMES]))
    f = report.forest["per_push"][-1]
    assert report.errors["forest"][-1]["mass"] == pytest.approx(
        abs(f["mass"]["mean"] - obj.mass) / rng["mass"]
    )
    # The prior mean is the tiny dataset's per-object mean.
    from pushtoknow.datasets.shards import list_shards, read_shard

    episodes = [ep for s in list_shards(forest_dir) for ep in read_shard(s, images=False)]
    params = np.array([ep.spec.params.as_array() for ep in episodes])
    np.testing.assert_allclose([report.prior_mean[p] for p in PARAM_NAMES], params.mean(0))
    # μ·m: truth and the forest's product of means.
    mm = report.mu_m
    assert mm["truth"] == pytest.approx(obj.mass * t["friction"])
    assert mm["forest"][-1] == pytest.approx(f["mass"]["mean"] * f["friction"]["mean"])
    assert all(s["std"] > 0 for s in mm["filter"])
    # Notes: friction below the catalogue, speed mismatch, what quasi-static pushes reveal.
    notes = " ".join(report.notes)
    assert "friction truth" in notes and "OUTSIDE" in notes
    assert "speed mismatch" in notes and "μ·m" in notes
    assert json.loads(json.dumps(report.to_json())) == report.to_json()  # JSON-ready


def test_filter_runs_the_pushes_in_order_carrying_the_posterior(report, real_dir, run_dir):
    """The report's filter estimates are one `LearnedFilterEstimator` run over the pushes in file
    order, each starting at its recorded pose, the posterior carried (not reset per push)."""
    from pushtoknow.evaluation.real_object import real_inference_config
    from pushtoknow.inference.learned_filter import LearnedFilterEstimator
    from pushtoknow.models.checkpoint import load_checkpoint

    real = load_real_object(real_dir)
    model = load_checkpoint(run_dir)
    est = LearnedFilterEstimator(model, real_inference_config(3), seed=0)
    carried, fresh = [], []
    for k, rec in enumerate(real.records):
        est.update(rec, View.before(rec), rec.pose[0])
        carried.append(est.estimate(k + 1).as_dict())
        alone = LearnedFilterEstimator(model, real_inference_config(1), seed=0)
        alone.update(rec, View.before(rec), rec.pose[0])
        fresh.append(alone.estimate(1).as_dict())
    assert report.filter["per_push"] == carried
    assert report.filter["per_push"][1:] != fresh[1:]


def test_deterministic_given_seed(report, real_dir, run_dir, forest_dir):
    again = estimate_real_object(
        real_dir, run_dir, forest_dir, seed=0, forest_trees=TREES, identify=False
    )
    assert again.filter == report.filter and again.forest == report.forest


def test_without_forest_data_the_filter_runs_and_no_forest_row_is_made(report, real_dir, run_dir):
    """`--forest-data` is optional: without it the filter's rows are the same and the forest
    and prior-mean rows are absent from the report and its tables."""
    bare = estimate_real_object(real_dir, run_dir, None, seed=0, identify=False)
    assert bare.filter == report.filter
    assert bare.forest is None and bare.prior_mean is None and bare.forest_data is None
    assert "forest" not in bare.errors and "forest" not in bare.mu_m["errors"]
    md = markdown_table(bare, "rect1")
    assert "forest" not in md and "prior mean" not in md and md.count("| filter, push") == 3


def test_rescaled_pushes_are_labelled_at_training_speed(real_dir_rescaled, run_dir, forest_dir):
    r = estimate_real_object(
        real_dir_rescaled, run_dir, forest_dir, seed=0, forest_trees=TREES, identify=False
    )
    for p in r.pushes:
        assert p["speed_m_per_s"] == pytest.approx(0.02) and p["time_scale"] == pytest.approx(5)
        assert p["file_speed_m_per_s"] == 0.1 and p["samples"] > 40
    assert "speed mismatch" not in " ".join(r.notes)
    assert "time-rescaled" in " ".join(r.notes)
    md = markdown_table(r, "rect1")
    assert md.startswith("### rect1") and "| mass (kg) | 0.837 |" in md
    assert md.count("| filter, push") == 3


def test_raw_files_are_rescaled_to_the_training_speed_by_default(
    sample_dir, run_dir, forest_dir, real_dir_rescaled, tmp_path
):
    """Raw MIT files: imported on the fly, time-rescaled to the model's 20 mm/s unless told not
    to; the same estimates as from the equivalent import."""
    kw = {"seed": 0, "forest_trees": TREES, "obj": "plywood:rect1", "identify": False}
    r = estimate_real_object(sample_dir, run_dir, forest_dir, import_dir=tmp_path / "imp", **kw)
    assert r.conversion["imported_here"] and r.conversion["as_speed_m_per_s"] == 0.02
    assert (tmp_path / "imp" / "import.json").exists()
    assert [p["speed_m_per_s"] for p in r.pushes] == pytest.approx([0.02] * 3)
    same = estimate_real_object(real_dir_rescaled, run_dir, forest_dir, **kw)
    assert not same.conversion["imported_here"]
    assert same.filter == r.filter and same.truth == r.truth
    raw = estimate_real_object(sample_dir, run_dir, forest_dir, rescale=False, **kw)
    assert raw.conversion["as_speed_m_per_s"] is None and raw.conversion["dir"] is None
    assert [p["speed_m_per_s"] for p in raw.pushes] == [0.1] * 3
    with pytest.raises(DatasetError, match="no MIT Push files of 'hex'"):
        estimate_real_object(
            sample_dir, run_dir, forest_dir, obj="hex", forest_trees=TREES, identify=False
        )


# ------------------------------------------------------------------------------------------
# errors
# ------------------------------------------------------------------------------------------
def test_wrong_directory_or_object_gives_clear_errors(real_dir, forest_dir, tmp_path, run_dir):
    with pytest.raises(DatasetError, match="import-mit"):
        load_real_object(forest_dir)  # a simulated dataset, not an import
    with pytest.raises(DatasetError, match="import-mit"):
        estimate_real_object(forest_dir, run_dir, forest_dir, forest_trees=TREES, identify=False)
    with pytest.raises(DatasetError, match="no such directory"):
        load_real_object(tmp_path / "missing")
    with pytest.raises(DatasetError, match=r"'rect2'.*plywood:rect1"):
        load_real_object(real_dir, "rect2")
    with pytest.raises(DatasetError, match=r"'abs:rect1'.*plywood:rect1"):
        load_real_object(real_dir, "abs:rect1")
    real = load_real_object(real_dir, "plywood:rect1")
    assert (real.shape, real.surface, real.name) == ("rect1", "plywood", "plywood:rect1")
    (tmp_path / "empty").mkdir()
    with pytest.raises(DatasetError, match="no shard"):
        estimate_real_object(
            real_dir, run_dir, tmp_path / "empty", forest_trees=TREES, identify=False
        )


# ------------------------------------------------------------------------------------------
# CLI
# ------------------------------------------------------------------------------------------
def _invoke(*args):
    return CliRunner().invoke(app, ["estimate-real", *map(str, args)])


def test_cli_json_out_and_markdown(real_dir, run_dir, forest_dir, tmp_path, report):
    out, md = tmp_path / "r" / "report.json", tmp_path / "r" / "table.md"
    res = _invoke(
        real_dir, "--model", run_dir, "--forest-data", forest_dir, "--seed", 0,
        "--trees", TREES, "--json", "--out", out, "--markdown", md, "--no-identify",
    )  # fmt: skip
    assert res.exit_code == 0, (res.output, res.exception)
    got = json.loads(res.stdout)
    assert tuple(got) == REPORT_KEYS
    assert got["filter"] == report.filter and got["truth"] == report.truth
    assert json.loads(out.read_text())["errors"] == got["errors"]
    assert "| friction |" in md.read_text()
    # Without --json: the tables.
    res = _invoke(
        real_dir, "--model", run_dir, "--forest-data", forest_dir, "--trees", TREES,
        "--no-identify",
    )  # fmt: skip
    assert res.exit_code == 0, (res.output, res.exception)
    for text in ("mass (kg)", "inertia", "0.837", "overall", "prior mean", "speed mismatch"):
        assert text in res.stdout, text


def test_cli_wrong_object_exits_2(real_dir, run_dir, forest_dir):
    res = _invoke(real_dir, "--model", run_dir, "--forest-data", forest_dir, "--object", "hex")
    assert res.exit_code == 2
    assert "error" in res.output and "plywood:rect1" in res.output
    assert res.exception is None or isinstance(res.exception, SystemExit)


# ------------------------------------------------------------------------------------------
# physics-based identification row
# ------------------------------------------------------------------------------------------
LIGHT_IDENTIFY = {"workers": 1, "screen_starts": 1, "refine_starts": 1, "max_iterations": 3}


def test_identify_row_replays_the_recorded_clock_and_reports_every_push(
    real_dir_rescaled, run_dir, forest_dir
):
    """On the pushes time-rescaled for the filter (10 Hz, scale 5), the identification replays
    the recorded 50 Hz clock along the recorded pusher tracks, estimates the noise from the
    misfit (real data have none), and reports after 1…3 pushes, with errors and μ·m beside
    the filter's; intervals contain their means, and the tables gain its column and rows."""
    from pushtoknow.identification.identify_config import IdentifyConfig

    r = estimate_real_object(
        real_dir_rescaled, run_dir, forest_dir, seed=0, forest_trees=TREES,
        identify_config=IdentifyConfig(**LIGHT_IDENTIFY),
    )  # fmt: skip
    ident = r.identify
    assert ident.rate_hz == pytest.approx(50.0)
    assert len(ident.per_push) == 3 and len(r.errors["identify"]) == 3
    assert ident.noise_std["estimated_from_misfit"] is True
    assert ident.noise_std["force_N"] > 0.05  # a real misfit, not the 0 N stored
    for p in ident.per_push:
        for n in PARAM_NAMES:
            lo, hi = p[n]["interval"]
            assert lo <= p[n]["mean"] <= hi and p[n]["std"] > 0
        assert p["mass"]["mean"] > 0 and p["friction"]["mean"] > 0 and p["inertia"]["mean"] > 0
    # μ·m is what quasi-static pushes reveal: within 40% of the measured reference
    assert r.mu_m["identify"][-1]["mean"] == pytest.approx(r.mu_m["truth"], rel=0.4)
    assert "probe radius 4.75 mm" in ident.model
    # three pushes: the leave-one-push-out check ran and its spread joined the intervals
    assert any("leave-one-push-out" in n for n in ident.notes)
    assert r.to_json()["identify"] == ident.to_json()
    assert tuple(ident.to_json()) == ("per_push", "rate_hz", "noise_std", "model", "notes")
    md = markdown_table(r, "rect1")
    assert "identify (3 pushes)" in md and md.count("| identify, push") == 3


def test_identify_refuses_pushes_on_different_clocks(real_dir_rescaled, tmp_path):
    from dataclasses import replace

    from pushtoknow.evaluation.real_object import identify_real, load_real_object

    real = load_real_object(real_dir_rescaled)
    attrs = [*real.attrs]
    attrs[1] = {**attrs[1], "mit_time_scale": 2.0}
    with pytest.raises(DatasetError, match="different time scales"):
        identify_real(real_dir_rescaled, replace(real, attrs=attrs), seed=0)


def test_identify_reads_a_rescaled_import_on_its_recorded_clock(real_dir, real_dir_rescaled):
    from pushtoknow.identification.recordings import load_recorded_objects

    (as_recorded,) = load_recorded_objects(real_dir)
    (rescaled,) = load_recorded_objects(real_dir_rescaled)
    assert as_recorded.sim_config.tactile.rate_hz == pytest.approx(10.0)
    assert rescaled.sim_config.tactile.rate_hz == pytest.approx(50.0)  # 10 Hz × scale 5
