"""Keeping part of a push's evidence: exact at the ends, interpolating, PSD, physics basis."""

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.errors import ShapeError
from pushtoknow.common.params import PARAM_NAMES, space_scale
from pushtoknow.models.calibration import evidence_basis, evidence_discount, keep_evidence
from pushtoknow.models.checkpoint import InferenceSettings

F64 = torch.float64


def random_belief(rng, b=3):
    a = torch.as_tensor(rng.normal(size=(b, 5, 5)), dtype=F64) * 0.3
    cov = a @ a.transpose(-1, -2) + 0.01 * torch.eye(5, dtype=F64)
    return torch.as_tensor(rng.normal(size=(b, 5)), dtype=F64), cov


def test_basis_is_orthonormal_and_its_first_direction_is_log_mu_m():
    r = evidence_basis().double()
    torch.testing.assert_close(r @ r.T, torch.eye(5, dtype=F64), atol=1e-6, rtol=0)
    # log μm = s_m z_m + s_μ z_μ + const: e1 is that gradient's direction, e2 leaves μ·m as is
    s = space_scale()
    i, j = PARAM_NAMES.index("mass"), PARAM_NAMES.index("friction")
    e1, e2 = r[0].numpy(), r[1].numpy()
    assert e1[i] / e1[j] == pytest.approx(s[i] / s[j], rel=1e-5)
    assert s[i] * e2[i] + s[j] * e2[j] == pytest.approx(0.0, abs=1e-6)


def test_weight_one_is_the_posterior_and_zero_the_prior():
    rng = np.random.default_rng(0)
    m0, c0 = random_belief(rng)
    m1, c1 = random_belief(rng)
    m, c = keep_evidence(m0, c0, m1, c1, torch.ones(5, dtype=F64))
    torch.testing.assert_close(m, m1)
    torch.testing.assert_close(c, c1)
    m, c = keep_evidence(m0, c0, m1, c1, torch.zeros(5, dtype=F64))
    torch.testing.assert_close(m, m0)
    r = evidence_basis().double()  # the prior's marginals in the basis come back

    def marginals(cov):
        return torch.diagonal(r @ cov @ r.T, dim1=-2, dim2=-1)

    torch.testing.assert_close(marginals(c), marginals(c0))


@settings(max_examples=50, deadline=None)
@given(seed=st.integers(0, 10_000), w=st.lists(st.floats(0.0, 1.0), min_size=5, max_size=5))
def test_kept_belief_is_between_prior_and_posterior_and_psd(seed, w):
    rng = np.random.default_rng(seed)
    m0, c0 = random_belief(rng)
    m1, c1 = random_belief(rng)
    weights = torch.tensor(w, dtype=F64)
    m, c = keep_evidence(m0, c0, m1, c1, weights)
    r = evidence_basis().double()
    y, y0, y1 = m @ r.T, m0 @ r.T, m1 @ r.T
    torch.testing.assert_close(y, y0 + weights * (y1 - y0))
    assert torch.linalg.eigvalsh(c).min() > -1e-9
    torch.testing.assert_close(c, c.transpose(-1, -2))


def test_shapes_and_weights_are_checked():
    m, c = torch.zeros(2, 5), torch.eye(5).expand(2, 5, 5)
    with pytest.raises(ShapeError, match="weights"):
        keep_evidence(m, c, m, c, torch.ones(4))
    with pytest.raises(ShapeError, match="cov1"):
        keep_evidence(m, c, m, c[:1], torch.ones(5))
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        InferenceSettings(evidence_weights=(1.0, 1.0, 1.5, 1.0, 1.0))


def test_per_row_weights_act_on_each_row_as_its_own_call():
    rng = np.random.default_rng(1)
    m0, c0 = random_belief(rng)
    m1, c1 = random_belief(rng)
    rows = torch.as_tensor(rng.uniform(size=(3, 5)), dtype=F64)
    m, c = keep_evidence(m0, c0, m1, c1, rows)
    for i in range(3):
        mi, ci = keep_evidence(m0[i : i + 1], c0[i : i + 1], m1[i : i + 1], c1[i : i + 1], rows[i])
        torch.testing.assert_close(m[i], mi[0])
        torch.testing.assert_close(c[i], ci[0])
    with pytest.raises(ShapeError, match="weights"):
        keep_evidence(m0, c0, m1, c1, rows[:2])


def test_a_profile_without_its_own_weights_uses_the_common_ones():
    common = (1.0, 0.5, 0.5, 0.5, 0.1)
    own = (1.0, 0.2, 0.3, 0.3, 0.0)
    s = InferenceSettings(evidence_weights=common, profile_evidence_weights={"release": own})
    assert s.evidence_weights_for("release") == own
    assert s.evidence_weights_for("constant") == common
    torch.testing.assert_close(s.evidence_weight_table(), torch.tensor([common, own]))
    with pytest.raises(ValueError, match="unknown speed profile 'fling'"):
        InferenceSettings(profile_evidence_weights={"fling": own})
    with pytest.raises(ValueError, match=r"\[0, 1\]"):
        InferenceSettings(profile_evidence_weights={"release": (1.0, 1.0, 2.0, 1.0, 1.0)})


def equicorrelated_information(n: int, r: float) -> float:
    """1ᵀ Σ⁻¹ 1 of n unit-variance measurements of one value whose errors correlate by r,
    Σ = (1 − r) I + r 11ᵀ: the information their best linear unbiased estimate draws from them,
    by direct linear algebra."""
    cov = (1.0 - r) * np.eye(n) + r * np.ones((n, n))
    ones = np.ones(n)
    return float(ones @ np.linalg.solve(cov, ones))


@settings(max_examples=40, deadline=None)
@given(r=st.floats(0.0, 0.95), n=st.integers(1, 12))
def test_discount_is_the_information_each_push_adds_under_a_shared_error(r, n):
    """g_r(n) = (I_n − I_{n−1}) / I_1 for n equicorrelated measurements (exact reference), so
    the n pushes keep I_n / I_1 = n / (1 + (n − 1) r) of one push's evidence in all."""
    info = [0.0] + [equicorrelated_information(k, r) for k in range(1, n + 1)]
    nth = torch.arange(1, n + 1)
    g = evidence_discount(nth, torch.tensor([r], dtype=F64))[:, 0].numpy()
    expected = np.diff(info) / info[1]
    np.testing.assert_allclose(g, expected, rtol=1e-9, atol=1e-12)
    np.testing.assert_allclose(g.sum(), n / (1 + (n - 1) * r), rtol=1e-9)
    assert g[0] == pytest.approx(1.0)
    assert np.all(np.diff(g) <= 1e-12)  # each push of a profile adds no more than the last


def test_discount_per_direction_and_independent_pushes_keep_everything():
    r = torch.tensor([0.0, 0.2, 0.5], dtype=F64)
    g = evidence_discount(torch.tensor([1, 2, 3]), r)
    assert g.shape == (3, 3)
    torch.testing.assert_close(g[:, 0], torch.ones(3, dtype=F64))  # r = 0: every push counts
    torch.testing.assert_close(g[1, 2], torch.tensor(1.0 / 3.0, dtype=F64))  # 0.5 / (1.5 · 1)
    with pytest.raises(ValueError, match="starts at 1"):
        evidence_discount(torch.tensor([0]), r)
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(ValueError, match=r"\[0, 1\)"):
            evidence_discount(torch.tensor([1]), torch.tensor([bad]))


def test_the_nth_push_of_a_profile_keeps_its_weight_times_the_discount():
    weights = (1.0, 0.5, 0.5, 0.5, 0.2)
    r = (0.0, 0.2, 0.5, 0.5, 0.25)
    s = InferenceSettings(profile_evidence_weights={"release": weights}, evidence_correlation=r)
    torch.testing.assert_close(s.kept_evidence("release", 1), torch.tensor(weights))
    third = s.kept_evidence("release", 3)
    expected = torch.tensor(weights, dtype=F64) * evidence_discount(
        torch.tensor(3), torch.tensor(r, dtype=F64)
    )
    torch.testing.assert_close(third, expected.float())
    assert third[0] == 1.0 and third[2] < 0.5 / 5  # r = 0.5: the third push adds 1/6 of the first
    assert InferenceSettings().evidence_correlation == (0.0,) * 5  # saved models without it
    for bad in (-1.0, 1.0):
        with pytest.raises(ValueError, match=r"\[0, 1\)"):
            InferenceSettings(evidence_correlation=(0.0, bad, 0.0, 0.0, 0.0))
