"""Push policies of an inference run (docs/DESIGN.md §7, §9): objects behind one interface,
made by one factory from their names.

Before push k (0-based) of K, the run samples candidate pushes among the affordances of S_0
(`candidate_pushes`) and the policy picks one:

- ``uniform``: contact points spread evenly around the object: the candidate whose bearing from
  the centroid, in the object frame, is nearest to 2πk/K (a seeded offset), with profile
  profiles[k mod P];
- ``random``: one random candidate (with one profile: the first, whose affordance is random);
- ``active-kl`` / ``active-entropy``: the candidate with the highest N-step information score of
  the estimator's own filter (`active.policies.ActivePolicy`), over the candidates' commanded pad
  paths; it chooses contact, direction and profile.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, ClassVar

import numpy as np
import torch

from pushtoknow.active.policies import ACTIVE_POLICY_NAMES, ActivePolicy, ScoreName
from pushtoknow.common.camera import CameraModel
from pushtoknow.common.policies import POLICY_NAMES
from pushtoknow.geometry.affordances import mask_contour, sample_push_affordances
from pushtoknow.models.learned import PushContext, with_pad_track
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.push import Push, pad_positions

if TYPE_CHECKING:
    from pushtoknow.inference.session import ObjectEstimator


@dataclass(frozen=True)
class PushDecision:
    """What a policy sees before push k (0-based) of `pushes`: the candidates (their contact
    points (C, 2), world m, in `contacts`), the object's view and start pose (x, y, θ), the
    run's numpy generator, the profiles it may use at their speeds (m/s), and the estimator
    (its filter and belief, for active policies)."""

    k: int
    pushes: int
    candidates: list[Push]
    contacts: np.ndarray
    view: View
    camera: CameraModel
    pose0: np.ndarray
    rng: np.random.Generator
    profiles: tuple[str, ...]
    speeds: dict[str, float]
    estimator: ObjectEstimator


class PushPolicy(ABC):
    """Chooses each push of an inference run."""

    name: str

    @abstractmethod
    def choose(self, decision: PushDecision) -> Push:
        """The push to execute (one of the candidates, possibly with another profile)."""


class UniformPolicy(PushPolicy):
    name = "uniform"

    def choose(self, decision: PushDecision) -> Push:
        d = decision
        centre = mask_contour(d.view.s0, d.camera).centroid
        cp = d.contacts
        bearing = np.arctan2(cp[:, 1] - centre[1], cp[:, 0] - centre[0]) - d.pose0[2]
        target = 2 * math.pi * d.k / d.pushes + d.rng.uniform(0, 2 * math.pi / d.pushes)
        diff = np.abs(np.angle(np.exp(1j * (bearing - target))))
        profile = d.profiles[d.k % len(d.profiles)]
        chosen = d.candidates[int(np.argmin(diff))]
        return dataclasses.replace(chosen, profile=profile, speed=d.speeds[profile])


class RandomPolicy(PushPolicy):
    name = "random"

    def choose(self, decision: PushDecision) -> Push:
        d = decision
        if len(d.profiles) == 1:
            return d.candidates[0]
        return d.candidates[int(d.rng.integers(len(d.candidates)))]


class InformationPolicy(PushPolicy):
    """Active selection (docs/DESIGN.md §7): rollouts of the estimator's filter over the
    candidates' commanded pad paths (`testbed.push.pad_positions`), all candidates in one
    batch, scored by `score` ("kl" or "entropy") over N = horizon_fraction of a push's steps.
    `sim_config`: the testbed settings the pushes are executed with (horizon, rate)."""

    SCORES: ClassVar[dict[str, ScoreName]] = {n: s for s, n in ACTIVE_POLICY_NAMES.items()}

    def __init__(self, name: str, sim_config: SimConfig, horizon_fraction: float = 0.5):
        self.name = name  # one class, two named policies
        self.score = self.SCORES[name]
        self.sim_config = sim_config
        self.horizon_fraction = horizon_fraction

    def choose(self, decision: PushDecision) -> Push:
        d, est = decision, decision.estimator
        push_config = self.sim_config.push
        dt = 1.0 / self.sim_config.tactile.rate_hz
        steps = int(round(push_config.horizon * self.sim_config.tactile.rate_hz))
        selector = ActivePolicy(
            est.filter, steps, self.score, self.horizon_fraction, est.num_sigma_points
        )
        mean, cov = est.start_belief(d.pose0)
        times = np.arange(steps + 1) * dt
        paths = torch.as_tensor(
            np.stack([pad_positions(p, times, push_config) for p in d.candidates]),
            dtype=torch.float32,
        )  # (M, T, 2)
        base = est.context(d.view, d.pose0, paths[:, 0], d.candidates)

        def builder(_: Any, step: int) -> PushContext:
            return with_pad_track(base, paths, step + 1, dt)

        return d.candidates[int(selector.choose(d.candidates, mean, cov, builder, est.gen))]


def make_policy(
    name: str, sim_config: SimConfig | None = None, horizon_fraction: float = 0.5
) -> PushPolicy:
    """The policy called `name` (one of `POLICY_NAMES`); active ones need the testbed settings
    the pushes run with."""
    if name == UniformPolicy.name:
        return UniformPolicy()
    if name == RandomPolicy.name:
        return RandomPolicy()
    if name in InformationPolicy.SCORES:
        if sim_config is None:
            raise ValueError(f"policy {name!r} needs the testbed settings (sim_config)")
        return InformationPolicy(name, sim_config, horizon_fraction)
    raise ValueError(f"policy must be one of {', '.join(POLICY_NAMES)}, got {name!r}")


def candidate_pushes(
    view: View,
    camera: CameraModel,
    candidates: int,
    rng: np.random.Generator,
    speeds: dict[str, float],
    profiles: tuple[str, ...],
) -> tuple[list[Push], np.ndarray]:
    """`candidates` affordances of S_0 as pushes (candidate i has profile profiles[i mod P] at
    speeds[profile]) and their contact points (C, 2)."""
    cp, pd = sample_push_affordances(view.s0, camera, candidates, rng)
    names = [profiles[i % len(profiles)] for i in range(len(pd))]
    cands = [Push(tuple(cp[i]), float(pd[i]), names[i], speeds[names[i]]) for i in range(len(pd))]
    return cands, cp
