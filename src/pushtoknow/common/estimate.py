"""The reported estimate of one Gaussian parameter belief: mean, std and interval of ONE
distribution per parameter (docs/DESIGN.md §2).

A belief is a Gaussian N(mean_norm, cov_norm) over the normalised parameters
(`common.params`). What is reported from it, per parameter in `PARAM_NAMES` order, SI:

- **m, μ, I_z**: log-normal. Mean exp(a + s²/2) and std from `common.params.si_moments`; the
  `level` interval is equal-tailed in the normalised space, exp(a ± k s), k = Φ⁻¹(½ + level/2),
  asymmetric in SI. The mean lies inside it iff s ≤ 2k (3.29 at 90 %: s²/2 ≤ k s; the lower end
  always holds): the mean of a wider log-normal lies above its own upper quantile. Such a belief
  spans a factor above e^(2k·2k) ≈ 5·10⁴ in its interval (at 90 %, 6–17 times the catalogue
  prior's width in the normalised space), so something upstream has failed:
  `estimate_from_belief` refuses it with a ValueError naming the parameter rather than print a
  mean outside its interval, or a median under the name of a mean.
- **CoM** (c_x, c_y): the Gaussian's (c_x, c_y) marginal, truncated to `com_region` when one is
  given: the convex polygon where a CoM can lie (a rigid body's CoM is a convex combination of
  its points, so it lies in the convex hull of its footprint; `com_region` below shrinks the
  hull by a margin, as the testbed's object check does, `testbed.objects.COM_MARGIN`). Mean,
  std and equal-tailed interval of each coordinate are those of the truncated distribution
  (`truncate_gaussian_2d`). A Gaussian density is log-concave and so is the indicator of a
  convex set, so the truncated density is log-concave, and so is each of its marginals
  (Prékopa, 1973). The mean of a log-concave distribution on R lies between its 1/e and
  1 − 1/e quantiles, F(mean) ∈ [1/e, 1 − 1/e] (the one-dimensional Grünbaum inequality for
  log-concave measures, the exponential distribution the extreme; e.g. Bobkov, "Extremal
  properties of half-spaces for log-concave distributions", Ann. Probab. 24, 1996), hence
  inside every equal-tailed interval of level ≥ 1 − 2/e ≈ 0.264, the 90 % one included
  (property-tested, with the quantiles computed here). And the mean of a distribution over a
  convex region lies in the region.
  Without a region the CoM is the untruncated Gaussian (mean at the interval's centre).
- **m and I_z**, once an `outline` (the footprint seen) is given: a body of that footprint with
  its CoM at c has I_z ≤ m·r², r = max‖p − c‖ over the footprint (all its mass at the farthest
  point), so the Gaussian marginal of (log m, log I_z) is truncated to the half-plane
  log I_z ≤ log m + log r² at the reported CoM (`inertia_region`), by the same quadrature, and m
  and I_z reported as exp of its coordinates: mean and std by quadrature, interval and z-score
  through exp's monotonicity. The bound holds at every point of the truncated belief, so
  E[I_z] ≤ r²·E[m]: the reported means describe a possible body. Where the half-plane misses
  less than `NEGLIGIBLE_EXCESS` of the belief (computed in closed form: log I_z − log m is
  Gaussian), the log-normals are reported unchanged; where it holds less than
  `MIN_REGION_MASS`, the nearest possible (log m, log I_z) with the Gaussian's width, as for
  the CoM. That the mean of exp lies in its interval is property-tested, not proven here.

Truncated moments, computed deterministically (same inputs, same output) and without
sampling: the x-marginal density of N(m, S) restricted to a convex polygon R is
f(x) = φ(x; m_x, σ_x) · [Φ((y_hi(x) − c(x)) / s) − Φ((y_lo(x) − c(x)) / s)], with
[y_lo(x), y_hi(x)] the slice of R at x, c(x) and s the conditional mean and std of y given x:
exact in y, it leaves a 1-D integral over x, taken with the trapezoidal rule on `GRID_POINTS`
points spanning exactly the x-range of R ∩ {the band within `BAND` conditional and marginal
std of the mean}, the rest holding < 4·10⁻¹⁷ of the Gaussian. The cumulative integral gives the
CDF, its inverse the quantiles. Likewise for y. Measured against closed forms (a box: products
of `scipy.stats.truncnorm`; a half-plane: the half-normal) and 4·10⁶-sample Monte Carlo
(tests/common/test_estimate.py): within 10⁻⁷ m of the closed forms, and within 0.3 µm of a
64 times finer quadrature over 186 random beliefs and footprints; 3–6 ms per belief (2 cores).
Where the conditional mean's line crosses an edge within less than a grid step, the slice's
mass steps there; extra points cluster about each such crossing.

Where R holds less than `MIN_REGION_MASS` of the Gaussian (the belief says the CoM is where
no CoM can be), the CoM is reported at the point of R nearest the Gaussian's mean with the
Gaussian's std and an interval of the Gaussian's width about it (`TruncatedGaussian2D.projected`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.special import ndtr, ndtri
from scipy.stats import norm
from shapely.geometry import Point, Polygon
from shapely.geometry.polygon import orient
from shapely.ops import nearest_points

from pushtoknow.common.params import (
    LOG_PARAMS,
    PARAM_NAMES,
    denormalise_params,
    linear_param_affine,
    normalise_params,
    si_moments,
    space_scale,
)

DEFAULT_LEVEL = 0.9  # the interval every estimate reports (docs/DESIGN.md §2)
MIN_REGION_MASS = 1e-6  # below this share of the Gaussian inside the region: projection
GRID_POINTS = 4097  # quadrature points per CoM coordinate
BAND = 8.5  # std each side of the mean the quadrature covers (outside: < 4e-17 of the mass)
JITTER = 1e-9  # m: added to each CoM std², so a singular covariance still has a density
TINY_REGION = 1e-6  # m: half-width of the region `com_region` returns for too thin a footprint
Z_LIMIT = float(-ndtri(1e-15))  # |z-score| of a truth where the truncated belief has no mass
CONVEX_RTOL = 1e-6  # a region whose hull exceeds its area by more is not convex
COM = [PARAM_NAMES.index("com_x"), PARAM_NAMES.index("com_y")]
MASS_INERTIA = [PARAM_NAMES.index("mass"), PARAM_NAMES.index("inertia")]
# below this share of the belief beyond I_z ≤ m·r², m and I_z are reported untruncated
NEGLIGIBLE_EXCESS = 1e-9
_IS_LOG = np.array([k in LOG_PARAMS for k in PARAM_NAMES])
# about a step of the slice's mass, in its widths: extra quadrature points
_STEP_OFFSETS = np.array([0.0, *(s * w for w in (0.25, 0.5, 1.0, 2.0, 4.0, 8.0) for s in (-1, 1))])


def com_region(footprint, margin: float) -> np.ndarray:
    """Where a rigid body's CoM can lie, `margin` (m) from the edge: the convex hull of the
    footprint polygon (V, 2) (m, object frame; any simple polygon, convex or not) shrunk by
    `margin`, as vertices (W, 2) counter-clockwise. For a footprint too thin for the margin,
    a square of half-width `TINY_REGION` about the footprint's area centroid."""
    poly = Polygon(np.asarray(footprint, dtype=np.float64)).buffer(0)  # a traced outline may
    if poly.is_empty or poly.area <= 0.0:  # touch itself
        raise ValueError("the footprint has no area")
    inner = poly.convex_hull.buffer(-float(margin)) if margin > 0 else poly.convex_hull
    if inner.is_empty or inner.geom_type != "Polygon" or inner.area < TINY_REGION**2:
        c = np.asarray(poly.centroid.coords[0])
        return c + TINY_REGION * np.array([[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0]])
    return np.asarray(orient(inner, 1.0).exterior.coords[:-1], dtype=np.float64)


def _convex_polygon(region) -> Polygon:
    """The convex polygon (V, 2) as a counter-clockwise shapely polygon; ValueError if it is
    not one."""
    v = np.asarray(region, dtype=np.float64)
    if v.ndim != 2 or v.shape[1] != 2 or len(v) < 3 or not np.isfinite(v).all():
        raise ValueError(f"a region is a finite polygon (V ≥ 3, 2), got shape {v.shape}")
    poly = Polygon(v)
    if not poly.is_valid or poly.area <= 0.0:
        raise ValueError("the region is not a simple polygon with area")
    hull = poly.convex_hull
    if hull.area > poly.area * (1.0 + CONVEX_RTOL):
        raise ValueError(
            f"the region is not convex (its hull is {hull.area / poly.area - 1:.2%} larger); "
            "pass the convex hull (`com_region`)"
        )
    return orient(hull, 1.0)


def _half_planes(poly: Polygon) -> tuple[np.ndarray, np.ndarray]:
    """A (E, 2), b (E,) with poly = {p : A p ≤ b}, for a counter-clockwise convex polygon."""
    v = np.asarray(poly.exterior.coords, dtype=np.float64)
    e = np.diff(v, axis=0)
    a = np.column_stack([e[:, 1], -e[:, 0]])  # outward normals
    return a, np.einsum("ij,ij->i", a, v[:-1])


def _slices(poly: Polygon, x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The slice [y_lo, y_hi] (N,), (N,) of a counter-clockwise convex polygon at each x (N,)
    within its x-range: interpolated along its lower and upper chains (monotone in x)."""
    v = np.asarray(poly.exterior.coords[:-1], dtype=np.float64)
    order = np.lexsort((v[:, 1], v[:, 0]))
    first, last = int(order[0]), int(order[-1])  # leftmost-lowest, rightmost-highest
    n = len(v)
    lower = v[[(first + i) % n for i in range((last - first) % n + 1)]]  # left to right
    upper = v[[(last + i) % n for i in range((first - last) % n + 1)]][::-1]
    out = []
    for chain, pick in ((lower, np.minimum), (upper, np.maximum)):
        # a vertical edge at either end: one point per x, the chain's outer one
        tol = 1e-12 * max(float(np.ptp(v)), 1e-300)
        start = np.flatnonzero(np.concatenate([[True], np.diff(chain[:, 0]) > tol]))
        out.append(np.interp(x, chain[start, 0], pick.reduceat(chain[:, 1], start)))
    return out[0], out[1]


def _mass_between(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """P(lo < Z < hi) for a standard normal Z, without cancellation in either tail."""
    upper_tail = lo > 0.0
    p = np.where(upper_tail, ndtr(-lo) - ndtr(-hi), ndtr(hi) - ndtr(lo))
    return np.clip(p, 0.0, None)


@dataclass(frozen=True)
class _Marginal:
    """One coordinate of the truncated distribution: grid (N,), CDF (N,) from 0 to 1, density
    (N,) normalised to integrate to 1 over the grid."""

    grid: np.ndarray
    cdf: np.ndarray
    pdf: np.ndarray
    mass: float
    mean: float
    std: float

    def exp_moments(self) -> tuple[float, float]:
        """Mean and std of exp(x) (the SI moments of a log-space coordinate), by the same
        trapezoidal rule as the CDF."""
        shift = float(self.grid[-1])  # exp(x − shift) ≤ 1: no overflow
        e = np.exp(self.grid - shift)
        m1 = float(np.trapezoid(e * self.pdf, self.grid))
        m2 = float(np.trapezoid(e * e * self.pdf, self.grid))
        return m1 * np.exp(shift), float(np.sqrt(max(m2 - m1 * m1, 0.0))) * np.exp(shift)

    def quantile(self, p) -> np.ndarray:
        return np.interp(p, self.cdf, self.grid)

    def at(self, x) -> np.ndarray:
        return np.interp(x, self.grid, self.cdf, left=0.0, right=1.0)


def _marginal(m: np.ndarray, s: np.ndarray, poly: Polygon, axis: int) -> _Marginal | None:
    """The `axis` marginal of N(m (2,), s (2, 2)) truncated to the convex polygon `poly`, or
    None where the band about the mean misses the polygon (negligible mass)."""
    if axis == 1:  # swap the coordinates: the same computation with y as the outer variable
        m, s = m[::-1], s[::-1, ::-1]
        poly = orient(Polygon(np.asarray(poly.exterior.coords)[:, ::-1]), 1.0)
    sx = float(np.sqrt(s[0, 0]))
    beta = float(s[0, 1] / s[0, 0])
    sc = float(np.sqrt(max(s[1, 1] - s[0, 1] * beta, 0.0)))
    sc = max(sc, JITTER)
    # the band: |x − m_x| ≤ BAND σ_x and |y − c(x)| ≤ BAND s, a parallelogram
    x0, x1 = m[0] - BAND * sx, m[0] + BAND * sx
    c0, c1 = m[1] + beta * (x0 - m[0]), m[1] + beta * (x1 - m[0])
    band = Polygon(
        [(x0, c0 - BAND * sc), (x1, c1 - BAND * sc), (x1, c1 + BAND * sc), (x0, c0 + BAND * sc)]
    )
    inside = poly.intersection(band)
    if inside.is_empty:
        return None
    lo, _, hi, _ = inside.bounds
    if not hi > lo:
        return None
    a, b = _half_planes(poly)
    x = np.linspace(lo, hi, GRID_POINTS)
    # where the conditional mean's line crosses an edge, the slice's mass steps from 0 to 1
    # over s / |edge slope − β|: points clustered there resolve a step narrower than the grid
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = (b - a[:, 1] * (m[1] - beta * m[0])) / (a[:, 0] + a[:, 1] * beta)
        width = sc * np.abs(a[:, 1]) / np.abs(a[:, 0] + a[:, 1] * beta)
    step = (hi - lo) / (GRID_POINTS - 1)
    sharp = np.isfinite(cross) & (cross > lo) & (cross < hi) & (width < 8.0 * step)
    extra = cross[sharp, None] + width[sharp, None] * _STEP_OFFSETS[None, :]
    vx = np.asarray(poly.exterior.coords)[:, 0]
    x = np.unique(np.concatenate([x, np.clip(extra.ravel(), lo, hi), vx[(vx > lo) & (vx < hi)]]))
    y_lo, y_hi = _slices(poly, x)
    c = m[1] + beta * (x - m[0])
    p = np.where(y_hi > y_lo, _mass_between((y_lo - c) / sc, (y_hi - c) / sc), 0.0)
    f = np.exp(-0.5 * ((x - m[0]) / sx) ** 2) / (sx * np.sqrt(2.0 * np.pi)) * p
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (f[1:] + f[:-1]) * np.diff(x))])
    mass = float(cum[-1])
    if not mass > 0.0:
        return None
    w = f / mass
    mean = float(np.trapezoid(x * w, x))
    var = float(np.trapezoid((x - mean) ** 2 * w, x))
    return _Marginal(x, cum / mass, w, mass, mean, float(np.sqrt(max(var, 0.0))))


@dataclass(frozen=True, eq=False)
class TruncatedGaussian2D:
    """A bivariate Gaussian restricted to a convex polygon, summarised per coordinate.

    region (V, 2): the polygon (counter-clockwise); mass: the Gaussian's probability inside it;
    mean, std, lower, upper (2,): moments and equal-tailed `level` interval of each coordinate
    of the truncated distribution (`projected`: of the fallback below); projected: the region
    held less than `MIN_REGION_MASS`, so the mean is the region's point nearest the Gaussian's
    mean and std and interval are the Gaussian's own width about it."""

    region: np.ndarray
    mass: float
    mean: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    level: float
    projected: bool
    _marginals: tuple[_Marginal, _Marginal] | None = field(default=None, repr=False)

    def cdf(self, xy) -> np.ndarray:
        """(2,) each coordinate's marginal CDF at the point xy (2,)."""
        xy = np.asarray(xy, dtype=np.float64).reshape(2)
        if self._marginals is None:
            return norm.cdf(xy, self.mean, np.maximum(self.std, 1e-300))
        return np.array([float(g.at(v)) for g, v in zip(self._marginals, xy)])

    def quantile(self, p: float) -> np.ndarray:
        """(2,) each coordinate's p-quantile."""
        if self._marginals is None:
            return self.mean + self.std * float(ndtri(p))
        return np.array([float(g.quantile(p)) for g in self._marginals])

    def exp_moments(self) -> tuple[np.ndarray, np.ndarray]:
        """Mean and std (2,) of exp of each coordinate: the SI moments where the coordinates are
        logarithms (log-normal ones for the projected fallback)."""
        if self._marginals is None:
            v = self.std**2
            mean = np.exp(self.mean + 0.5 * v)
            return mean, mean * np.sqrt(np.expm1(v))
        pairs = [g.exp_moments() for g in self._marginals]
        return np.array([p[0] for p in pairs]), np.array([p[1] for p in pairs])

    def zscore(self, xy) -> np.ndarray:
        """(2,) Φ⁻¹ of each coordinate's CDF at xy: |z| ≤ Φ⁻¹(½ + level/2) iff that
        coordinate lies in its interval (for an untruncated Gaussian, the usual z-score);
        ±`Z_LIMIT` where the belief holds no mass."""
        u = np.clip(self.cdf(xy), 1e-15, 1.0 - 1e-15)
        return np.clip(ndtri(u), -Z_LIMIT, Z_LIMIT)


def truncate_gaussian_2d(mean, cov, region, level: float = DEFAULT_LEVEL) -> TruncatedGaussian2D:
    """N(mean (2,), cov (2, 2)) restricted to the convex polygon region (V, 2), summarised (see
    the module docstring for how, and `TruncatedGaussian2D` for what). Deterministic."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    m = np.asarray(mean, dtype=np.float64).reshape(2)
    s = np.asarray(cov, dtype=np.float64).reshape(2, 2)
    if not (np.isfinite(m).all() and np.isfinite(s).all()):
        raise ValueError("the belief is not finite")
    poly = _convex_polygon(region)
    vertices = np.asarray(poly.exterior.coords[:-1])
    # the nearest positive semi-definite matrix, and a nanometre of width for a density
    w, v = np.linalg.eigh(0.5 * (s + s.T))
    s = (v * np.clip(w, 0.0, None)) @ v.T + JITTER**2 * np.eye(2)
    k = float(ndtri(0.5 + level / 2))
    tails = (0.5 - level / 2, 0.5 + level / 2)
    marginals = [_marginal(m, s, poly, axis) for axis in (0, 1)]
    if any(g is None or g.mass < MIN_REGION_MASS for g in marginals):
        mass = 0.0 if marginals[0] is None else marginals[0].mass
        q = nearest_points(poly, Point(*m))[0]
        centre = np.array([q.x, q.y])
        sd = np.sqrt(np.diagonal(s))
        return TruncatedGaussian2D(
            vertices, mass, centre, sd, centre - k * sd, centre + k * sd, level, True
        )
    gx, gy = marginals
    return TruncatedGaussian2D(
        vertices,
        gx.mass,
        np.array([gx.mean, gy.mean]),
        np.array([gx.std, gy.std]),
        np.array([float(gx.quantile(tails[0])), float(gy.quantile(tails[0]))]),
        np.array([float(gx.quantile(tails[1])), float(gy.quantile(tails[1]))]),
        level,
        False,
        (gx, gy),
    )


def inertia_region(mean, cov, log_r2: float) -> np.ndarray:
    """Where (log m, log I_z) can lie for a body whose footprint reaches r from its CoM:
    I_z ≤ m·r², i.e. log I_z ≤ log m + log_r2 (log_r2 = log r², r in m). The half-plane as a
    convex polygon (V, 2) (a box cut by the line) large enough to hold every point within
    `BAND` std of the Gaussian N(mean (2,), cov (2, 2)) that lies in it, for
    `truncate_gaussian_2d`."""
    m = np.asarray(mean, dtype=np.float64).reshape(2)
    excess = float(m[1] - m[0] - log_r2)  # > 0: the mean itself lies beyond the line
    centre = m - 0.5 * max(excess, 0.0) * np.array([-1.0, 1.0])  # its nearest feasible point
    sd = float(np.sqrt(max(np.linalg.eigvalsh(np.asarray(cov, dtype=np.float64)).max(), 0.0)))
    h = 2.0 * BAND * sd + abs(excess) + 1e-3
    x0, x1, y0, y1 = centre[0] - h, centre[0] + h, centre[1] - h, centre[1] + h
    box = Polygon([(x0, y0), (x1, y0), (x1, y1), (x0, y1)])
    # below the line over a wider x-range (the centre lies on or below it, within h)
    below = Polygon(
        [
            (x0 - h, x0 - h + log_r2),
            (x0 - h, y0 - 3 * h),
            (x1 + h, y0 - 3 * h),
            (x1 + h, x1 + h + log_r2),
        ]
    )
    cut = box.intersection(below)
    return np.asarray(orient(cut, 1.0).exterior.coords[:-1], dtype=np.float64)


@dataclass(frozen=True, eq=False)
class ParameterEstimate:
    """The reported estimate of a Gaussian belief over the normalised parameters.

    mean, std, lower, upper (5,): SI, `PARAM_NAMES` order, of one distribution per parameter
    (log-normal m, μ, I_z; the CoM's Gaussian marginal, truncated to `com.region` when `com` is
    set; (log m, log I_z)'s Gaussian marginal truncated to I_z ≤ m·r² when `inertia` is set);
    lower/upper: its equal-tailed `level` interval, lower ≤ mean ≤ upper. mean_norm (5,),
    cov_norm (5, 5): the Gaussian belief itself; com: the CoM's truncated belief, or None;
    inertia: (log m, log I_z)'s truncated belief, or None; outline (V, 2): the footprint (m,
    the belief's object frame) that bounds I_z, or None."""

    mean: np.ndarray
    std: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    mean_norm: np.ndarray
    cov_norm: np.ndarray
    level: float = DEFAULT_LEVEL
    com: TruncatedGaussian2D | None = None
    inertia: TruncatedGaussian2D | None = None
    outline: np.ndarray | None = None

    @property
    def std_norm(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diagonal(self.cov_norm), 0.0, None))

    def zscore(self, truth) -> np.ndarray:
        """(5,) standardised error of an SI truth under the reported distribution: the truth
        lies in the `level` interval iff |zscore| ≤ Φ⁻¹(½ + level/2). The Gaussian's z-score in
        the normalised space, except for a truncated CoM, m and I_z: Φ⁻¹ of their marginal
        CDF."""
        t = np.asarray(truth, dtype=np.float64).reshape(len(PARAM_NAMES))
        z = (normalise_params(t) - self.mean_norm) / np.maximum(self.std_norm, 1e-12)
        if self.com is not None:
            z[COM] = self.com.zscore(t[COM])
        if self.inertia is not None:
            z[MASS_INERTIA] = self.inertia.zscore(np.log(t[MASS_INERTIA]))
        return z

    def to_json(self) -> dict:
        """{param: {"mean", "std", "interval90": [low, high]}} (docs/DESIGN.md §2), SI."""
        key = f"interval{round(100 * self.level)}"
        return {
            n: {"mean": float(m), "std": float(s), key: [float(a), float(b)]}
            for n, m, s, a, b in zip(
                PARAM_NAMES, self.mean, self.std, self.lower, self.upper, strict=True
            )
        }


def estimate_from_belief(
    mean_norm, cov_norm, com_region=None, level: float = DEFAULT_LEVEL, outline=None
) -> ParameterEstimate:
    """The reported estimate of the Gaussian belief N(mean_norm (5,), cov_norm (5, 5)) over the
    normalised parameters. com_region: the convex polygon (V, 2) (m, the belief's object frame)
    the CoM can lie in (see `com_region`), or None for the untruncated Gaussian. outline: the
    footprint (V, 2) (m, same frame) whose reach r from the reported CoM bounds I_z ≤ m·r²
    (module docstring), or None for untruncated m and I_z. ValueError for
    a malformed belief, a non-convex region or a log-normal wider than 2·Φ⁻¹(½ + level/2) in log
    space (its mean would lie above its interval; module docstring). Deterministic."""
    if not 0.0 < level < 1.0:
        raise ValueError(f"level must lie in (0, 1), got {level}")
    d = len(PARAM_NAMES)
    m = np.array(mean_norm, dtype=np.float64).reshape(-1)
    c = np.array(cov_norm, dtype=np.float64)
    if m.shape != (d,) or c.shape != (d, d):
        raise ValueError(f"a belief is mean ({d},), cov ({d}, {d}); got {m.shape}, {c.shape}")
    if not (np.isfinite(m).all() and np.isfinite(c).all()):
        raise ValueError("the belief is not finite")
    c = 0.5 * (c + c.T)
    sd = np.sqrt(np.clip(np.diagonal(c), 0.0, None))
    k = float(ndtri(0.5 + level / 2))
    log_sd = space_scale() * sd
    too_wide = _IS_LOG & (log_sd > 2.0 * k * (1.0 + 1e-12))
    if too_wide.any():
        i = int(np.argmax(too_wide))
        raise ValueError(
            f"{PARAM_NAMES[i]}: the belief's log-space std {log_sd[i]:.3g} exceeds 2·{k:.3g}, "
            f"so its log-normal mean lies above its {level:.0%} interval"
        )
    mean, std = si_moments(m, c)
    lower = denormalise_params(m - k * sd)
    upper = denormalise_params(m + k * sd)
    com = None
    if com_region is not None:
        affine = np.array([linear_param_affine(PARAM_NAMES[i]) for i in COM])
        offset, scale = affine[:, 0], affine[:, 1]
        com = truncate_gaussian_2d(
            offset + scale * m[COM],
            scale[:, None] * c[np.ix_(COM, COM)] * scale[None, :],
            com_region,
            level,
        )
        mean[COM], std[COM], lower[COM], upper[COM] = com.mean, com.std, com.lower, com.upper
    inertia = None
    vertices = None if outline is None else np.asarray(outline, dtype=np.float64).reshape(-1, 2)
    if vertices is not None:
        reach = float(np.max(np.linalg.norm(vertices - mean[COM][None], axis=1)))
        if not reach > 0.0:
            raise ValueError("the outline has no extent about the CoM")
        log_r2 = 2.0 * np.log(reach)
        scale = space_scale()[MASS_INERTIA]
        u = np.log(denormalise_params(m)[MASS_INERTIA])  # (log m, log I_z)
        cu = scale[:, None] * c[np.ix_(MASS_INERTIA, MASS_INERTIA)] * scale[None, :]
        gap_sd = float(np.sqrt(max(cu[0, 0] + cu[1, 1] - 2.0 * cu[0, 1], 0.0)))
        excess = ndtr((u[1] - u[0] - log_r2) / max(gap_sd, 1e-300))
        if excess > NEGLIGIBLE_EXCESS:
            inertia = truncate_gaussian_2d(u, cu, inertia_region(u, cu, log_r2), level)
            mean[MASS_INERTIA], std[MASS_INERTIA] = inertia.exp_moments()
            lower[MASS_INERTIA] = np.exp(inertia.lower)
            upper[MASS_INERTIA] = np.exp(inertia.upper)
    return ParameterEstimate(
        mean,
        std,
        lower,
        upper,
        m,
        c,
        level,
        com,
        inertia,
        vertices,
    )
