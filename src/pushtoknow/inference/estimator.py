"""The estimator interface (docs/DESIGN.md §9): one object's parameter belief, updated push by
push, whatever the model behind it.

An `Estimator` holds a Gaussian belief over the normalised parameters φ̃ (`common.params`) and
offers four things to the run (`inference.session.infer_object`) and to push policies:

- `estimate(index, push)`: the belief as a typed `PushEstimate` (SI moments, 90% intervals);
- `start_pose(view, initial_pose)`: the object's pose (x, y, θ) before the next push, from
  perception;
- `update(record, view, pose0)`: the belief after an executed push (what was commanded, what was
  seen and felt: a `testbed.sim.PushRecord`); returns the pose track the update used;
- `information(candidates, view, pose0, score, horizon_fraction)`: how much each candidate push
  is expected to reveal (the scoring hook of active policies, `inference.policies`).

Two implementations: the paper's learned dual filter (`inference.learned_filter`) and the
simulator-in-the-loop dual filter (`inference.physics_filter`).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import torch
from pydantic import Field

from pushtoknow.active.selection import ScoreName
from pushtoknow.common.estimate import ParameterEstimate, estimate_from_belief
from pushtoknow.common.estimators import DEFAULT_ESTIMATOR, EstimatorName
from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS, PARAM_NAMES
from pushtoknow.common.policy_names import PolicyName
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.push import PROFILES, ProfileName, Push
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig

INTERVAL_LEVEL = 0.9  # the interval every estimate reports


class InferenceConfig(Config):
    """Settings of an inference run and its estimator."""

    pushes: int = Field(5, ge=1)
    policy: PolicyName = "uniform"
    estimator: EstimatorName = Field(
        DEFAULT_ESTIMATOR,
        description="the estimator: the physics filter or the paper's learned dual filter",
    )
    candidates: int = Field(16, ge=1, description="affordances sampled per push decision")
    num_sigma_points: int | None = Field(None, ge=MIN_SIGMA_POINTS, description="None: the model's")
    init_pose_std: tuple[float, float, float] = Field(
        (0.002, 0.002, 0.03), description="pose std at a push's start (m, m, rad)"
    )
    active_horizon_fraction: float = Field(0.5, gt=0, le=1)
    profiles: tuple[ProfileName, ...] = Field(
        ("constant",),
        min_length=1,
        description="speed profiles the policy may use: each candidate gets one (in turn); "
        "uniform cycles through them push by push, random draws one",
    )


def profile_speeds(sim_config: SimConfig) -> dict[str, float]:
    """The characteristic speed v (m/s) of each profile under the testbed's push settings."""
    return {p: sim_config.push.profile_speed(p) for p in PROFILES}


@dataclass(frozen=True)
class PushEstimate:
    """The parameter belief after push `index` (1-based; 0 = the prior) as reported: `belief`
    (`common.estimate.ParameterEstimate`) holds the Gaussian over the normalised parameters
    (mean_norm (K,), cov_norm (K, K)) and the SI mean, std and 90% interval (K,) of one
    distribution per parameter: log-normal m, μ, I_z, the CoM truncated to where a CoM can lie
    (the footprint's convex hull less the testbed's margin) once the footprint is seen, so
    every mean lies inside its interval. PARAM_NAMES order."""

    index: int
    belief: ParameterEstimate
    push: Push | None = None

    @property
    def mean(self) -> np.ndarray:
        return self.belief.mean

    @property
    def std(self) -> np.ndarray:
        return self.belief.std

    @property
    def mean_norm(self) -> np.ndarray:
        return self.belief.mean_norm

    @property
    def cov_norm(self) -> np.ndarray:
        return self.belief.cov_norm

    @property
    def std_norm(self) -> np.ndarray:
        return self.belief.std_norm

    def interval(self, level: float = INTERVAL_LEVEL) -> tuple[np.ndarray, np.ndarray]:
        """Equal-tailed SI interval (lo, hi) (K,) holding `level` of the reported
        distributions (asymmetric for m, μ and I_z)."""
        b = self.belief
        if level != b.level:
            region = None if b.com is None else b.com.region
            b = estimate_from_belief(b.mean_norm, b.cov_norm, region, level, b.outline)
        return b.lower, b.upper

    def zscore(self, truth: np.ndarray) -> np.ndarray:
        """(K,) standardised error of an SI truth under the reported distributions: the truth
        lies in the level-L interval iff |zscore| ≤ the two-sided L quantile."""
        return self.belief.zscore(np.asarray(truth, dtype=np.float64))

    def as_dict(self) -> dict:
        """{param: {mean, std, interval90}} (SI)."""
        return self.belief.to_json()


def belief_to_estimate(
    index: int,
    mean: torch.Tensor | np.ndarray,
    cov: torch.Tensor | np.ndarray,
    push: Push | None = None,
    com_region: np.ndarray | None = None,
    outline: np.ndarray | None = None,
) -> PushEstimate:
    """Normalised parameter belief (K,), (K, K) → `PushEstimate`; com_region: the convex
    polygon (V, 2) (m, object frame) the CoM can lie in, outline: the footprint (V, 2) (m,
    object frame) that bounds I_z ≤ m·r²; both None before the footprint is seen
    (`common.estimate.estimate_from_belief`)."""
    m = torch.as_tensor(mean).detach().double().numpy()
    c = torch.as_tensor(cov).detach().double().numpy()
    belief = estimate_from_belief(m, c, com_region, INTERVAL_LEVEL, outline)
    return PushEstimate(index, belief, push)


@dataclass
class InferenceResult:
    """prior: the belief before any push; estimates: one per push; truth: SI (K,) or None;
    records: the executed pushes; poses: the pose track each update used (T, 3);
    estimator: its name; seconds: wall time of each push's update and replays: the
    single-push simulations it ran (`Estimator.replays`; neither in the JSON, which the same
    seed makes identical); outline (V, 2) (m, object frame) and height (m): the
    object as the estimator saw it (`Estimator.seen_object`), None before any push."""

    prior: PushEstimate
    estimates: list[PushEstimate]
    truth: np.ndarray | None
    records: list[PushRecord] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    object_name: str = ""
    estimator: str = ""
    seconds: list[float] = field(default_factory=list)
    replays: list[int] = field(default_factory=list)
    outline: np.ndarray | None = None
    height: float | None = None

    def add_seen(self, estimator: Estimator) -> None:
        """Keep the outline and height `estimator` saw (`Estimator.seen_object`)."""
        seen = estimator.seen_object()
        if seen is not None:
            self.outline, self.height = seen

    def to_json(self) -> dict:
        return {
            "object": self.object_name,
            "estimator": self.estimator,
            "outline": None if self.outline is None else np.round(self.outline, 6).tolist(),
            "height": self.height,
            "prior": {"estimate": self.prior.as_dict()},
            "pushes": [
                {
                    "estimate": e.as_dict(),
                    "push": None if e.push is None else push_dict(e.push),
                }
                for e in self.estimates
            ],
            "truth": None
            if self.truth is None
            else {n: float(v) for n, v in zip(PARAM_NAMES, self.truth, strict=True)},
        }


def push_dict(p: Push) -> dict:
    """A push's JSON: contact (object frame, m), direction (rad), profile, speed (m/s)."""
    return {
        "contact": [float(c) for c in p.contact],
        "direction": float(p.direction),
        "profile": p.profile,
        "speed": float(p.speed),
    }


class Estimator(ABC):
    """One object's parameter belief, updated push by push (module doc). Implementations keep
    their own random streams; the run's candidate sampling and policy use another."""

    name: str

    @abstractmethod
    def estimate(self, index: int, push: Push | None = None) -> PushEstimate:
        """The current belief as the estimate after push `index` (0: the prior)."""

    @abstractmethod
    def start_pose(self, view: View, initial_pose: np.ndarray | None) -> np.ndarray:
        """(3,) pose (x, y, θ) of the object seen in `view` at the next push's start;
        `initial_pose` defines the object frame at the first push when given."""

    @abstractmethod
    def see_object(self, view: View, pose0: np.ndarray) -> None:
        """Take the object as seen in the first push's `view` at pose0 (3,), which fixes the
        object frame: its outline bounds every later estimate (`common.estimate`), and a prior
        that follows the footprint becomes the footprint's. Called before the prior is
        reported; a later call changes nothing."""

    @abstractmethod
    def update(self, record: PushRecord, view: View | None, pose0: np.ndarray) -> np.ndarray:
        """The belief after the executed push `record` of the object seen in `view` at pose0
        (None: a recording without images, its poses tracked). Returns the pose track (T, 3)
        the update used."""

    @abstractmethod
    def information(
        self,
        candidates: Sequence[Push],
        view: View,
        pose0: np.ndarray,
        score: ScoreName,
        horizon_fraction: float,
    ) -> np.ndarray:
        """(C,) expected information of each candidate push under the current belief (higher
        is better; `active.selection` defines the scores)."""

    @abstractmethod
    def seen_object(self) -> tuple[np.ndarray, float] | None:
        """The object as seen at the first push: its outline (V, 2) (m, in the object frame the
        estimates use) and height (m); None before `see_object`."""

    def replays(self) -> int:
        """Single-push simulations the last update ran: its cost on any machine, where wall
        time varies with the host (0: an estimator without the simulator in the loop)."""
        return 0

    def close(self) -> None:  # noqa: B027 - optional hook
        """Release what the estimator holds (worker processes)."""
