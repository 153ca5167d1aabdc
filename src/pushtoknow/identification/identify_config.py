"""Settings of the physics-based identifier (frozen, loadable from YAML)."""

from __future__ import annotations

import math

from pydantic import Field

from pushtoknow.common.frozen_config import Config
from pushtoknow.identification.prior import CATALOGUE_PRIOR, PriorRanges


class IdentifyConfig(Config):
    """How `identify` weighs the data, searches and reports.

    Noise model: the tactile force has the recording's own noise (`force_noise` None: the
    `tactile.force_noise_std` of the simulation settings stored with the pushes); the pose
    track is weighted as if measured to `position_noise` / `angle_noise` (a tracker's
    resolution and the testbed's start-pose sensitivity, docs/PHYSICS.md: ≤ 0.23 mm / 0.27°).
    """

    prior: PriorRanges = Field(
        CATALOGUE_PRIOR,
        description="ranges of m, μ and I_z the prior spreads over (`prior.PriorRanges`)",
    )
    force_noise: float | None = Field(None, gt=0, description="N; None: the recording's")
    position_noise: float = Field(5e-4, gt=0, description="m, per pose sample")
    angle_noise: float = Field(math.radians(0.5), gt=0, description="rad, per pose sample")
    huber: float = Field(
        3.0,
        gt=0,
        description="force residuals beyond this many noise std weigh linearly (robust to "
        "contact glitches); pose residuals stay quadratic",
    )
    screen_starts: int = Field(
        6, ge=0, description="prior draws screened (one rollout each) besides the closed-form start"
    )
    refine_starts: int = Field(
        4,
        ge=1,
        description="at most this many of the best starts are refined, the next one only while "
        "the fit stays poor (see `restart_chi2`): a stalled fit is far off, with narrow "
        "intervals, and another start usually finds the optimum",
    )
    restart_chi2: float = Field(
        1.2,
        gt=0,
        description="refine the next start only if the reduced χ² stays above this (≈ 1 at the "
        "optimum when the noise model is right)",
    )
    coarse_pose_factor: float = Field(
        10.0,
        ge=1,
        description="a fit still poor after every start (on a recording with a noise level) "
        "descends once more with the pose noise this many times larger (a landscape led by "
        "the force, without the pose misfit's local minima), then again under the true "
        "noise; kept if its objective is lower (1: no such stage)",
    )
    max_iterations: int = Field(20, ge=1, description="Levenberg–Marquardt iterations per start")
    step_tolerance: float = Field(
        1e-3, gt=0, description="stop when no fit coordinate moves more than this (normalised)"
    )
    max_step: float = Field(
        0.5, gt=0, description="largest change of a fit coordinate per iteration (normalised)"
    )
    cost_tolerance: float = Field(
        0.05,
        gt=0,
        description="stop when an iteration lowers the objective by less than this (the "
        "objective is χ²/2: one standard deviation along any direction is worth 0.5)",
    )
    fd_steps: tuple[float, float, float, float, float] = Field(
        (0.01, 0.1, 0.02, 0.02, 0.15),
        description="finite-difference step of each fit coordinate (log μ·m, log m at fixed "
        "μ·m, c_x, c_y, log I_z; normalised units): large where the response is weak, so the "
        "simulator's step-to-step jitter (a few χ² units) does not pose as information",
    )
    flat_information: float = Field(
        10.0,
        ge=0,
        description="a direction whose data information is below this many times the prior's "
        "is reported as not identified: it keeps the prior's width and the prior's estimate "
        "(below ~10 the curvature is within reach of the simulator's step-to-step jitter of a "
        "few χ² units, so a Laplace width there would not be honest)",
    )
    information_scale: tuple[float, float, float, float, float] = Field(
        (0.5, 0.5, 0.5, 0.5, 0.5),
        description="share of the data information the posterior keeps, per fit coordinate "
        "(log μ·m, log m at fixed μ·m, c_x, c_y, log I_z; 1: the Laplace approximation as it "
        "is). Below 1 it widens identified directions for what the noise model leaves out: the "
        "simulator's jitter and an optimum located only to within it (0.5: 1.4-fold). Chosen "
        "for 90% coverage on 48 novel objects (seeds 9–11, 5 mixed pushes, with the poor-fit "
        "rule, docs/identification), with `com_floor` and `inertia_floor`",
    )
    com_floor: float = Field(
        5e-5,
        ge=0,
        description="m: the CoM is not reported more precisely than this std (added in "
        "quadrature): a few pushes can locate it to a few µm by the curvature, below what the "
        "replay's step-to-step jitter allows; chosen for 90% coverage on 48 novel objects "
        "(seeds 1–3, 5 mixed pushes, docs/identification)",
    )
    inertia_floor: float = Field(
        0.1,
        ge=0,
        description="std of log I_z added in quadrature (0.1: ~10%): I_z is read from a few "
        "spin-downs whose replay depends on the start pose to within its noise; chosen with "
        "`information_scale` for 90% coverage on 48 novel objects (seeds 9–11, 5 mixed "
        "pushes, docs/identification)",
    )
    quasi_static_rule: bool = Field(
        True,
        description="when every push is quasi-static (constant profile, ≤ 0.2 m/s), keep m at "
        "fixed μ·m and I_z at the prior (physics: they do not enter quasi-static pushing; a "
        "Laplace width there would come from contact transients the replay reproduces only "
        "to within the start pose's noise)",
    )
    poor_fit_rule: bool = Field(
        True,
        description="when the reduced χ² stays above `restart_chi2` after every start and the "
        "coarse stage (a recording with a noise level): raise each channel's noise to its "
        "misfit counted by its effective number of samples, and keep m at fixed μ·m and I_z "
        "at the prior's width about the fit (the Laplace widths of a fit the replay cannot "
        "bring to the noise level are far too narrow: tens of std off)",
    )
    between_push_check: bool = Field(
        True,
        description="for a recording without a noise level (real data) and ≥ 3 pushes: fit "
        "again leaving out each push in turn and add the jackknife covariance of those fits "
        "(pushes that disagree reveal model error; K more fits)",
    )
    stop_at_rest: float = Field(
        1e-4, gt=0, description="m/s: a replayed release push stops once pad and object rest"
    )
    workers: int = Field(2, ge=1, description="processes for the batched rollouts")
