"""The simulator as a dual filter's model: the parameter belief updated push by push from the
replay of each executed push (docs/DESIGN.md §12).

The belief is a Gaussian over the fit coordinates u (5,) of `prior.fit_transform` (log μ·m,
log m at fixed μ·m, c_x, c_y, log I_z, normalised). After a push, the update is the iterated
(Gauss–Newton) Kalman update of that push's measurements, i.e. the maximum a posteriori u of

    Σ ρ(r_i(u)) + ½ (u − ū)ᵀ P⁻¹ (u − ū),

r the push's replayed force and pose track against the observed one in noise units (ρ Huber
on the force), ū, P the belief before the push; Levenberg–Marquardt steps with forward-difference
Jacobians from batched replays. The posterior covariance is the Laplace one at that point
(`fit.laplace_posterior`), its Jacobian statistically linearised across the belief's spread
(`optimise.linearised_information`, so that a replay's jitter counts as noise rather than
information). Directions the push carries less than `flat_information` times the belief's
information about (the belief before the push; the filter's prior with `flat_against_prior`)
keep the belief's width and mean. Each channel group's noise is raised
to the push's own misfit where the replay cannot reproduce it (a perceived outline or pose track
the replay only approximates), counted by its effective number of samples, so model error
widens the intervals instead of narrowing them.

`refit` updates the prior by every push so far at once, from several starts: the physics
filter's way out of a wrong basin when a push cannot be reproduced from the belief.

`expected_information` scores candidate pushes by the entropy an update would remove,
½ log det(I + P^½ JᵀWJ P^½), with J the candidate's forward-difference replay Jacobian at the
belief's mean (not linearised across the belief as the update is: a ranking, at six replays a
candidate).
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np
from pydantic import Field

from pushtoknow.common.frozen_config import Config
from pushtoknow.identification.fit import (
    is_quasi_static,
    laplace_posterior,
    misfit_noise_scale,
    without_blind,
)
from pushtoknow.identification.optimise import (
    DescentSettings,
    Objective,
    levenberg_marquardt,
    linearised_information,
)
from pushtoknow.identification.prior import CATALOGUE_PRIOR, PriorRanges
from pushtoknow.identification.replay import PushTrack, ReplayScene, RolloutPool
from pushtoknow.identification.residuals import (
    OFFSET_UNIT,
    ReplayResiduals,
    huber_weights,
    rest_weights,
)


class PhysicsFilterConfig(Config):
    """How the physics filter weighs a push and searches its update.

    The pose track is weighted as measured to `position_noise` / `angle_noise` per sample
    (perception's accuracy), the force with the recording's noise (`force_noise` None: the
    tactile noise of the simulation settings, 0.1 N where those have none)."""

    prior: PriorRanges = Field(
        CATALOGUE_PRIOR,
        description="ranges of m, μ and I_z the prior spreads over (`prior.PriorRanges`)",
    )
    force_noise: float | None = Field(None, gt=0, description="N; None: the recording's")
    position_noise: float = Field(2e-3, gt=0, description="m, per pose sample")
    angle_noise: float = Field(math.radians(2.5), gt=0, description="rad, per pose sample")
    huber: float = Field(3.0, gt=0, description="force residuals beyond this many std: linear")
    max_iterations: int = Field(6, ge=1, description="Gauss–Newton iterations per update")
    max_step: float = Field(0.5, gt=0, description="largest change of a fit coordinate per step")
    broyden_steps: int = Field(
        0,
        ge=0,
        description="Gauss–Newton steps between exact (finite-difference) Jacobians, the "
        "Jacobian updated by Broyden's rank-one rule in between (0: exact at every step; the "
        "posterior always uses an exact one). 3 halved the replays on the validation objects "
        "but stopped descents short of the optimum (overall error 0.65 against 0.14)",
    )
    step_tolerance: float = Field(1e-2, gt=0, description="stop when no coordinate moves more")
    cost_tolerance: float = Field(0.05, gt=0, description="stop when the objective drops less")
    fd_steps: tuple[float, float, float, float, float] = Field(
        (0.01, 0.1, 0.02, 0.02, 0.15),
        description="finite-difference step of each fit coordinate (normalised units)",
    )
    flat_information: float = Field(
        10.0,
        ge=0,
        description="a direction with less information than this × the belief's before "
        "the push (the prior's with `flat_against_prior`) keeps the belief's width and mean. "
        "1 took the validation objects' overall error from 0.20 to 0.12 but split μ·m of a "
        "random shape of the evaluation into m 0.06 kg and μ 10.4 (truth 0.84, 0.46; z −10) "
        "in a refit (docs/DESIGN.md §12)",
    )
    flat_against_prior: bool = Field(
        False,
        description="count `flat_information` in the prior's information, not the belief's "
        "before the push",
    )
    jump_chi2: float | None = Field(
        None,
        gt=0,
        description="an update whose mean moves a squared Mahalanobis distance d² above this "
        "under the belief before it adds (1 − jump_chi2 / d²) times the move's outer product "
        "to its covariance: pushes that disagree widen the belief along the disagreement "
        "(None: never)",
    )
    information_scale: float = Field(
        0.5,
        gt=0,
        le=1,
        description="share of a push's data information the update keeps (as `identify`'s): "
        "the replay's step-to-step jitter and an optimum located only to within it",
    )
    poor_fit_chi2: float = Field(
        2.0,
        gt=0,
        description="a push whose reduced χ² stays above this (the replay cannot reproduce "
        "it) reveals neither m at fixed μ·m nor I_z: its misfit there is model error",
    )
    inflation: tuple[float, ...] = Field(
        (),
        description="factors the belief's covariance is inflated by, in turn, when a push "
        "cannot be reproduced from it (the belief was too sure); () never. (100,) kept no "
        "inflated update on the validation objects of random seed 101 (17 poor pushes) while "
        "doubling the cost of each poor push",
    )
    refit_spread: float = Field(
        1.2,
        ge=0,
        description="a refit's search starts at the best of the belief's mean and that mean with "
        "its CoM at the outline hull's centroid and moved this many of the prior CoM's standard "
        "deviations along each principal axis",
    )
    refit_gain: float = Field(
        0.5,
        gt=0,
        description="a refit is kept when its reduced χ² over every push so far is at most "
        "this share of the belief's mean's (both as replayed from the prior)",
    )
    outline_views: int | None = Field(
        None,
        ge=2,
        description="once this many views of a traced outline are registered (the first push's "
        "and each push's end), the outline is traced again from all of them "
        "(`perception.footprint.fused_outline`), once, the pushes before refit on it, and "
        "replayed from then on (None: the first view's outline throughout). None by default: "
        "with 3, on the validation objects the CoM's error fell by 30–50% while m's rose by a "
        "quarter (docs/DESIGN.md §12)",
    )
    max_refits: int = Field(
        2,
        ge=0,
        description="a poor push (`poor_fit_chi2`) after the first refits every push so far "
        "from the prior (`refit`), kept when it explains them better (`refit_gain`), this many "
        "times per object at most (0: never). 2 was chosen on the validation objects: the "
        "CoM's error 20–60% lower there, the median time per object up to three times as "
        "long (docs/DESIGN.md §12)",
    )
    coarse_pose_factor: float = Field(
        10.0,
        ge=1,
        description="an update still poor after its descent descends once more with the pose "
        "noise this many times larger, then again under the true noise (1: never)",
    )
    restart_chi2: float | None = Field(
        None,
        gt=0,
        description="a push whose reduced χ² stays above this after its descents is searched "
        "again from each of the `restarts` the filter gives (the belief's mean with its CoM "
        "moved across the outline), the lowest objective kept (None: never). 2 lowered the "
        "validation objects' error (docs/DESIGN.md §12); not yet measured on the evaluation "
        "sets or real objects, where every push is poor",
    )
    pose_correlation: float = Field(
        0.7,
        ge=0,
        lt=1,
        description="lag-1 correlation of the pose track's error from frame to frame "
        "(perception's error drifts; its residuals are whitened as AR(1))",
    )
    rest_as_one: bool = Field(
        True,
        description="count a pose track's final stretch at rest as one sample "
        "(`residuals.rest_weights`, within the pose noise of the last pose): perception "
        "sees a resting object in the same image, with the same error, frame after frame",
    )
    end_pose_noise: tuple[float, float] | None = Field(
        (5e-4, math.radians(0.5)),
        description="m, rad: noise of a push's end pose registered in the image taken at rest "
        "after it (`PushTrack.end_pose`), a measurement of the replay's last pose beside the "
        "track (None: unused; chosen on validation objects, docs/DESIGN.md §12)",
    )
    misfit_noise: bool = Field(
        True, description="raise each channel's noise to the push's misfit where it is larger"
    )
    workers: int = Field(2, ge=1, description="replay processes")
    contact_offset_std: float = Field(
        1.5e-3,
        ge=0,
        description="m: prior std of where the object's edge lies along a push's line relative "
        "to the outline seen (the traced outline's error at the contact), estimated with each "
        "update and marginalised (0: the outline seen is exact)",
    )
    offset_fd_step: float = Field(0.3, gt=0, description="finite-difference step of an offset, mm")
    com_floor: float = Field(
        3e-3,
        ge=0,
        description="m: std of the CoM relative to the true outline added to the reported CoM "
        "(in quadrature): the traced outline's placement error (its corners and edges within "
        "about a pixel of the 256 px outline mask), which no number of pushes averages away "
        "(chosen on validation objects, docs/DESIGN.md §12)",
    )
    split_floor: float = Field(
        0.25,
        ge=0,
        description="std of log m at fixed μ·m (so of log μ too) added to the reported belief "
        "in quadrature: the split of μ·m into m and μ as the replay of a perceived pose track "
        "reads it off a slide, which no noise term holds (chosen on validation objects, "
        "docs/DESIGN.md §12)",
    )
    inertia_floor: float = Field(
        0.3,
        ge=0,
        description="std of log I_z added to the reported I_z in quadrature: a spin-down "
        "replayed on a perceived outline and CoM reads I_z with an error no noise term holds "
        "(chosen on validation objects, docs/DESIGN.md §12)",
    )
    look_ahead_candidates: int = Field(
        8, ge=1, description="candidates an active policy scores with replays"
    )
    linearisation_rounds: int = Field(
        2,
        ge=0,
        description="rounds of posterior linearisation of the push's information "
        "(`linearised_information`): the replay's Jacobian by central differences across the "
        "belief's spread (the first round the belief before the push, then the last round's "
        "posterior), its jitter and curvature there added to the noise (0: the "
        "forward-difference Jacobian at the optimum). 1 took 16% fewer replays per update on "
        "the validation objects but raised their overall error from 0.190 to 0.212 "
        "(docs/DESIGN.md §12)",
    )
    linearisation_spread: float = Field(
        1.0, gt=0, description="posterior standard deviations to each side of the optimum"
    )


@dataclass(frozen=True)
class PhysicsUpdate:
    """One push's update: mean (5,), cov (5, 5) in fit coordinates; chi2: reduced χ² of the
    push's misfit under the configured noise; noise_scale (5,): the factors the noise was raised
    by; information (D,): the push's data information in prior-whitened directions (the
    contact offset's included), ascending; identified: how many directions it revealed;
    replays: single-push replays it took; iterations: Gauss–Newton iterations; poor_fit: the
    replay could not reproduce the push (`poor_fit_chi2`); contact_offset (m): where the
    object's edge lay along the push line relative to the outline seen; inflation: the factor
    the belief's covariance was inflated by before the update (its largest per coordinate; 1:
    none); refit: the belief is `refit`'s of every push so far (contact_offset the last
    push's); start_chi2: the reduced χ² of each start of the search (the belief's mean first,
    then the extra starts in order)."""

    mean: np.ndarray
    cov: np.ndarray
    chi2: float
    noise_scale: np.ndarray
    information: np.ndarray
    identified: int
    replays: int
    iterations: int
    poor_fit: bool = False
    contact_offset: float = 0.0
    inflation: float = 1.0
    refit: bool = False
    start_chi2: tuple[float, ...] = ()


def rest_tolerance(config: PhysicsFilterConfig) -> tuple[float, float] | None:
    """`ReplayResiduals`' rest tolerance (m, rad) under `config` (None: `rest_as_one` off)."""
    return (config.position_noise, config.angle_noise) if config.rest_as_one else None


def iterated_update(
    mean: np.ndarray,
    cov: np.ndarray,
    track: PushTrack,
    scene: ReplayScene,
    pool: RolloutPool,
    sigmas: np.ndarray,
    config: PhysicsFilterConfig,
    extra_starts: Sequence[np.ndarray] = (),
    ceiling: np.ndarray | None = None,
    restarts: Sequence[np.ndarray] = (),
) -> PhysicsUpdate:
    """The belief (mean (5,), cov (5, 5), fit coordinates) after one push (module doc).
    `extra_starts`: other points to start the search from (the best of them and the mean, by
    objective, is refined), e.g. a closed-form reading of the first push. `restarts` (R, 5):
    points the search starts again from, each descended in full, when the push stays poor
    (`PhysicsFilterConfig.restart_chi2`).

    A push the replay cannot reproduce from the belief (reduced χ² above `poor_fit_chi2`) may
    say the belief was too sure of itself: the update is repeated from the belief's covariance
    inflated by each of `inflation` in turn (an adaptive, fading-memory filter), each
    coordinate's variance at most the `ceiling` covariance's (5, 5) (the prior's; None: no
    bound), and the first that fits is kept. If none fits, the push is one the replay cannot
    reproduce at all, and the uninflated update stands. An update that moves the mean further
    than the belief before it allowed is widened along the move (`widened_after_jump`,
    `PhysicsFilterConfig.jump_chi2`)."""
    reference = ceiling if config.flat_against_prior else None
    first = _update_once(
        mean, cov, [track], scene, pool, sigmas, config, extra_starts, restarts, reference
    )
    up = first
    for factor in config.inflation if first.poor_fit else ():
        d = np.full(len(mean), factor)
        if ceiling is not None:
            d = np.clip(np.diagonal(ceiling) / np.diagonal(cov), 1.0, factor)
        wide = np.sqrt(d)[:, None] * cov * np.sqrt(d)[None, :]
        again = _update_once(
            mean, wide, [track], scene, pool, sigmas, config, extra_starts, (), reference
        )
        replays = up.replays + again.replays
        if not again.poor_fit:
            up = dataclasses.replace(again, inflation=float(np.max(d)), replays=replays)
            break
        up = dataclasses.replace(up, replays=replays)
    if config.jump_chi2 is not None:
        jumped = widened_after_jump(mean, cov, up.mean, up.cov, config.jump_chi2, ceiling)
        up = dataclasses.replace(up, cov=jumped)
    return up


def widened_after_jump(
    mean_before: np.ndarray,
    cov_before: np.ndarray,
    mean: np.ndarray,
    cov: np.ndarray,
    gate: float,
    ceiling: np.ndarray | None = None,
) -> np.ndarray:
    """The posterior covariance (D, D) `cov`, plus (1 − gate / d²) ΔΔᵀ when the update's move
    Δ = mean − mean_before (D,) has d² = Δᵀ cov_before⁻¹ Δ above `gate`. A consistent
    filter's move lies within its belief's spread (d² ~ χ²_D at most), so a larger one says
    the belief before was too sure of a mean the push contradicts; the added term, the
    moment match of the two means' mixture grown towards ΔΔᵀ as d² exceeds the gate, keeps
    both inside the belief along Δ and leaves the other directions as they are. `ceiling`
    (D, D): no coordinate's variance is widened beyond its (the prior's; each coordinate's
    row and column scaled, so the result stays a covariance)."""
    delta = np.asarray(mean, dtype=np.float64) - mean_before
    d2 = float(delta @ np.linalg.solve(cov_before, delta))
    if d2 <= gate:
        return cov
    wide = cov + (1.0 - gate / d2) * np.outer(delta, delta)
    if ceiling is None:
        return wide
    bound = np.maximum(np.diagonal(ceiling), np.diagonal(cov))  # never narrower than cov
    scale = np.sqrt(np.minimum(1.0, bound / np.diagonal(wide)))
    return scale[:, None] * wide * scale[None, :]


def refit(
    prior_mean: np.ndarray,
    prior_cov: np.ndarray,
    tracks: Sequence[PushTrack],
    scene: ReplayScene,
    pool: RolloutPool,
    sigmas: np.ndarray,
    config: PhysicsFilterConfig,
    starts: Sequence[np.ndarray],
) -> PhysicsUpdate:
    """The belief after every push in `tracks` (K) at once, from the prior (prior_mean (5,),
    prior_cov (5, 5), fit coordinates): the update of the module doc with all K pushes'
    measurements and contact offsets, its search begun at the best of the prior's mean and
    `starts` (S, 5) by objective (`start_chi2` gives their misfits, the prior's first). A filter
    whose belief sits in the wrong basin (a CoM read off one push that later pushes cannot
    reproduce) is taken out of it this way: the batch is the smoother's answer."""
    return _update_once(prior_mean, prior_cov, tracks, scene, pool, sigmas, config, starts)


def _update_once(
    mean: np.ndarray,
    cov: np.ndarray,
    tracks: Sequence[PushTrack],
    scene: ReplayScene,
    pool: RolloutPool,
    sigmas: np.ndarray,
    config: PhysicsFilterConfig,
    extra_starts: Sequence[np.ndarray] = (),
    restarts: Sequence[np.ndarray] = (),
    reference: np.ndarray | None = None,
) -> PhysicsUpdate:
    """One update of `iterated_update` from the belief (mean, cov), without inflation, by the
    measurements of `tracks` (K pushes; K > 1: `refit`); `reference` (5, 5): the covariance
    whose information a direction must exceed `flat_information` times to be revealed (None:
    the belief's own)."""
    cfg = config
    tracks = list(tracks)
    res = ReplayResiduals(
        scene, tracks, pool, sigmas, rest_tolerance(cfg), cfg.pose_correlation, cfg.end_pose_noise
    )
    n = res.n_data
    before = pool.push_rollouts
    offset = cfg.contact_offset_std > 0
    k = len(tracks) if offset else 0
    if offset:  # each push's contact offset joins the state (mm), marginalised at the end
        mean = np.append(mean, np.zeros(k))
        cov = np.pad(cov, ((0, k), (0, k)))
        cov[np.arange(5, 5 + k), np.arange(5, 5 + k)] = (cfg.contact_offset_std / OFFSET_UNIT) ** 2
        extra_starts = [np.append(u[:5], np.zeros(k)) for u in extra_starts]
        restarts = [np.append(u[:5], np.zeros(k)) for u in restarts]
        if reference is not None:
            reference = np.pad(reference, ((0, k), (0, k)))
            reference[5:, 5:] = cov[5:, 5:]
    dim = len(mean)
    objective = Objective(res.residuals, n, res.robust, cfg.huber, mean, np.linalg.inv(cov))
    cost = objective.cost

    starts = np.stack([mean, *extra_starts])
    r_starts = res.residuals(starts)

    def reduced_chi2(r: np.ndarray, params: int) -> float:
        return float(np.sum(r[:n] ** 2) / max(n - params, 1))

    start_chi2 = tuple(reduced_chi2(r_s, dim) for r_s in r_starts)
    costs = [cost(r, u) for r, u in zip(r_starts, starts)]
    best = int(np.argmin(costs))
    u, r, c = starts[best].copy(), r_starts[best], costs[best]
    fd = np.asarray([*cfg.fd_steps, *[cfg.offset_fd_step] * k], dtype=np.float64)
    iterations = 0

    descent = DescentSettings(
        max_iterations=cfg.max_iterations,
        max_step=cfg.max_step,
        step_tolerance=cfg.step_tolerance,
        cost_tolerance=cfg.cost_tolerance,
        fd_steps=tuple(fd),
        trials=3,
        broyden_steps=cfg.broyden_steps,
        final_jacobian=cfg.linearisation_rounds == 0,  # else the rounds replace it
    )

    def descend(u, r, c):
        """Levenberg–Marquardt (`optimise.levenberg_marquardt`) from u (residuals r, objective
        c) → (u, r, c, jac, step), jac exact (forward differences) at the returned u (None
        when the linearisation rounds replace it)."""
        nonlocal iterations
        d = levenberg_marquardt(objective, u, r, descent, c)
        iterations += d.iterations
        return d.u, d.r, d.cost, d.jacobian, d.step

    u, r, c, jac, step = descend(u, r, c)
    if reduced_chi2(r, 5) > cfg.poor_fit_chi2 and cfg.coarse_pose_factor > 1:
        # stuck where the pose misfit's landscape is rough (a CoM far from the start): descend
        # once with the pose track weighted as if `coarse_pose_factor` times noisier (led by
        # the force), then again under the true weights; kept if the objective is lower
        true_sigmas = res.sigmas.copy()
        res.sigmas[2:] *= cfg.coarse_pose_factor
        u_c = descend(u, res.residuals(u[None])[0], np.inf)[0]
        res.sigmas = true_sigmas
        r_c = res.residuals(u_c[None])[0]
        fit = descend(u_c, r_c, cost(r_c, u_c))
        if fit[2] < c:
            u, r, c, jac, step = fit
    if cfg.restart_chi2 is not None and reduced_chi2(r, 5) > cfg.restart_chi2:
        # still poor: the belief may sit in another basin of this push's misfit
        for start in restarts:
            r_s = res.residuals(np.asarray(start)[None])[0]
            fit = descend(np.asarray(start, dtype=np.float64), r_s, cost(r_s, start))
            if fit[2] < c:
                u, r, c, jac, step = fit

    chi2 = reduced_chi2(r, dim)
    raised, raised_end = np.ones(5), np.ones(3)
    samples, ends = r[: res.n_samples].reshape(-1, 5), r[res.n_samples : n].reshape(-1, 3)
    if cfg.misfit_noise:
        raised = np.maximum(misfit_noise_scale(samples, res.push_lengths), 1.0)
        if len(ends):
            rms = np.sqrt([np.mean(ends[:, :2] ** 2)] * 2 + [np.mean(ends[:, 2] ** 2)])
            raised_end = np.maximum(rms, 1.0)
    data_scale = np.concatenate(  # (n,): each data residual's misfit scaling
        [np.tile(1.0 / raised, len(samples)), np.tile(1.0 / raised_end, len(ends))]
    )
    w_huber = huber_weights(r[:n] * data_scale, cfg.huber, res.robust)
    poor = chi2 > cfg.poor_fit_chi2
    # a quasi-static push reveals neither m at fixed μ·m nor I_z (docs/DESIGN.md §10); a push
    # the replay cannot reproduce reads them off accelerations and spin-downs it does not match
    rate = scene.sim_config.tactile.rate_hz
    blind = all(is_quasi_static(t, rate) for t in tracks) or poor

    def posterior(jac_d: np.ndarray, extra_var: np.ndarray | float = 0.0):
        """The Laplace posterior of data Jacobian jac_d (n, D), each residual's variance in
        noise units (1 + extra_var) raised by the misfit."""
        scale2 = data_scale**2
        w_d = w_huber * scale2 / (1.0 + extra_var * scale2)
        h_data = jac_d.T @ (w_d[:, None] * jac_d)
        if blind:
            h_data = without_blind(h_data)
        return laplace_posterior(
            h_data, step, cov, cfg.flat_information, cfg.information_scale, reference
        )

    if cfg.linearisation_rounds == 0:
        assert jac is not None
        post, lam_d, vecs, flat = posterior(jac[:n])
    spread = cov  # the first round across the belief before the push, then its posterior's
    for _ in range(cfg.linearisation_rounds):
        jac_s, jitter = linearised_information(
            res.residuals, u, r[:n], spread, cfg.linearisation_spread
        )
        post, lam_d, vecs, flat = posterior(jac_s, jitter)
        spread = post
    # along a direction the push does not reveal, the mean stays the prior's
    chol = np.linalg.cholesky(cov)
    w_u = np.linalg.solve(chol, u - mean)
    for j in np.where(flat)[0]:
        w_u -= vecs[:, j] * float(vecs[:, j] @ w_u)
    u = mean + chol @ w_u
    return PhysicsUpdate(
        mean=u[:5],
        cov=post[:5, :5],  # the contact offset marginalised
        chi2=chi2,
        noise_scale=raised,
        information=lam_d,
        identified=int((~flat).sum()),
        replays=pool.push_rollouts - before,
        iterations=iterations,
        poor_fit=poor,
        contact_offset=float(u[-1] * OFFSET_UNIT) if offset else 0.0,
        start_chi2=start_chi2,
    )


def expected_information(
    mean: np.ndarray,
    cov: np.ndarray,
    tracks: Sequence[PushTrack],
    scene: ReplayScene,
    pool: RolloutPool,
    sigmas: np.ndarray,
    config: PhysicsFilterConfig,
) -> np.ndarray:
    """(C,) entropy (nats) each candidate push would remove from the belief (mean, cov): ½ log
    det(I + Lᵀ JᵀWJ L), L = chol(cov), J the candidate's replay Jacobian at the mean (forward
    differences); quasi-static candidates carry no information on m at fixed μ·m and I_z. The
    tracks' observed force and pose are unused (zeros will do)."""
    fd = np.asarray(config.fd_steps, dtype=np.float64)
    probes = np.concatenate([mean[None], mean[None] + np.diag(fd)])
    chol = np.linalg.cholesky(cov)
    out = []
    for track in tracks:
        res = ReplayResiduals(scene, [track], pool, sigmas, None, config.pose_correlation)
        sims = np.stack(res.simulate(probes))  # (6, N, 5)
        weights = np.ones(sims.shape[1:])
        tol = rest_tolerance(config)
        if tol is not None:  # the rest the mean's replay predicts
            pose = np.concatenate([track.pose0[None], sims[0][:, 2:]])
            weights[:, 2:] = rest_weights(pose, *tol)[1:, None]
        sims = res.standardise(sims / res.sigmas, weights)
        jac = ((sims[1:] - sims[0][None]) / fd[:, None, None]).reshape(5, -1).T
        h = jac.T @ jac
        if is_quasi_static(track, scene.sim_config.tactile.rate_hz):
            h = without_blind(h)
        white = chol.T @ h @ chol
        sign, logdet = np.linalg.slogdet(np.eye(5) + 0.5 * (white + white.T))
        out.append(0.5 * logdet if sign > 0 else 0.0)
    return np.asarray(out)
