"""One Gaussian belief → the reported numbers: mean, std and interval of one distribution, the
CoM's truncated to where a CoM can lie (`common.estimate`)."""

import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import norm, truncnorm
from shapely.geometry import Point, Polygon

from pushtoknow.common.estimate import (
    COM,
    MIN_REGION_MASS,
    ParameterEstimate,
    com_region,
    estimate_from_belief,
    truncate_gaussian_2d,
)
from pushtoknow.common.params import (
    PARAM_NAMES,
    linear_param_affine,
    normalise_params,
    si_moments,
    space_scale,
)
from pushtoknow.testbed.objects import COM_MARGIN

K90 = float(norm.ppf(0.95))
# the user's L (m): a 0.1 m square less a 0.06 m notch in its +x +y corner
L_SHAPE = np.array(
    [
        [-0.03875, -0.03875],
        [0.06125, -0.03875],
        [0.06125, 0.00125],
        [0.00125, 0.00125],
        [0.00125, 0.06125],
        [-0.03875, 0.06125],
    ]
)
OFFSET, SCALE = (np.array(v) for v in zip(*(linear_param_affine(k) for k in ("com_x", "com_y"))))


def _belief(com_mean, com_std, rho=0.0):
    """A belief (normalised) with the CoM's SI mean (2,), std (2,) and correlation rho; the
    other parameters at the range centres with std 0.3."""
    mean = np.zeros(5)
    mean[COM] = (np.asarray(com_mean) - OFFSET) / SCALE
    sd = np.full(5, 0.3)
    sd[COM] = np.asarray(com_std) / SCALE
    corr = np.eye(5)
    corr[COM[0], COM[1]] = corr[COM[1], COM[0]] = rho
    return mean, corr * np.outer(sd, sd)


def _covers(region, xy, tol=1e-9) -> bool:
    return Polygon(region).buffer(tol).covers(Point(*xy))


def _check(est: ParameterEstimate, region=None):
    assert np.all(est.std >= 0.0)
    assert np.all(est.lower <= est.mean) and np.all(est.mean <= est.upper), (
        est.lower,
        est.mean,
        est.upper,
    )
    if region is not None:
        assert _covers(region, est.mean[COM])


# ---- the region --------------------------------------------------------------------------------


def test_com_region_is_the_convex_hull_less_the_margin():
    region = com_region(L_SHAPE, COM_MARGIN)
    hull = Polygon(L_SHAPE).convex_hull
    assert Polygon(region).equals_exact(hull.buffer(-COM_MARGIN), 1e-12) or Polygon(
        region
    ).symmetric_difference(hull.buffer(-COM_MARGIN)).area == pytest.approx(0.0, abs=1e-12)
    assert _covers(region, (0.02, 0.02))  # the notch: a CoM can lie there
    assert not _covers(region, (0.06, 0.0))  # within the margin of the edge
    # counter-clockwise
    x, y = region[:, 0], region[:, 1]
    assert np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y) > 0
    # too thin for the margin: a tiny square about the centroid
    thin = np.array([[-0.05, -0.002], [0.05, -0.002], [0.05, 0.002], [-0.05, 0.002]]) + 0.01
    tiny = com_region(thin, COM_MARGIN)
    assert Polygon(tiny).area < 1e-11 and _covers(tiny, (0.01, 0.01))


def test_a_non_convex_region_is_refused():
    with pytest.raises(ValueError, match="not convex"):
        truncate_gaussian_2d(np.zeros(2), np.eye(2) * 1e-4, L_SHAPE)


# ---- known answers -----------------------------------------------------------------------------


def test_a_region_much_larger_than_the_gaussian_gives_the_untruncated_moments():
    mean, cov = _belief((0.004, -0.003), (0.003, 0.002), rho=0.6)
    big = np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    est = estimate_from_belief(mean, cov, big)
    free = estimate_from_belief(mean, cov)
    assert est.com.mass == pytest.approx(1.0, abs=1e-9) and not est.com.projected
    np.testing.assert_allclose(est.mean, free.mean, rtol=0, atol=1e-9)
    np.testing.assert_allclose(est.std, free.std, rtol=1e-6)
    np.testing.assert_allclose(est.lower, free.lower, rtol=0, atol=1e-7)
    np.testing.assert_allclose(est.upper, free.upper, rtol=0, atol=1e-7)
    si_mean, si_std = si_moments(mean, cov)
    np.testing.assert_allclose(free.mean, si_mean) and np.testing.assert_allclose(free.std, si_std)
    truth = np.array([0.5, 0.5, 0.006, -0.001, 1e-3])
    np.testing.assert_allclose(est.zscore(truth), free.zscore(truth), atol=1e-5)
    assert free.to_json()["com_x"]["interval90"] == [free.lower[2], free.upper[2]]


def test_a_box_truncation_gives_two_truncated_normals():
    """Independent coordinates and a rectangle: each coordinate is a truncated normal."""
    m, sd = np.array([0.01, -0.004]), np.array([0.008, 0.005])
    lo, hi = np.array([0.003, -0.02]), np.array([0.03, 0.0])
    box = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    got = truncate_gaussian_2d(m, np.diag(sd**2), box)
    tn = [truncnorm((lo[i] - m[i]) / sd[i], (hi[i] - m[i]) / sd[i], m[i], sd[i]) for i in (0, 1)]
    np.testing.assert_allclose(got.mean, [d.mean() for d in tn], rtol=0, atol=1e-7)
    np.testing.assert_allclose(got.std, [d.std() for d in tn], rtol=0, atol=1e-7)
    np.testing.assert_allclose(got.lower, [d.ppf(0.05) for d in tn], rtol=0, atol=1e-7)
    np.testing.assert_allclose(got.upper, [d.ppf(0.95) for d in tn], rtol=0, atol=1e-7)
    mass = np.prod([norm.cdf(hi[i], m[i], sd[i]) - norm.cdf(lo[i], m[i], sd[i]) for i in (0, 1)])
    assert got.mass == pytest.approx(mass, rel=1e-6)


@pytest.mark.parametrize("angle", [0.0, 0.5, 2.0])
def test_a_half_plane_truncation_gives_the_half_normal(angle):
    """A Gaussian narrow across one axis, cut through its mean along the other: the half-normal
    mean μ + σ·√(2/π), std σ·√(1 − 2/π) and its quantiles; turned by `angle`, the 2-D mean
    turns with it (the correlated case)."""
    mu, sigma, thin = np.array([0.012, -0.007]), 0.006, 1e-6
    rot = np.array([[math.cos(angle), -math.sin(angle)], [math.sin(angle), math.cos(angle)]])
    cov = rot @ np.diag([sigma**2, thin**2]) @ rot.T
    half = np.array([[0.0, -0.4], [0.4, -0.4], [0.4, 0.4], [0.0, 0.4]])  # x ≥ 0, 0.4 m wide
    got = truncate_gaussian_2d(mu, cov, mu + half @ rot.T)
    want = mu + rot @ np.array([sigma * math.sqrt(2 / math.pi), 0.0])
    np.testing.assert_allclose(got.mean, want, rtol=0, atol=1e-7)
    assert got.mass == pytest.approx(0.5, abs=1e-6)
    if angle == 0.0:
        assert got.std[0] == pytest.approx(sigma * math.sqrt(1 - 2 / math.pi), abs=1e-7)
        assert got.lower[0] == pytest.approx(mu[0] + sigma * norm.ppf(0.525), abs=1e-7)
        assert got.upper[0] == pytest.approx(mu[0] + sigma * norm.ppf(0.975), abs=1e-7)


def test_moments_match_monte_carlo_on_a_correlated_belief():
    """The L's CoM region and a correlated Gaussian centred near its diagonal edge."""
    region = com_region(L_SHAPE, COM_MARGIN)
    m, cov = np.array([0.035, 0.03]), np.array([[1.2e-4, -0.5e-4], [-0.5e-4, 0.9e-4]])
    got = truncate_gaussian_2d(m, cov, region)
    rng = np.random.default_rng(0)
    s = rng.multivariate_normal(m, cov, 4_000_000)
    path = Polygon(region)
    from shapely import contains_xy

    s = s[contains_xy(path, s[:, 0], s[:, 1])]
    assert got.mass == pytest.approx(len(s) / 4_000_000, abs=1e-3)
    se = s.std(0) / math.sqrt(len(s))
    assert np.all(np.abs(got.mean - s.mean(0)) < 5 * se)
    np.testing.assert_allclose(got.std, s.std(0), rtol=3e-3)
    np.testing.assert_allclose(got.lower, np.quantile(s, 0.05, axis=0), atol=5e-5)
    np.testing.assert_allclose(got.upper, np.quantile(s, 0.95, axis=0), atol=5e-5)


def test_negligible_mass_falls_back_to_the_projection_with_the_gaussian_width():
    region = com_region(L_SHAPE, COM_MARGIN)
    got = truncate_gaussian_2d(np.array([0.2, 0.0]), np.diag([1e-6, 1e-6]), region)
    assert got.projected and got.mass < MIN_REGION_MASS
    assert got.mean[0] == pytest.approx(region[:, 0].max(), abs=1e-9)
    np.testing.assert_allclose(got.std, [1e-3, 1e-3], rtol=1e-6)
    assert np.all(got.lower <= got.mean) and np.all(got.mean <= got.upper)
    assert _covers(region, got.mean)


def test_the_zscore_is_consistent_with_the_reported_interval():
    region = com_region(L_SHAPE, COM_MARGIN)
    mean, cov = _belief((0.05, 0.0), (0.01, 0.01), rho=-0.3)
    est = estimate_from_belief(mean, cov, region)
    for bound, sign in ((est.lower, -1), (est.upper, 1)):
        z = est.zscore(bound)
        np.testing.assert_allclose(z, sign * K90, atol=1e-3)
    assert abs(est.zscore(est.mean)[COM]).max() < norm.ppf(1 - 1 / math.e)
    # a truth where the truncated belief has no mass: a large, finite z-score
    far = est.mean.copy()
    far[COM] = (0.2, 0.2)
    assert np.all(np.isfinite(est.zscore(far))) and np.all(est.zscore(far)[COM] > 7)


def test_the_estimate_is_deterministic_and_fast():
    import time

    region = com_region(L_SHAPE, COM_MARGIN)
    mean, cov = _belief((0.05, 0.01), (0.01, 0.015), rho=0.4)
    a = estimate_from_belief(mean, cov, region)
    t0 = time.perf_counter()
    b = estimate_from_belief(mean, cov, region)
    assert time.perf_counter() - t0 < 0.1  # ~5 ms; generous for a loaded machine
    for name in ("mean", "std", "lower", "upper"):
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name))


def test_to_json_is_the_design_estimate_format():
    est = estimate_from_belief(*_belief((0.0, 0.0), (0.005, 0.005)))
    out = est.to_json()
    assert list(out) == list(PARAM_NAMES)
    for i, n in enumerate(PARAM_NAMES):
        assert out[n] == {
            "mean": est.mean[i],
            "std": est.std[i],
            "interval90": [est.lower[i], est.upper[i]],
        }


# ---- log-normal parameters ---------------------------------------------------------------------


def test_a_log_normal_wider_than_twice_the_quantile_is_refused():
    """exp(a + s²/2) ≤ exp(a + k s) iff s ≤ 2k: at the bound the mean meets the upper end."""
    i = PARAM_NAMES.index("mass")
    mean, cov = _belief((0.0, 0.0), (0.005, 0.005))
    s_norm = 2 * K90 / space_scale()[i]
    cov[i, i] = (s_norm * (1 - 1e-6)) ** 2
    est = estimate_from_belief(mean, cov)
    assert est.mean[i] <= est.upper[i] and est.mean[i] / est.upper[i] > 0.999
    cov[i, i] = (s_norm * 1.01) ** 2
    with pytest.raises(ValueError, match="mass"):
        estimate_from_belief(mean, cov)


# ---- the user's reproductions ------------------------------------------------------------------


def test_the_l_shape_reproductions():
    """The learned filter moved only the printed mean (into the outline seen), not the interval:
    (a) a Gaussian whose c_x mean lies beyond the L: the mean was moved into the L while the
    interval stayed about the Gaussian's mean; (b) a mean inside the L's hull, in its notch, with
    an interval reaching beyond it. Here both come from the truncated belief."""
    region = com_region(L_SHAPE, COM_MARGIN)
    x_max = region[:, 0].max()
    # (a) the Gaussian's c_x mean beyond the region
    mean, cov = _belief((0.07, -0.01), (0.004, 0.004))
    gauss = estimate_from_belief(mean, cov)
    assert gauss.lower[2] > x_max  # the old report's interval lay wholly outside: any mean
    est = estimate_from_belief(mean, cov, region)  # moved inside missed it
    _check(est, region)
    assert est.upper[2] <= x_max + 1e-9 and est.com.mass > MIN_REGION_MASS
    # (b) the mean in the notch, the interval partly outside the hull
    mean, cov = _belief((0.025, 0.025), (0.006, 0.006))
    gauss = estimate_from_belief(mean, cov)
    assert gauss.upper[2] + gauss.upper[3] > 0.0625  # beyond the hull's diagonal edge
    est = estimate_from_belief(mean, cov, region)
    _check(est, region)
    assert est.mean[2] < gauss.mean[2] and est.upper[2] < gauss.upper[2]


# ---- properties --------------------------------------------------------------------------------


@st.composite
def _footprints(draw):
    """Footprints (V, 2) about the origin (m): L-shapes, or random star-shaped polygons (simple,
    mostly non-convex)."""
    if draw(st.booleans()):
        w, h = draw(st.floats(0.03, 0.2)), draw(st.floats(0.03, 0.2))
        a, b = draw(st.floats(0.1, 0.9)), draw(st.floats(0.1, 0.9))
        v = np.array([[0, 0], [w, 0], [w, b * h], [a * w, b * h], [a * w, h], [0, h]])
    else:
        n = draw(st.integers(3, 14))
        gaps = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n)))
        angles = 2 * np.pi * np.cumsum(gaps) / gaps.sum()
        radii = np.array(draw(st.lists(st.floats(0.01, 0.15), min_size=n, max_size=n)))
        v = np.column_stack([radii * np.cos(angles), radii * np.sin(angles)])
    poly = Polygon(v)
    if not poly.is_valid or poly.area < 1e-5:
        v = np.array([[0, 0], [0.05, 0], [0.05, 0.05], [0, 0.05]])
    c = Polygon(v).centroid
    return v - np.array([c.x, c.y])


@st.composite
def _beliefs(draw):
    """A normalised belief: mean in [-4, 4]⁵, covariance A Aᵀ (A's entries within ±1.5, so every
    log std stays below the 2k bound), the CoM block scaled by 10^[-4, 0]."""
    mean = np.array(draw(st.lists(st.floats(-4.0, 4.0), min_size=5, max_size=5)))
    a = np.array(draw(st.lists(st.floats(-1.5, 1.5), min_size=25, max_size=25))).reshape(5, 5)
    cov = a @ a.T + 1e-12 * np.eye(5)
    s = np.ones(5)
    s[COM] = 10.0 ** draw(st.floats(-4.0, 0.0))
    return mean, cov * np.outer(s, s)


@settings(max_examples=150, deadline=None)
@given(_footprints(), _beliefs(), st.floats(0.0, 0.006))
def test_every_reported_mean_lies_in_its_interval_and_the_com_in_its_region(fp, belief, margin):
    region = com_region(fp, margin)
    est = estimate_from_belief(*belief, region)
    _check(est, region)
    if not est.com.projected:
        # log-concave marginals: the mean lies between the 1/e and 1 − 1/e quantiles
        lo, hi = est.com.quantile(1 / math.e), est.com.quantile(1 - 1 / math.e)
        tol = 1e-6 * np.maximum(est.com.std, 1e-9)
        assert np.all(lo - tol <= est.com.mean) and np.all(est.com.mean <= hi + tol)
        assert np.all(est.lower[COM] >= region.min(0) - 1e-12)
        assert np.all(est.upper[COM] <= region.max(0) + 1e-12)
    # the parameters other than the CoM are the Gaussian belief's own
    free = estimate_from_belief(*belief)
    others = [i for i in range(5) if i not in COM]
    np.testing.assert_array_equal(est.mean[others], free.mean[others])
    np.testing.assert_array_equal(est.upper[others], free.upper[others])
    z = normalise_params(est.mean)
    assert np.all(np.isfinite(z))


# ---- I_z ≤ m·r² ---------------------------------------------------------------------------------

MI = [PARAM_NAMES.index("mass"), PARAM_NAMES.index("inertia")]
SQUARE = np.array([[-0.05, -0.05], [0.05, -0.05], [0.05, 0.05], [-0.05, 0.05]])


def _mass_inertia_belief(mass, inertia, log_sd=(0.3, 0.3), rho=0.0):
    """A belief with m and I_z log-normal about (mass, inertia) SI, log stds log_sd and log
    correlation rho; μ 0.5, the CoM at the origin with 2 mm std."""
    phi = np.array([mass, 0.5, 0.0, 0.0, inertia])
    mean = normalise_params(phi)
    sd = np.array([log_sd[0], 0.1, 0.002, 0.002, log_sd[1]]) / space_scale()
    corr = np.eye(5)
    corr[MI[0], MI[1]] = corr[MI[1], MI[0]] = rho
    return mean, corr * np.outer(sd, sd)


def test_an_inertia_above_what_the_outline_allows_is_truncated_to_a_possible_one():
    """m 0.3 kg with I_z 3 g·m² on a 10 cm square: m·r² at the centre is 1.5 g·m², so the
    Gaussian belief's own mean is impossible. Truncated to I_z ≤ m·r², the reported mean obeys
    it (E[I_z] ≤ r² E[m] pointwise), m rises and I_z falls, and the evaluation's count of
    impossible estimates goes from 1 to 0."""
    from pushtoknow.evaluation.metrics import impossible_estimates
    from pushtoknow.testbed.shapes import Footprint

    belief = _mass_inertia_belief(0.3, 3e-3)
    region = com_region(SQUARE, COM_MARGIN)
    free = estimate_from_belief(*belief, region)
    est = estimate_from_belief(*belief, region, outline=SQUARE)
    reach2 = float(np.max(np.sum((SQUARE - est.mean[COM]) ** 2, axis=1)))
    assert free.mean[4] > free.mean[0] * reach2  # the untruncated mean is impossible
    assert est.mean[4] <= est.mean[0] * reach2
    assert est.mean[0] > free.mean[0] and est.mean[4] < free.mean[4]
    _check(est, region)
    fp = [Footprint(SQUARE)]
    assert impossible_estimates(free.mean[None, None], fp) == 1
    assert impossible_estimates(est.mean[None, None], fp) == 0
    # μ and the CoM are untouched
    np.testing.assert_array_equal(est.mean[1:4], free.mean[1:4])


def test_the_truncated_mass_and_inertia_match_monte_carlo():
    """Moments, quantiles and z-scores of exp of (log m, log I_z) ~ N restricted to
    log I_z ≤ log m + log r², against 4·10⁶ samples, on a correlated belief straddling the line."""
    belief = _mass_inertia_belief(0.4, 1.6e-3, log_sd=(0.35, 0.25), rho=0.4)
    est = estimate_from_belief(*belief, outline=SQUARE)
    assert est.inertia is not None and 0.2 < est.inertia.mass < 0.9
    scale = space_scale()[MI]
    u_mean = np.log(np.array([0.4, 1.6e-3]))
    u_cov = scale[:, None] * belief[1][np.ix_(MI, MI)] * scale[None, :]
    rng = np.random.default_rng(1)
    u = rng.multivariate_normal(u_mean, u_cov, 4_000_000)
    u = u[u[:, 1] <= u[:, 0] + np.log(0.05**2 * 2)]  # reach of the square from its centre
    assert est.inertia.mass == pytest.approx(len(u) / 4_000_000, abs=1e-3)
    x = np.exp(u)
    se = x.std(0) / math.sqrt(len(x))
    assert np.all(np.abs(est.mean[MI] - x.mean(0)) < 5 * se)
    np.testing.assert_allclose(est.std[MI], x.std(0), rtol=3e-3)
    np.testing.assert_allclose(est.lower[MI], np.quantile(x, 0.05, axis=0), rtol=2e-3)
    np.testing.assert_allclose(est.upper[MI], np.quantile(x, 0.95, axis=0), rtol=2e-3)
    for bound, sign in ((est.lower, -1), (est.upper, 1)):
        np.testing.assert_allclose(est.zscore(bound)[MI], sign * K90, atol=1e-3)


def test_a_belief_well_inside_the_bound_is_reported_unchanged():
    belief = _mass_inertia_belief(1.0, 0.8e-3, log_sd=(0.2, 0.2))
    region = com_region(SQUARE, COM_MARGIN)
    est = estimate_from_belief(*belief, region, outline=SQUARE)
    free = estimate_from_belief(*belief, region)
    assert est.inertia is None
    for name in ("mean", "std", "lower", "upper"):
        np.testing.assert_array_equal(getattr(est, name), getattr(free, name))


@settings(max_examples=150, deadline=None)
@given(_footprints(), _beliefs(), st.floats(0.0, 0.006))
def test_every_estimate_with_an_outline_is_a_possible_body(fp, belief, margin):
    """m, μ, I_z positive, the CoM in the hull (`_check`, to rounding: a belief with no mass
    there is reported on its edge), I_z ≤ m·max‖p − c‖² at the reported CoM, and every mean
    inside its own interval."""
    region = com_region(fp, margin)
    est = estimate_from_belief(*belief, region, outline=fp)
    _check(est, region)
    assert np.all(est.mean[MI] > 0) and est.mean[1] > 0
    if est.inertia is not None and est.inertia.projected:
        return  # the belief holds no possible body: reported at the nearest one, its median
    reach2 = float(np.max(np.sum((fp - est.mean[COM]) ** 2, axis=1)))
    assert est.mean[4] <= est.mean[0] * reach2 * (1 + 1e-9)
