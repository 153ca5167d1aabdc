"""Push sequences of validation objects and the per-direction evidence weights."""

import math

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.models.calibration import DIRECTIONS
from pushtoknow.training.calibrate import choose_weights, direction_nll, push_sequences
from pushtoknow.training.push_tensors import load_push_tensors
from tiny_training import DATA_OBJECTS, DATA_PUSHES, SIGMA_POINTS, tiny_dataset, tiny_run


def test_sequences_follow_each_objects_pushes_in_order(tmp_path_factory):
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    seqs = push_sequences(pt, max_objects=DATA_OBJECTS)
    assert seqs.shape == (DATA_OBJECTS, DATA_PUSHES)
    for row in seqs:
        assert len(set(pt.object_index[row].tolist())) == 1  # one object per sequence
        assert pt.push_index[row].tolist() == sorted(pt.push_index[row].tolist())
    assert push_sequences(pt, max_objects=2).shape == (2, DATA_PUSHES)


def test_direction_nll_is_the_gaussian_nll_in_the_basis():
    mean = torch.zeros(1, 5)
    cov = torch.eye(5).expand(1, 5, 5) * 4.0
    nll = direction_nll(mean, cov, torch.zeros(1, 5))
    expected = 0.5 * (math.log(4.0) + math.log(2 * math.pi))  # zero error, variance 4
    torch.testing.assert_close(nll, torch.full((1, 5), expected))
    worse = direction_nll(mean, cov, torch.ones(1, 5))
    assert (worse > nll).all()


def test_dynamic_noise_scale_is_chosen_with_the_weights(tmp_path_factory):
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.training.calibrate import SequenceCalibrationConfig, calibrate_evidence

    model = load_checkpoint(tiny_run(tmp_path_factory)).eval()
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    cfg = SequenceCalibrationConfig(
        weights=(0.0, 1.0), dynamic_noise_scales=(0.25, 64.0), num_sigma_points=SIGMA_POINTS
    )
    rows: list[dict] = []
    with torch.no_grad():
        chosen = calibrate_evidence(model, pt, cfg, seed=0, log=rows.append)
    assert len(rows) == 2 * 3  # weights × (the calibrated scale, 0.25, 64)
    by_scale: dict = {}
    for r in rows:
        by_scale.setdefault(r["dynamic_noise_scale"], []).append(r)
    # each candidate's score: the NLL of its best weight, summed over the directions
    score = {
        s: sum(min(r[f"nll_{d}"] for r in rs) for d in DIRECTIONS) for s, rs in by_scale.items()
    }
    # the chosen candidate's score is the lowest, up to the float32 rounding of the sums (the
    # candidates tie exactly where every chosen evidence weight is 0)
    lowest = min(score.values())
    assert score[chosen.dynamic_noise_scale or ""] <= lowest + 1e-6 * abs(lowest)
    assert chosen.noise_scale == model.inference.noise_scale
    assert set(chosen.evidence_weights) <= {0.0, 1.0}
    # the dynamic scale changes the posterior (release pushes have dynamic samples)
    kept = [next(r for r in rs if r["weight"] == 1.0) for rs in by_scale.values()]
    assert len({round(r["nll_log_mu_m"], 6) for r in kept}) == 3


def test_each_profiles_weights_are_chosen_in_turn(tmp_path_factory):
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.testbed.push import PROFILES
    from pushtoknow.training.calibrate import (
        SequenceCalibrationConfig,
        calibrate_evidence,
        run_sequences,
    )

    model = load_checkpoint(tiny_run(tmp_path_factory)).eval()
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    cfg = SequenceCalibrationConfig(
        weights=(0.0, 1.0), profile_rounds=1, num_sigma_points=SIGMA_POINTS
    )
    seqs = push_sequences(pt, cfg.max_objects)
    profiles = pt.action[seqs, 4].long()
    assert set(profiles.flatten().tolist()) == {0, 1}  # the tiny data holds both profiles
    rows: list[dict] = []
    with torch.no_grad():
        chosen = calibrate_evidence(model, pt, cfg, seed=0, log=rows.append)
        # a row of the table acts on that profile's pushes only: with release evidence
        # dropped, a sequence's belief after a release push is its belief before it
        table = torch.tensor([[1.0] * 5, [0.0] * 5])
        beliefs = run_sequences(model, pt, seqs, table, model.inference, cfg, seed=0)
    assert len(rows) == 2 * (1 + len(PROFILES))  # the common scan, then each profile's
    assert [r["profile"] for r in rows] == ["all"] * 2 + ["constant"] * 2 + ["release"] * 2
    assert set(chosen.profile_evidence_weights) == set(PROFILES)
    for name, weights in chosen.profile_evidence_weights.items():
        assert set(weights) <= {0.0, 1.0}
        # each chosen weight is the best of its profile's scan, per direction
        scan = [r for r in rows if r["profile"] == name]
        for d, w in zip(DIRECTIONS, weights, strict=True):
            assert w == min(scan, key=lambda r: r[f"nll_{d}"])["weight"]
    for j in range(1, seqs.shape[1]):
        released = profiles[:, j] == 1
        torch.testing.assert_close(beliefs[j][0][released], beliefs[j - 1][0][released])
        assert not torch.allclose(beliefs[j][0][~released], beliefs[j - 1][0][~released])


def test_a_capped_direction_takes_its_best_allowed_weight(tmp_path_factory):
    """max_weights bars the weights above a direction's cap; the others choose as before."""
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.training.calibrate import SequenceCalibrationConfig, calibrate_evidence

    model = load_checkpoint(tiny_run(tmp_path_factory)).eval()
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    weights = (0.0, 0.5, 1.0)
    free = SequenceCalibrationConfig(weights=weights, num_sigma_points=SIGMA_POINTS)
    capped = free.model_copy(update={"max_weights": {"com_x": 0.5, "com_y": 0.0}})
    rows: list[dict] = []
    with torch.no_grad():
        a = calibrate_evidence(model, pt, free, seed=0, log=rows.append)
        b = calibrate_evidence(model, pt, capped, seed=0)
    nll = {d: [r[f"nll_{d}"] for r in rows] for d in DIRECTIONS}
    best_x = min(range(2), key=lambda i: nll["com_x"][i])  # the weights 0 and 0.5
    assert b.evidence_weights[2] == weights[best_x]
    assert b.evidence_weights[3] == 0.0
    for k in (0, 1, 4):
        assert b.evidence_weights[k] == a.evidence_weights[k]


def test_max_weights_must_name_a_direction_and_allow_a_weight():
    from pydantic import ValidationError

    from pushtoknow.training.calibrate import SequenceCalibrationConfig

    with pytest.raises(ValidationError, match="unknown direction 'mass'"):
        SequenceCalibrationConfig(max_weights={"mass": 0.5})
    with pytest.raises(ValidationError, match=r"com_x = 1.5: a weight lies in \[0, 1\]"):
        SequenceCalibrationConfig(max_weights={"com_x": 1.5})
    with pytest.raises(ValidationError, match="below every candidate weight"):
        SequenceCalibrationConfig(weights=(0.25, 1.0), max_weights={"com_y": 0.1})


def test_a_shared_error_discounts_the_later_pushes_of_a_profile(tmp_path_factory):
    """run_sequences applies g_r(n) to the n-th push of each profile: r = 0 is the plain
    weights; with r near 1 only each profile's first push moves the belief."""
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.training.calibrate import SequenceCalibrationConfig, run_sequences

    model = load_checkpoint(tiny_run(tmp_path_factory)).eval()
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    cfg = SequenceCalibrationConfig(num_sigma_points=SIGMA_POINTS)
    seqs = push_sequences(pt, cfg.max_objects)
    profiles = pt.action[seqs, 4].long()
    table = torch.ones(2, 5)
    with torch.no_grad():
        plain = run_sequences(model, pt, seqs, table, model.inference, cfg, seed=0)
        zero = run_sequences(model, pt, seqs, table, model.inference, cfg, 0, torch.zeros(5))
        shared = run_sequences(
            model, pt, seqs, table, model.inference, cfg, 0, torch.full((5,), 1.0 - 1e-7)
        )
    for (m, c), (mz, cz) in zip(plain, zero, strict=True):
        torch.testing.assert_close(m, mz)
        torch.testing.assert_close(c, cz)
    repeats = 0
    for j in range(1, seqs.shape[1]):
        again = (profiles[:, :j] == profiles[:, j : j + 1]).any(1)  # not the profile's first
        repeats += int(again.sum())
        torch.testing.assert_close(shared[j][0][again], shared[j - 1][0][again], atol=1e-5, rtol=0)
        first = ~again
        if first.any():
            assert not torch.allclose(shared[j][0][first], shared[j - 1][0][first])
    assert repeats > 0  # the tiny data repeats a profile within a sequence


def test_correlations_are_chosen_per_direction_with_the_weights(tmp_path_factory, monkeypatch):
    """Each direction keeps the (w, r) of lowest sequence NLL over the common scan (r = 0) and
    the scans of every other r, within its cap. The filter runs are replaced by an NLL known
    per direction as a function of (w, r), so the choice has a unique right answer."""
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.training import calibrate as calibration
    from pushtoknow.training.calibrate import SequenceCalibrationConfig, calibrate_evidence

    best_w = torch.tensor([0.5, 1.0, 1.0, 0.5, 0.0], dtype=torch.float64)
    best_r = torch.tensor([0.5, 0.0, 0.2, 0.2, 0.0], dtype=torch.float64)

    def fake_run(model, val, seqs, table, settings, cfg, seed, correlation=None):
        w = table[0].double()
        r = torch.zeros(5, dtype=torch.float64) if correlation is None else correlation.double()
        r = torch.where(w > 0, r, 0.0)  # a weight of 0 keeps nothing to discount
        return [(((w - best_w).square() + (r - best_r).abs())[None], None)]

    monkeypatch.setattr(calibration, "run_sequences", fake_run)
    monkeypatch.setattr(calibration, "direction_nll", lambda mean, cov, truth: mean)
    model = load_checkpoint(tiny_run(tmp_path_factory))
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    cfg = SequenceCalibrationConfig(
        weights=(0.0, 0.5, 1.0),
        correlations=(0.0, 0.5, 0.2, 0.5),  # a repeat is scanned once
        max_weights={"log_mu_m": 0.5, "m_vs_mu": 0.5},
    )
    rows: list[dict] = []
    chosen = calibrate_evidence(model, pt, cfg, seed=0, log=rows.append)
    assert [r["correlation"] for r in rows] == (
        ["0 0 0 0 0"] * 3 + ["0.2 0.2 0.2 0.2 0.2"] * 3 + ["0.5 0.5 0.5 0.5 0.5"] * 3
    )
    # log μ·m: (0.5, 0.5) as set; m vs μ capped at 0.5 (r = 0); c_x (1, 0.2); c_y (0.5, 0.2);
    # log I_z at w = 0 is the same for every r, so r stays 0
    assert chosen.evidence_weights == (0.5, 0.5, 1.0, 0.5, 0.0)
    assert chosen.evidence_correlation == (0.5, 0.0, 0.2, 0.2, 0.0)
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        SequenceCalibrationConfig(correlations=(0.0, -0.5))
    with pytest.raises(ValueError, match=r"\[0, 1\)"):
        SequenceCalibrationConfig(correlations=(0.0, 1.0))


def test_choose_weights_takes_the_lowest_nll_within_the_cap():
    weights = torch.tensor([0.0, 0.5, 1.0], dtype=torch.float64)
    nll = torch.tensor([[1.0, 2.0], [0.5, 1.0], [0.2, 3.0]])[:, None, :].expand(3, 4, 2)
    allowed = torch.ones(3, 2, dtype=torch.bool)
    lowest, index = choose_weights(nll, weights, allowed, tolerance_se=0.0)
    assert index.tolist() == [2, 1]
    torch.testing.assert_close(lowest, torch.tensor([0.2, 1.0]))
    allowed[2, 0] = False  # direction 0 capped below 1.0
    assert choose_weights(nll, weights, allowed, 0.0)[1].tolist() == [1, 1]
    broken = nll.clone()
    broken[1, 0, 1] = float("nan")  # a non-finite NLL never wins
    assert choose_weights(broken, weights, allowed, 0.0)[1].tolist() == [1, 0]


def test_choose_weights_keeps_evidence_only_where_it_pays_beyond_the_noise():
    """The one-standard-error rule: a smaller weight whose NLL is within `tolerance_se`
    standard errors (of the paired per-object difference) of the lowest is chosen instead;
    a gain that every object shows is kept however small."""
    gen = torch.Generator().manual_seed(0)
    n = 100
    weights = torch.tensor([0.0, 0.2], dtype=torch.float64)
    allowed = torch.ones(2, 2, dtype=torch.bool)
    base = torch.randn(n, 2, generator=gen)
    # direction 0: weight 0.2 lowers the mean NLL by 0.01 with per-object noise 0.5 (SE 0.05);
    # direction 1: by 0.01 on every object alike (SE ≈ 0.0001)
    gain = torch.stack([0.01 + 0.5 * torch.randn(n, generator=gen), torch.full((n,), 0.01)], -1)
    gain[:, 0] += 0.01 - gain[:, 0].mean()  # exactly 0.01 on average
    gain[:, 1] += 1e-3 * torch.randn(n, generator=gen)
    nll = torch.stack([base, base - gain])
    assert choose_weights(nll, weights, allowed, 0.0)[1].tolist() == [1, 1]
    lowest, index = choose_weights(nll, weights, allowed, 1.0)
    assert index.tolist() == [0, 1]
    torch.testing.assert_close(lowest, torch.stack([nll[0, :, 0].mean(), nll[1, :, 1].mean()]))


@settings(max_examples=50, deadline=None)
@given(st.integers(2, 5), st.integers(2, 30), st.floats(0.0, 3.0), st.integers(0, 2**31 - 1))
def test_choose_weights_never_exceeds_the_lowest_nlls_weight(w, n, tolerance, seed):
    gen = torch.Generator().manual_seed(seed)
    weights = torch.rand(w, generator=gen, dtype=torch.float64)
    nll = torch.randn(w, n, 3, generator=gen)
    allowed = torch.ones(w, 3, dtype=torch.bool)
    lowest, index = choose_weights(nll, weights, allowed, tolerance)
    best = nll.mean(1).argmin(0)
    assert (weights[index] <= weights[best]).all()
    diff_se = (nll - nll[best, :, [0, 1, 2]].T[None]).std(1) / math.sqrt(n)
    bound = nll.mean(1).min(0).values + tolerance * diff_se[index, [0, 1, 2]]
    assert (lowest <= bound + 1e-6).all()
    if tolerance == 0.0:
        torch.testing.assert_close(lowest, nll.mean(1).min(0).values)


def test_a_setting_the_filter_cannot_run_with_is_never_chosen(tmp_path_factory, monkeypatch):
    """A candidate dynamic R scale under which the filter's belief stops being a covariance
    (`CovarianceError`) on a validation sequence under one weight is dropped whole, though its
    other weight would score best by far: the weights chosen are never run together. The failed
    trial is logged with an infinite NLL and its reason; the calibration does not stop."""
    from pushtoknow.filters.gaussian import CovarianceError
    from pushtoknow.models.checkpoint import load_checkpoint
    from pushtoknow.training import calibrate
    from pushtoknow.training.calibrate import SequenceCalibrationConfig, calibrate_evidence

    model = load_checkpoint(tiny_run(tmp_path_factory)).eval()
    pt = load_push_tensors(tiny_dataset(tmp_path_factory))
    cfg = SequenceCalibrationConfig(
        weights=(0.0, 1.0), dynamic_noise_scales=(0.25,), num_sigma_points=SIGMA_POINTS
    )
    run = calibrate.run_sequences

    def breaks_without_evidence(model, pt, seqs, weights, settings, *args, **kwargs):
        if settings.dynamic_noise_scale != 0.25:
            return run(model, pt, seqs, weights, settings, *args, **kwargs)
        if not bool(weights.any()):
            raise CovarianceError("belief covariance is not positive definite at batch index [1]")
        truth = pt.params_norm[seqs[:, 0]].float()  # the truth, sure of it: the lowest NLL
        return [(truth, 1e-4 * torch.eye(5).expand(len(truth), 5, 5))] * seqs.shape[1]

    monkeypatch.setattr(calibrate, "run_sequences", breaks_without_evidence)
    rows: list[dict] = []
    with torch.no_grad():
        chosen = calibrate_evidence(model, pt, cfg, seed=0, log=rows.append)
    failed = [r for r in rows if r.get("failed")]
    assert len(failed) == 1 and failed[0]["dynamic_noise_scale"] == 0.25
    assert failed[0]["weight"] == 0.0 and math.isinf(failed[0]["nll_log_mu_m"])
    sure = next(r for r in rows if r["dynamic_noise_scale"] == 0.25 and r["weight"] == 1.0)
    assert all(
        sure[f"nll_{d}"] < min(r[f"nll_{d}"] for r in rows if r is not sure) for d in DIRECTIONS
    )
    assert chosen.dynamic_noise_scale != 0.25

    def always_breaks(*args, **kwargs):
        raise CovarianceError("belief covariance is not positive definite at batch index [0]")

    monkeypatch.setattr(calibrate, "run_sequences", always_breaks)
    with pytest.raises(ValueError, match="no setting"), torch.no_grad():
        calibrate_evidence(model, pt, cfg, seed=0)  # nothing runs: said, not a wrong choice
