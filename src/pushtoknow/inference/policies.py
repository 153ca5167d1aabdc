"""Push policies of an inference run (docs/DESIGN.md §7, §9): objects behind one interface,
made by one factory from their names.

Before push k (0-based) of K, the run samples candidate pushes among the affordances of S_0
(`candidate_pushes`) and the policy picks one:

- ``uniform``: contact points spread evenly around the object: the candidate whose bearing from
  the centroid, in the object frame, is nearest to 2πk/K (a seeded offset), with profile
  profiles[k mod P];
- ``random``: one random candidate (with one profile: the first, whose affordance is random);
- ``active-kl`` / ``active-entropy``: the candidate with the highest N-step information score
  under the estimator's own model (`PushDecision.information`, the estimator's scoring hook); it
  chooses contact, direction and profile.

A policy sees the decision only: the candidates, the view, the start pose, the run's generator
and the scoring hook, never the estimator itself.
"""

from __future__ import annotations

import dataclasses
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from pushtoknow.active.information_policy import ACTIVE_POLICY_NAMES, ScoreName
from pushtoknow.common.camera import CameraModel
from pushtoknow.common.policy_names import POLICY_NAMES
from pushtoknow.geometry.affordances import mask_contour, sample_push_affordances
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.push import Push

InformationHook = Callable[[ScoreName, float], np.ndarray]
"""(score, horizon_fraction) ↦ (C,) expected information of each candidate under the current
belief (`inference.estimator.Estimator.information`, bound to the decision's candidates)."""


@dataclass(frozen=True)
class PushDecision:
    """What a policy sees before push k (0-based) of `pushes`: the candidates (their contact
    points (C, 2), world m, in `contacts`), the object's view and start pose (x, y, θ), the
    run's numpy generator, the profiles it may use at their speeds (m/s), and `information`,
    the estimator's scoring hook for active policies."""

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
    information: InformationHook


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
    """Active selection (docs/DESIGN.md §7): the candidate with the highest expected
    information `score` ("kl" or "entropy") over N = horizon_fraction of a push's steps, as
    the estimator's own model predicts it (`PushDecision.information`); ties go to the first."""

    SCORES: ClassVar[dict[str, ScoreName]] = {n: s for s, n in ACTIVE_POLICY_NAMES.items()}

    def __init__(self, name: str, horizon_fraction: float = 0.5):
        self.name = name  # one class, two named policies
        self.score = self.SCORES[name]
        self.horizon_fraction = horizon_fraction
        self.last_scores: np.ndarray | None = None

    def choose(self, decision: PushDecision) -> Push:
        if not decision.candidates:
            raise ValueError("no candidate pushes to choose from")
        scores = np.asarray(decision.information(self.score, self.horizon_fraction))
        self.last_scores = scores
        return decision.candidates[int(np.argmax(scores))]


def make_policy(name: str, horizon_fraction: float = 0.5) -> PushPolicy:
    """The policy called `name` (one of `POLICY_NAMES`); active ones look ahead over
    `horizon_fraction` of a push."""
    if name == UniformPolicy.name:
        return UniformPolicy()
    if name == RandomPolicy.name:
        return RandomPolicy()
    if name in InformationPolicy.SCORES:
        return InformationPolicy(name, horizon_fraction)
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
