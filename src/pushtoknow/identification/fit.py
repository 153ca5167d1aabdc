"""`identify`: φ by simulator-in-the-loop least squares, with honest uncertainty.

Objective (maximum a posteriori): Σ ρ(r_i) + ½ (u − ū)ᵀ P_u⁻¹ (u − ū), where r are the misfits of
every replayed push against the recording in noise units (tactile force over its noise std,
pose over the assumed tracking noise), ρ the Huber loss (quadratic within `huber` std, linear
beyond, so one bad sample or a contact glitch cannot dominate) and the Gaussian term the prior
of `prior.prior_moments`, in the fit coordinates u of `prior.fit_transform` (log μ·m, log m at
fixed μ·m, CoM, log I_z: positive m, μ, I_z by construction, the μ·m ridge along an axis).

Search: a closed-form start (μ·m from the steady force of constant pushes, m and μ from the
acceleration and free slide of release pushes, `testbed.fidelity.read_release`; CoM at the
centroid, I_z at the prior mean) and `screen_starts` draws from the prior (μ·m between the
closed-form value, a lower bound, and `MU_M_START_SPAN` times it) are screened with one batched
rollout each; the best is refined by Levenberg–Marquardt with iteratively reweighted (Huber)
Gauss–Newton steps and forward difference Jacobians (one batch of 5 rollouts per iteration; the
testbed is not chaotic, so finite differences are smooth). The next start is refined only if
the fit stays poor (reduced χ² above `restart_chi2`). Candidates outside the simulable set (CoM
within the testbed's margin of the edge, I_z below the footprint's bound) are projected onto it
and pay a penalty residual, so the search stays inside.

Uncertainty: Laplace at the optimum, combined with the prior: the data information JᵀWJ
(scaled by the reduced χ² when that exceeds 1) is diagonalised in prior-whitened
coordinates; a direction carrying less than `flat_information` of the prior's information is
reported as not identified and its data information dropped, so it keeps exactly the prior's
width, never a narrow width from a flat or noisy curvature. Posterior cov = (H_data + P⁻¹)⁻¹
plus δδᵀ, δ the last Gauss–Newton step (a polish with a central-difference Jacobian): how far
the optimum may still be from where the search stopped. Reported (`common.estimate`): m, μ, I_z
log-normal, the CoM the Gaussian truncated to where a CoM can lie (the footprint's convex hull
less the testbed's `COM_MARGIN`), each parameter's mean, std and interval from one distribution.

Stages (docs/DESIGN.md §12), each a function with a frozen dataclass between: `fit_problem`
(residuals, objective) → `fit_starts` → `optimise` (Levenberg–Marquardt,
`optimise.levenberg_marquardt`) → `posterior` (intervals) → `report`.
"""

from __future__ import annotations

import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np
from scipy.stats import norm

from pushtoknow.common.errors import IdentificationError
from pushtoknow.common.estimate import ParameterEstimate, com_region, estimate_from_belief
from pushtoknow.common.params import (
    GRAVITY,
    PARAM_NAMES,
    denormalise_params,
    normalise_params,
    product_moments,
    space_scale,
)
from pushtoknow.identification.identify_config import IdentifyConfig
from pushtoknow.identification.optimise import (
    DescentSettings,
    Objective,
    central_jacobian,
    clip_step,
    levenberg_marquardt,
)
from pushtoknow.identification.prior import fit_transform, prior_moments
from pushtoknow.identification.replay import (
    PushTrack,
    ReplayScene,
    RolloutPool,
    feasible,
)
from pushtoknow.identification.residuals import ReplayResiduals
from pushtoknow.testbed.objects import COM_MARGIN
from pushtoknow.testbed.push import pad_positions
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig, check_testbed_version

TRACK_TOLERANCE = 1e-3  # m: a recorded pad track may depart this far from its commanded profile
LEVEL = 0.9
QUASI_STATIC_SPEED = 0.2  # m/s: constant pushes up to this speed are quasi-static
# m/s²: a recorded pad that accelerates more carries m in its force (m·a at least 5% of the
# friction μ·m·g at μ = 1)
QUASI_STATIC_ACCEL = 0.05 * GRAVITY
QUASI_STATIC_BLIND = [1, 4]  # fit coordinates they do not reveal: log m at fixed μ·m, log I_z
UNKNOWN_FORCE_NOISE = 0.1  # N: first guess for a recording without a noise level (real data)
NOISE_FLOOR_SHARE = 1e-2  # an estimated noise level stays above this share of its first guess
MU_M_START_SPAN = 1.5  # screened starts keep μ·m within [1, this] × the closed form's
COM_NOTE_MASS = 0.9  # a note says so when the CoM region holds less of the Gaussian than this
STEADY_AFTER = 1.0  # s: a constant push's force is steady from here (or its contact's middle)


@dataclass(frozen=True)
class Identification:
    """Result of `identify`, SI unless stated.

    mean, std (5,): posterior moments in PARAM_NAMES order (log-normal for m, μ, I_z; the CoM's
    of the Gaussian truncated to where a CoM can lie, the footprint's convex hull less the
    testbed's `COM_MARGIN`, and m's and I_z's to I_z ≤ m·r² on the footprint,
    `common.estimate`); estimate (5,): the MAP point (its CoM projected
    into the hull less `COM_MARGIN` + `COM_INSET`, `replay.feasible`); lower, upper (5,):
    equal-tailed `level` interval of the same distributions (asymmetric for m, μ, I_z), so
    lower ≤ mean ≤ upper; mean_norm (5,), cov_norm (5, 5): the Gaussian posterior over the
    normalised parameters (`common.params.normalise_params`); belief: the reported estimate of
    that posterior (`common.estimate.ParameterEstimate`, the source of mean, std, lower,
    upper and the z-scores); mu_m, mu_m_std, mu_m_interval: μ·m (kg);
    unidentified: the directions the pushes did not reveal (kept at the prior's width), each
    as a combination of normalised parameters; information (5,): data information of the
    prior-whitened eigendirections (1 = as much as the prior), descending; chi2: reduced χ² of
    the weighted misfit at the optimum; rollouts: candidate φ replayed over all pushes;
    push_rollouts: single push replays; seconds: wall time.
    """

    mean: np.ndarray
    std: np.ndarray
    estimate: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    mean_norm: np.ndarray
    cov_norm: np.ndarray
    mu_m: float
    mu_m_std: float
    mu_m_interval: tuple[float, float]
    unidentified: tuple[str, ...]
    information: np.ndarray
    chi2: float
    rollouts: int
    push_rollouts: int
    iterations: int
    starts: int
    seconds: float
    pushes: int
    profiles: tuple[str, ...]
    level: float = LEVEL
    notes: tuple[str, ...] = field(default=())
    data_information: np.ndarray | None = None  # (5, 5) fit coordinates, unscaled
    last_step: np.ndarray | None = None  # (5,) fit coordinates
    noise: np.ndarray | None = None  # (3,) force (N), position (m), angle (rad) std weighed by
    noise_estimated: bool = False  # the noise came from the misfit (a recording without one)
    poor_fit: bool = False  # χ² stayed above `restart_chi2`: the poor-fit rule widened it
    coarse_stage: bool = False  # the coarse-to-fine descent found the reported optimum
    belief: ParameterEstimate | None = field(default=None, repr=False)

    def zscore(self, truth) -> np.ndarray:
        """(5,) z-scores of a true φ (SI) under the reported distributions: the truth lies in
        the `level` interval iff |z| ≤ Φ⁻¹(½ + level/2). In the normalised space where the belief
        is Gaussian, except for the truncated CoM (`ParameterEstimate.zscore`)."""
        if self.belief is not None:
            return self.belief.zscore(truth)
        z = normalise_params(np.asarray(truth, dtype=np.float64))
        return (z - self.mean_norm) / np.sqrt(np.diagonal(self.cov_norm))

    def as_dict(self) -> dict:
        per = {
            k: {
                "mean": float(self.mean[i]),
                "std": float(self.std[i]),
                "estimate": float(self.estimate[i]),
                "interval": [float(self.lower[i]), float(self.upper[i])],
            }
            for i, k in enumerate(PARAM_NAMES)
        }
        return {
            "method": "physics-based identification (simulator in the loop, Laplace + prior)",
            "parameters": per,
            "interval_level": self.level,
            "mu_m": {
                "mean": self.mu_m,
                "std": self.mu_m_std,
                "interval": list(self.mu_m_interval),
            },
            "unidentified": list(self.unidentified),
            "information": self.information.tolist(),
            "mean_norm": self.mean_norm.tolist(),
            "cov_norm": self.cov_norm.tolist(),
            "reduced_chi2": self.chi2,
            "rollouts": self.rollouts,
            "push_rollouts": self.push_rollouts,
            "iterations": self.iterations,
            "starts_refined": self.starts,
            "seconds": self.seconds,
            "pushes": self.pushes,
            "profiles": list(self.profiles),
            "notes": list(self.notes),
            "poor_fit": self.poor_fit,
            "coarse_stage": self.coarse_stage,
            "noise_std": None
            if self.noise is None
            else {
                "force_N": float(self.noise[0]),
                "position_m": float(self.noise[1]),
                "angle_rad": float(self.noise[2]),
                "estimated_from_misfit": self.noise_estimated,
            },
            "data_information_fit": None
            if self.data_information is None
            else self.data_information.tolist(),
            "last_step_fit": None if self.last_step is None else self.last_step.tolist(),
        }


def tracks_from_records(records: Sequence[PushRecord], sim_config: SimConfig) -> list[PushTrack]:
    """The pushes to replay. A push whose recorded pad track follows its speed profile (within
    `TRACK_TOLERANCE`) over the settings' whole horizon (every simulated push) is replayed with
    that profile from its recorded start; any other (a real pusher's, a shorter one) is
    replayed along its recorded pad track, at the recorder's own rate where the record holds
    it (`PushRecord.pusher_fine`). Raises
    IdentificationError if there are none, or if a push is too short or not finite."""
    if not records:
        raise IdentificationError("no pushes to identify from")
    tracks = []
    for i, r in enumerate(records):
        if len(r.time) < 2:
            raise IdentificationError(f"push {i}: {len(r.time)} sample(s); at least 2 are needed")
        arrays = {"pusher": r.pusher, "pose": r.pose, "tactile": r.tactile[:, :2]}
        for name, a in arrays.items():
            if not np.isfinite(a).all():
                raise IdentificationError(f"push {i}: non-finite values in its {name} track")
        samples = int(round(sim_config.push.horizon * sim_config.tactile.rate_hz)) + 1
        try:
            want = pad_positions(r.push, r.time, sim_config.push, start=r.pusher[0])
            follows = float(np.max(np.linalg.norm(want - r.pusher, axis=1))) <= TRACK_TOLERANCE
        except ValueError:
            follows = False
        follows = follows and len(r.time) == samples  # a profile replays the whole horizon
        tracks.append(
            PushTrack(
                r.push,
                r.pusher[0].copy(),
                r.pose[0].copy(),
                r.tactile[:, :2],
                r.pose,
                None if follows else r.pusher.copy(),
                None if follows or r.pusher_fine is None else r.pusher_fine.copy(),
            )
        )
    return tracks


@dataclass(frozen=True)
class ClosedFormReading:
    """Rough φ read off pushes in closed form (`closed_form_start`); None: not readable from
    them. mu_m: μ·m (kg); mass: m (kg); friction: μ (dimensionless)."""

    mu_m: float | None
    mass: float | None
    friction: float | None


def closed_form_start(records: Sequence[PushRecord], sim_config: SimConfig) -> ClosedFormReading:
    """Rough φ from the records alone (`ClosedFormReading`). μ·m: largest median force
    magnitude of a constant push in steady contact (after `STEADY_AFTER`, or after the middle
    of a shorter contact phase; ≤ μ·m·g, equal on a centred push) over g; m and μ: medians of
    `testbed.fidelity.read_release` over release pushes (acceleration F = m(μg + a), free slide
    v²/(2μg))."""
    from pushtoknow.testbed.fidelity import read_release

    forces, masses, frictions = [], [], []
    for r in records:
        if r.push.profile == "constant":
            touching = r.tactile[:, 2] >= 0.5
            mid = float(np.mean(r.time[touching])) if touching.any() else 0.0
            steady = (r.time >= min(STEADY_AFTER, mid)) & touching
            if steady.any():
                forces.append(float(np.median(np.linalg.norm(r.tactile[steady, :2], axis=1))))
        elif r.push.profile == "release":
            try:
                reading = read_release(r, sim_config)
            except (ValueError, ZeroDivisionError, FloatingPointError, IndexError):
                continue  # IndexError: a push too short to hold its braking phase
            if np.isfinite(reading.friction) and 0.05 < reading.friction < 2.0:
                frictions.append(reading.friction)
                if np.isfinite(reading.mass) and 0.02 < reading.mass < 10.0:
                    masses.append(reading.mass)
    mass = float(np.median(masses)) if masses else None
    friction = float(np.median(frictions)) if frictions else None
    if forces:
        mu_m = max(forces) / GRAVITY
    elif mass is not None and friction is not None:
        mu_m = mass * friction
    else:
        mu_m = None
    return ClosedFormReading(mu_m=mu_m, mass=mass, friction=friction)


def is_quasi_static(track: PushTrack, rate: float) -> bool:
    """Whether a push is quasi-static: constant, at most `QUASI_STATIC_SPEED`, and, replayed
    along a recorded pad track sampled at `rate` (Hz), never accelerating by more than
    `QUASI_STATIC_ACCEL` (its start from rest included: a real pusher that starts touching
    the object accelerates it, and m·a is there in the force)."""
    push = track.push
    if push.profile != "constant" or push.speed > QUASI_STATIC_SPEED:
        return False
    if track.pad is None:
        return True
    velocity = np.diff(np.asarray(track.pad, dtype=np.float64), axis=0) * rate  # (T-1, 2)
    steps = np.diff(np.vstack([np.zeros((1, 2)), velocity]), axis=0) * rate
    return float(np.max(np.linalg.norm(steps, axis=1), initial=0.0)) <= QUASI_STATIC_ACCEL


def without_blind(h_data: np.ndarray) -> np.ndarray:
    """The data information (D, D), fit coordinates first, less what quasi-static pushing
    cannot reveal (`QUASI_STATIC_BLIND`: m at fixed μ·m and I_z, docs/DESIGN.md §10)."""
    h = h_data.copy()
    h[QUASI_STATIC_BLIND, :] = 0.0
    h[:, QUASI_STATIC_BLIND] = 0.0
    return h


def _describe(direction_z: np.ndarray) -> str:
    """A unit direction over the normalised parameters as text, e.g. "+1.00 inertia"."""
    d = direction_z / np.linalg.norm(direction_z)
    d = d if d[np.argmax(np.abs(d))] > 0 else -d
    parts = [f"{c:+.2f} {k}" for c, k in zip(d, PARAM_NAMES) if abs(c) >= 0.2]
    return " ".join(parts)


NOISE_GROUPS = ((0, 1), (2, 3), (4,))  # force, position, angle columns of a residual sample


def misfit_noise_scale(residuals: np.ndarray, lengths: Sequence[int]) -> np.ndarray:
    """(5,) factors turning assumed noise levels into the misfit's own, per channel group.

    residuals (N, 5): the weighted misfit samples (force x, y, x, y, θ), pushes of `lengths`
    samples one after another. Per group: RMS × √((1 + ρ) / (1 − ρ)), ρ ∈ [0, 0.99] the lag-1
    autocorrelation within pushes. A model error (what a real recording's misfit mostly is)
    runs in long correlated stretches, and counting each of its samples as independent
    evidence would make the intervals far too narrow; the AR(1) factor counts it by its
    effective number of samples (a white misfit keeps factor RMS)."""
    ends = np.cumsum(lengths)
    starts = ends - np.asarray(lengths)
    scale = np.ones(5)
    for g in NOISE_GROUPS:
        cols = residuals[:, list(g)]
        rms = float(np.sqrt(np.mean(cols**2)))
        num = den = 0.0
        for a, b in zip(starts, ends):
            x = cols[a:b]
            num += float(np.sum(x[1:] * x[:-1]))
            den += float(np.sum(x * x))
        rho = float(np.clip(num / den if den > 0 else 0.0, 0.0, 0.99))
        scale[list(g)] = max(rms, NOISE_FLOOR_SHARE) * np.sqrt((1 + rho) / (1 - rho))
    return scale


def laplace_posterior(
    h_data: np.ndarray,
    last_step: np.ndarray,
    prior_cov: np.ndarray,
    flat_information: float,
    information_scale: float | Sequence[float] = 1.0,
    reference_cov: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Posterior covariance (5, 5) in fit coordinates from the data information h_data (5, 5)
    at the optimum, the prior covariance and the last Gauss–Newton step (5,).

    The data information, scaled by `information_scale` (one share, or one per fit
    coordinate s: D^½ H D^½ with D = diag(s)), is diagonalised in prior-whitened
    coordinates (eigenvalue 1 = as informative as the prior); eigenvalues below
    `flat_information` are dropped (those directions keep the prior's width), the rest combine
    with the prior, and the last step's outer product is added. `reference_cov` (5, 5): the
    belief whose information `flat_information` counts in (None: `prior_cov`'s; a recursive
    filter's own prior, so that a push is weighed against what nothing had yet revealed rather
    than against the pushes before it). Returns (cov, eigenvalues (5,) ascending, eigenvectors
    (5, 5) in whitened coordinates, flat (5,) bool)."""
    chol = np.linalg.cholesky(prior_cov)
    dim = len(h_data)
    root = np.sqrt(np.broadcast_to(np.asarray(information_scale, dtype=np.float64), (dim,)))
    white = chol.T @ (root[:, None] * h_data * root[None, :]) @ chol
    lam, vecs = np.linalg.eigh(0.5 * (white + white.T))
    lam = np.clip(lam, 0.0, None)
    threshold = np.full(dim, float(flat_information))
    if reference_cov is not None:  # the reference's information along each eigenvector
        ref_white = chol.T @ np.linalg.solve(reference_cov, chol)
        threshold *= np.einsum("ij,ik,kj->j", vecs, ref_white, vecs)
    flat = lam < threshold
    kept = np.where(flat, 0.0, lam)
    cov = chol @ vecs @ np.diag(1.0 / (1.0 + kept)) @ vecs.T @ chol.T
    cov += np.outer(last_step, last_step)
    return 0.5 * (cov + cov.T), lam, vecs, flat


@dataclass(frozen=True, eq=False)
class FitProblem:
    """The residual stage of `identify`: what its later stages share.

    records (K): the pushes and `tracks` (K) what replays them; residuals: their replay misfit
    in noise units (`ReplayResiduals`, its `sigmas` (5,) the noise a stage weighs by); objective:
    the MAP objective over the fit coordinates u (5,) (`optimise.Objective`: Huber on the force,
    the feasibility penalties, the prior); transform (5, 5): normalised parameters → fit
    coordinates (`prior.fit_transform`); prior_z, prior_cov_z (5,), (5, 5): the prior over
    normalised parameters, prior_u, prior_cov_u, prior_chol the same in fit coordinates (and its
    Cholesky factor); descent: the Levenberg–Marquardt settings; quasi_static: the quasi-static
    rule applies (every push constant, ≤ `QUASI_STATIC_SPEED`); noise_unknown: the recording
    has no force noise level (real data); rollouts_before, push_rollouts_before: the pool's
    counters when the fit began; progress: told the number of candidates after each batch."""

    records: Sequence[PushRecord]
    scene: ReplayScene
    config: IdentifyConfig
    seed: int
    pool: RolloutPool
    progress: Callable[[int], None] | None
    tracks: list[PushTrack]
    residuals: ReplayResiduals
    objective: Objective
    transform: np.ndarray
    prior_z: np.ndarray
    prior_cov_z: np.ndarray
    prior_u: np.ndarray
    prior_cov_u: np.ndarray
    prior_chol: np.ndarray
    descent: DescentSettings
    quasi_static: bool
    noise_unknown: bool
    rollouts_before: int
    push_rollouts_before: int

    def replayed(self, n: int) -> None:
        """Report n candidates replayed to `progress`."""
        if self.progress is not None:
            self.progress(n)

    def reduced_chi2(self, r_data: np.ndarray) -> float:
        """Reduced χ² of data residuals r_data (n_data,) (any shape of n_data elements)."""
        return float(np.sum(r_data**2) / max(self.residuals.n_data - 5, 1))


@dataclass(frozen=True, eq=False)
class Starts:
    """The screened starts, best first: u (S, 5) fit coordinates, residuals (S, M) and cost (S,)
    (the MAP objective); closed_form: `closed_form_start`'s reading of the records."""

    u: np.ndarray
    residuals: np.ndarray
    cost: np.ndarray
    closed_form: ClosedFormReading


@dataclass(frozen=True, eq=False)
class Optimum:
    """The MAP fit: u (5,) fit coordinates, r (M,) its residuals, `cost` its objective and chi2
    its reduced χ², all under `sigmas` (5,: force x, y (N), x, y (m), θ (rad)), the noise weighed
    by at the end (the misfit's without a noise level, raised by the poor-fit rule); raised
    (5,): the poor-fit rule's factors on the noise (1: none); poor: that rule applied; coarse:
    the coarse-to-fine descent found u; starts: starts refined; iterations: Levenberg–Marquardt
    iterations in all."""

    u: np.ndarray
    r: np.ndarray
    cost: float
    chi2: float
    sigmas: np.ndarray
    raised: np.ndarray
    poor: bool
    coarse: bool
    starts: int
    iterations: int


@dataclass(frozen=True, eq=False)
class Posterior:
    """The Laplace posterior at the optimum, combined with the prior: mean_z (5,), cov_z (5, 5)
    over the normalised parameters, the CoM in the replay footprint's frame (before the scene's
    `frame_offset`); chi2: reduced χ² after the polish under the noise weighed by, fit_chi2
    under the noise the fit was given (before a poor fit's was raised); data_information (5, 5):
    JᵀWJ / max(1, χ²) in fit coordinates (less the blind directions where dropped); last_step
    (5,): the Gauss–Newton polish (fit coordinates); information (5,): the data information's
    prior-whitened eigenvalues, ascending; unidentified: the flat directions as text; spread
    (5, 5) or None: the leave-one-push-out jackknife covariance added to cov_z."""

    mean_z: np.ndarray
    cov_z: np.ndarray
    chi2: float
    fit_chi2: float
    data_information: np.ndarray
    last_step: np.ndarray
    information: np.ndarray
    unidentified: tuple[str, ...]
    spread: np.ndarray | None


def fit_problem(
    records: Sequence[PushRecord],
    tracks: list[PushTrack],
    scene: ReplayScene,
    config: IdentifyConfig,
    seed: int,
    pool: RolloutPool,
    progress: Callable[[int], None] | None = None,
) -> FitProblem:
    """The residual stage: the noise model, the replay residuals of `tracks` (K) and the MAP
    objective over the fit coordinates, with the prior (module doc)."""
    cfg = config
    rate = scene.sim_config.tactile.rate_hz
    quasi_static = cfg.quasi_static_rule and all(is_quasi_static(t, rate) for t in tracks)
    recorded_noise = scene.sim_config.tactile.force_noise_std
    noise_unknown = cfg.force_noise is None and recorded_noise == 0.0
    sigma_f = cfg.force_noise or (UNKNOWN_FORCE_NOISE if noise_unknown else recorded_noise)
    sigmas = np.array([sigma_f, sigma_f, cfg.position_noise, cfg.position_noise, cfg.angle_noise])
    rollouts_before, push_rollouts_before = pool.rollouts, pool.push_rollouts
    tmat = fit_transform()
    z_prior, p_z = prior_moments(cfg.prior)
    u_prior = tmat @ z_prior
    p_u = tmat @ p_z @ tmat.T
    p_u_inv = np.linalg.inv(p_u)
    chol = np.linalg.cholesky(p_u)
    prob = ReplayResiduals(scene, tracks, pool, sigmas)
    objective = Objective(prob.residuals, prob.n_data, prob.robust, cfg.huber, u_prior, p_u_inv)
    descent = DescentSettings(
        max_iterations=cfg.max_iterations,
        max_step=cfg.max_step,
        step_tolerance=cfg.step_tolerance,
        cost_tolerance=cfg.cost_tolerance,
        fd_steps=cfg.fd_steps,
        trials=4,
    )
    return FitProblem(
        records=records,
        scene=scene,
        config=cfg,
        seed=seed,
        pool=pool,
        progress=progress,
        tracks=tracks,
        residuals=prob,
        objective=objective,
        transform=tmat,
        prior_z=z_prior,
        prior_cov_z=p_z,
        prior_u=u_prior,
        prior_cov_u=p_u,
        prior_chol=chol,
        descent=descent,
        quasi_static=quasi_static,
        noise_unknown=noise_unknown,
        rollouts_before=rollouts_before,
        push_rollouts_before=push_rollouts_before,
    )


def fit_starts(problem: FitProblem) -> Starts:
    """The starts: the closed form (`closed_form_start`; CoM at the centroid) and
    `screen_starts` prior draws, screened by one batched rollout and ordered by objective."""
    cfg, tmat, z_prior = problem.config, problem.transform, problem.prior_z
    cf = closed_form_start(problem.records, problem.scene.sim_config)
    z_cf = z_prior.copy()
    i_m, i_mu = PARAM_NAMES.index("mass"), PARAM_NAMES.index("friction")
    mass0 = cf.mass if cf.mass is not None else float(denormalise_params(z_prior)[i_m])
    z_cf[i_m] = normalise_params(np.array([mass0, 0.5, 0, 0, 1e-3]))[i_m]
    if cf.mu_m is not None:
        z_cf[i_mu] = normalise_params(np.array([1.0, cf.mu_m / mass0, 0, 0, 1e-3]))[i_mu]
    z_cf[2:4] = normalise_params(np.array([1.0, 0.5, 0.0, 0.0, 1e-3]))[2:4]
    rng = np.random.default_rng(problem.seed)
    starts = [tmat @ z_cf]
    # the steady force of a constant push is at most μ·m·g (an off-centre push needs
    # less), so the draws keep μ·m between the closed form and MU_M_START_SPAN times it
    s = space_scale()
    per_log = 1.0 / (s[i_m] + s[i_mu])  # u_0 per unit of log μ·m (`fit_transform`)
    span = np.log(MU_M_START_SPAN)
    for _ in range(cfg.screen_starts):
        z = rng.multivariate_normal(z_prior, problem.prior_cov_z)
        u = tmat @ z
        u[0] = starts[0][0] + rng.uniform(0.0, span) * per_log
        starts.append(u)
    us = np.stack(starts)
    res = problem.residuals.residuals(us)
    problem.replayed(len(us))
    cost = np.array([problem.objective.cost(r, u) for r, u in zip(res, us)])
    order = np.argsort(cost, kind="stable")
    return Starts(us[order], res[order], cost[order], cf)


def optimise(problem: FitProblem, starts: Starts) -> Optimum:
    """The optimise stage: Levenberg–Marquardt (`optimise.levenberg_marquardt`) from the best
    start, the next one only while the reduced χ² stays above `restart_chi2`; a fit still poor
    gets the coarse-to-fine descent; then the noise from the misfit (a recording without a
    noise level, refined once under it) or the poor-fit rule's raised noise."""
    cfg, prob = problem.config, problem.residuals
    n = prob.n_data
    iterations = 0

    def refine(u: np.ndarray, r: np.ndarray) -> tuple[np.ndarray, np.ndarray, float, float]:
        """Levenberg–Marquardt from u (residuals r) → (u, r, cost, reduced χ²)."""
        nonlocal iterations
        d = levenberg_marquardt(problem.objective, u, r, problem.descent, None, problem.replayed)
        iterations += d.iterations
        return d.u, d.r, d.cost, problem.reduced_chi2(d.r[:n])

    best = None
    refined = 0
    for u0, r0 in zip(starts.u[: cfg.refine_starts], starts.residuals[: cfg.refine_starts]):
        refined += 1
        fit = refine(u0.copy(), r0)
        if best is None or fit[2] < best[2]:
            best = fit
        if best[3] <= cfg.restart_chi2:
            break
    assert best is not None  # refine_starts ≥ 1 and the closed-form start is always there
    coarse = False
    if not problem.noise_unknown and best[3] > cfg.restart_chi2 and cfg.coarse_pose_factor > 1.0:
        # a fit still poor after every start is usually caught where the pose misfit's
        # landscape is rough (a disc's spin, a CoM near an edge): descend once more with
        # the pose track weighted as if `coarse_pose_factor` times noisier (a smoother
        # landscape led by the force), then refine under the true weights from there.
        # (Without a noise level, χ² is not yet a measure of fit.)
        true_sigmas = prob.sigmas.copy()
        prob.sigmas[[2, 3, 4]] *= cfg.coarse_pose_factor
        r_c = prob.residuals(best[0][None])[0]
        problem.replayed(1)
        u_c, *_ = refine(best[0].copy(), r_c)
        prob.sigmas = true_sigmas
        r_c = prob.residuals(u_c[None])[0]
        problem.replayed(1)
        fit = refine(u_c, r_c)
        if fit[2] < best[2]:
            best, coarse = fit, True
    u, r, cost, chi2 = best
    poor, raised = False, np.ones(5)  # raised: the poor-fit rule's factors on the noise
    if problem.noise_unknown:
        # the recording has no noise level: each channel group's noise is its misfit at
        # the optimum (force, position, angle), and the fit is refined once under it
        prob.sigmas *= misfit_noise_scale(r[:n].reshape(-1, 5), prob.push_lengths)
        u, r, cost, chi2 = refine(u, prob.residuals(u[None])[0])
    elif cfg.poor_fit_rule and chi2 > cfg.restart_chi2:
        # the replay cannot bring the misfit to the noise level: model error or a local
        # optimum the noise model leaves out. As for a recording without a noise level,
        # each channel group's noise is raised to its misfit, counted by its effective
        # number of samples (a systematic misfit runs in long correlated stretches)
        poor = True
        raised = np.maximum(misfit_noise_scale(r[:n].reshape(-1, 5), prob.push_lengths), 1.0)
        prob.sigmas *= raised
        r = np.concatenate([(r[:n].reshape(-1, 5) / raised).reshape(-1), r[n:]])
        cost = problem.objective.cost(r, u)
        chi2 = problem.reduced_chi2(r[:n])
    return Optimum(u, r, cost, chi2, prob.sigmas.copy(), raised, poor, coarse, refined, iterations)


def posterior(problem: FitProblem, fit: Optimum) -> Posterior:
    """The intervals stage: a Gauss–Newton polish with the central-difference Jacobian, the
    Laplace posterior there combined with the prior (`laplace_posterior`; the blind directions
    of a quasi-static or poor fit dropped, flat directions at the prior's width and estimate),
    the floors on the CoM and I_z, and, without a noise level and with ≥ 3 pushes, the
    leave-one-push-out jackknife covariance."""
    cfg, prob, objective = problem.config, problem.residuals, problem.objective
    prob.sigmas = fit.sigmas.copy()  # the noise the optimum was weighed by
    n = prob.n_data
    u_prior, p_u, chol = problem.prior_u, problem.prior_cov_u, problem.prior_chol
    u, r, chi2 = fit.u, fit.r, fit.chi2
    fd = np.asarray(cfg.fd_steps, dtype=np.float64)
    jac = central_jacobian(prob.residuals, u, fd)
    problem.replayed(2 * len(fd))
    w = objective.weights(r)
    # one Gauss–Newton polish with the central Jacobian; the optimum is known only to
    # within this last step, so its outer product joins the covariance below
    h_full, grad = objective.normal_equations(jac, r, u)
    newton = clip_step(np.linalg.solve(h_full, -grad), cfg.max_step)
    trial = u + newton
    rt = prob.residuals(trial[None])[0]
    problem.replayed(1)
    if objective.cost(rt, trial) < fit.cost:
        u, r = trial, rt
        chi2 = problem.reduced_chi2(r[:n])
    # χ² under the noise the fit was given (before a poor fit's noise was raised)
    fit_chi2 = problem.reduced_chi2(r[:n].reshape(-1, 5) * fit.raised)
    h_data = jac.T @ (w[:, None] * jac) * (1.0 / max(1.0, chi2))
    if problem.quasi_static or fit.poor:
        # quasi-static pushes reveal neither m at fixed μ·m nor I_z (docs/DESIGN.md §10):
        # the curvature there comes from contact transients the replay reproduces only to
        # within the start pose's noise, so it is dropped and those stay at the prior's
        # width. A poor fit's m and I_z (read from accelerations and spin-downs it does
        # not reproduce) are as far off as its misfit allows, so they keep it too.
        h_data = without_blind(h_data)
    cov_u, lam_d, vecs, flat = laplace_posterior(
        h_data, newton, p_u, cfg.flat_information, cfg.information_scale
    )
    # along a direction the pushes do not reveal, the estimate is the prior's (given the
    # identified coordinates), as the information dropped there would have it
    fit_log_mass = u[1]
    w_u = np.linalg.solve(chol, u - u_prior)
    for j in np.where(flat)[0]:
        w_u -= vecs[:, j] * float(vecs[:, j] @ w_u)
    u = u_prior + chol @ w_u
    if fit.poor and not problem.quasi_static:
        # a poor fit keeps its own m at fixed μ·m, read from the force of accelerating
        # pushes that it still matches roughly (the prior's width says how little it is
        # worth); its I_z, read from spin-downs it does not reproduce (up to 13 times off
        # on validation objects), is the prior's
        u[1] = fit_log_mass
    t_inv = np.linalg.inv(problem.transform)
    z_map = t_inv @ u
    cov_z = t_inv @ cov_u @ t_inv.T
    cov_z = 0.5 * (cov_z + cov_z.T)
    com = [PARAM_NAMES.index("com_x"), PARAM_NAMES.index("com_y")]
    cov_z[com, com] += (cfg.com_floor / space_scale()[com]) ** 2
    i_iz = PARAM_NAMES.index("inertia")
    cov_z[i_iz, i_iz] += (cfg.inertia_floor / space_scale()[i_iz]) ** 2
    unidentified = tuple(_describe(t_inv @ chol @ vecs[:, j]) for j in np.where(flat)[0])
    spread = None
    records = problem.records
    if problem.noise_unknown and cfg.between_push_check and len(records) >= 3:
        # the pushes' disagreement is model error the misfit's noise level cannot show:
        # the jackknife covariance of leave-one-push-out fits joins the posterior's
        quiet = cfg.model_copy(update={"between_push_check": False})
        loo = np.stack(
            [
                identify(
                    [rec for j, rec in enumerate(records) if j != i],
                    problem.scene,
                    quiet,
                    problem.seed,
                    problem.progress,
                    problem.pool,
                ).mean_norm
                for i in range(len(records))
            ]
        )
        k = len(records)
        dev = loo - loo.mean(axis=0)
        spread = (k - 1) / k * dev.T @ dev
        cov_z = cov_z + spread
    return Posterior(z_map, cov_z, chi2, fit_chi2, h_data, newton, lam_d, unidentified, spread)


def report(
    problem: FitProblem, starts: Starts, fit: Optimum, post: Posterior, started: float
) -> Identification:
    """The report stage: the posterior's SI summaries in the record's object frame (the CoM
    truncated to where a CoM can lie, `common.estimate`), μ·m, the notes, as an
    `Identification`; `started`: `time.perf_counter()` when the fit began."""
    scene, pool = problem.scene, problem.pool
    footprint = scene.footprint
    z_map, cov_z = post.mean_z, post.cov_z
    # ---- SI summaries, the CoM in the record's object frame
    estimate = feasible(denormalise_params(z_map), footprint)[0]
    dx, dy = scene.frame_offset
    estimate[2:4] += (dx, dy)
    z_map = z_map.copy()
    z_map[2:4] += np.array([dx, dy]) / space_scale()[2:4]  # the CoM is normalised linearly
    # mean, std and interval of one distribution per parameter: the CoM's truncated to where a
    # CoM can lie (the footprint's convex hull less the testbed's margin, record frame)
    region = com_region(footprint.vertices, COM_MARGIN) + np.array([dx, dy])
    outline = footprint.vertices + np.array([dx, dy])
    belief = estimate_from_belief(z_map, cov_z, region, LEVEL, outline)
    mean, std, lower, upper = belief.mean, belief.std, belief.lower, belief.upper
    q = norm.ppf(0.5 + LEVEL / 2)
    pm, ps = product_moments(z_map, cov_z)
    s = space_scale()
    wv = np.zeros(5)
    wv[[0, 1]] = s[[0, 1]]
    log_pm = float(np.log(denormalise_params(z_map)[0] * denormalise_params(z_map)[1]))
    sd_pm = float(np.sqrt(max(wv @ cov_z @ wv, 0.0)))
    notes = _notes(problem, starts, fit, post, belief)
    tracks = problem.tracks
    return Identification(
        mean=mean,
        std=std,
        estimate=estimate,
        lower=lower,
        upper=upper,
        mean_norm=z_map,
        cov_norm=cov_z,
        mu_m=pm,
        mu_m_std=ps,
        mu_m_interval=(float(np.exp(log_pm - q * sd_pm)), float(np.exp(log_pm + q * sd_pm))),
        unidentified=post.unidentified,
        information=post.information[::-1].copy(),
        chi2=post.fit_chi2,
        rollouts=pool.rollouts - problem.rollouts_before,
        push_rollouts=pool.push_rollouts - problem.push_rollouts_before,
        iterations=fit.iterations,
        starts=fit.starts,
        seconds=time.perf_counter() - started,
        pushes=len(tracks),
        profiles=tuple(sorted({t.push.profile for t in tracks})),
        notes=tuple(notes),
        data_information=post.data_information,
        last_step=post.last_step,
        noise=fit.sigmas[[0, 2, 4]].copy(),
        noise_estimated=problem.noise_unknown,
        poor_fit=fit.poor,
        coarse_stage=fit.coarse,
        belief=belief,
    )


def _notes(
    problem: FitProblem,
    starts: Starts,
    fit: Optimum,
    post: Posterior,
    belief: ParameterEstimate,
) -> list[str]:
    """The report's notes: a poor fit, a noise level from the misfit, a truncated CoM, the
    jackknife's widening, pushes that leave m and I_z at the prior."""
    cfg, raised, sigmas = problem.config, fit.raised, fit.sigmas
    notes = []
    if fit.poor:
        notes.append(
            f"the fit stays poor (reduced χ² {post.fit_chi2:.2f} > {cfg.restart_chi2} after "
            f"{fit.starts} start(s)"
            + (" and a coarse-to-fine descent" if fit.coarse else "")
            + "): a local minimum, or pushes the replay cannot reproduce. Each channel's noise "
            "is raised to its misfit counted by its effective number of samples (force ×"
            f"{raised[0]:.1f}, position ×{raised[2]:.1f}, angle ×{raised[4]:.1f}); m at fixed "
            "μ·m keeps the fit's estimate at the prior's width, I_z the prior's"
        )
    elif post.chi2 > cfg.restart_chi2:
        notes.append(
            f"the fit stays poor (reduced χ² {post.chi2:.2f} > {cfg.restart_chi2}): the "
            "intervals are widened by √χ² only and may be too narrow"
        )
    if problem.noise_unknown:
        notes.append(
            "the recording has no noise level (real data): each channel's noise is its "
            "misfit at the optimum, counted by its effective number of samples (force "
            f"{sigmas[0]:.3g} N, position {sigmas[2] * 1e3:.3g} mm, angle "
            f"{np.degrees(sigmas[4]):.3g}°), so "
            "model error counts as noise and widens the intervals"
        )
    if belief.com is not None and belief.com.mass < COM_NOTE_MASS:
        notes.append(
            f"the Gaussian posterior puts only {belief.com.mass:.1%} of the CoM's probability "
            "where a CoM can lie (the footprint's convex hull less "
            f"{COM_MARGIN * 1e3:g} mm): the CoM's mean, std and interval are those of the "
            "posterior restricted to it"
            + (
                " (too little to restrict to: the mean is the nearest such point, the "
                "Gaussian's width about it)"
                if belief.com.projected
                else ""
            )
        )
    if post.spread is not None:
        cov_z = post.cov_z
        widened = np.sqrt(np.diagonal(cov_z) / np.maximum(np.diagonal(cov_z - post.spread), 1e-300))
        notes.append(
            "leave-one-push-out fits disagree: their jackknife covariance is added (std "
            + ", ".join(f"{n} ×{f:.1f}" for n, f in zip(PARAM_NAMES, widened))
            + ")"
        )
    if problem.quasi_static:
        notes.append(
            "quasi-static pushes only (constant, ≤ "
            f"{QUASI_STATIC_SPEED:g} m/s): m and μ separate only through dynamic content "
            "(acceleration, free slide) and I_z does not enter, so m at fixed μ·m and I_z keep "
            "the prior's width; μ·m and the CoM are identified"
        )
    elif starts.closed_form.mass is None:
        notes.append(
            "no release push: m and μ separate only through dynamic content (acceleration, "
            "free slide), so constant pushes leave them at the prior except for μ·m"
        )
    return notes


def identify(
    records: Sequence[PushRecord],
    scene: ReplayScene,
    config: IdentifyConfig | None = None,
    seed: int = 0,
    progress: Callable[[int], None] | None = None,
    pool: RolloutPool | None = None,
) -> Identification:
    """Fit φ to recorded pushes of one object by replaying them in the testbed's scene.

    records: the object's pushes (K, each T samples); scene: its footprint and the simulation
    settings the pushes were recorded with. progress(n) is called with the number of candidate
    φ replayed after every batch. Same inputs and seed, same result (any number of workers).
    Stages: `fit_problem` (residuals) → `fit_starts` → `optimise` → `posterior` (intervals) →
    `report`.
    """
    cfg = config or IdentifyConfig()
    started = time.perf_counter()
    check_testbed_version(scene.sim_config, "the pushes")
    tracks = tracks_from_records(records, scene.sim_config)
    own_pool = pool is None
    pool = pool or RolloutPool(cfg.workers)
    try:
        problem = fit_problem(records, tracks, scene, cfg, seed, pool, progress)
        starts = fit_starts(problem)
        fit = optimise(problem, starts)
        post = posterior(problem, fit)
    finally:
        if own_pool:
            pool.close()
    return report(problem, starts, fit, post, started)
