"""Push policies: pick one of M candidate pushes given the current belief (docs/DESIGN.md §7).

The policy sees only tensors and a caller-supplied `context_builder(pushes, step)` that turns
candidate pushes into the filter context of look-ahead step `step`, batched over the pushes
(for the learned models a `PushContext` with the pad where `testbed.push.pad_positions` puts
it). Uniform and random selection live with the inference layer.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import TYPE_CHECKING, Literal, Protocol, runtime_checkable

import torch
from pydantic import Field

from pushtoknow.active.selection import ScoreName, score_candidates
from pushtoknow.common.frozen_config import Config
from pushtoknow.filters.base import BeliefFilter

if TYPE_CHECKING:
    from pushtoknow.testbed.push import Push

ContextBuilder = Callable[[Sequence["Push"], int], object]
"""(pushes, step) ↦ the filter context of look-ahead step `step` for `pushes`, batched over
len(pushes) (step k is the transition from sample k to k + 1)."""

ACTIVE_POLICY_NAMES: dict[ScoreName, str] = {"kl": "active-kl", "entropy": "active-entropy"}


class ActiveConfig(Config):
    """Active push selection. num_candidates: M pushes sampled per decision (by the caller);
    horizon_fraction: look-ahead N as a fraction of the push's filter steps (paper: 50% of
    t_H); score: "kl" (paper eq. 17) or "entropy" (expected parameter-entropy reduction,
    see `pushtoknow.active.selection`); num_sigma_points: C of the look-ahead predictions
    (None: the filter's)."""

    num_candidates: int = Field(16, ge=1)
    horizon_fraction: float = Field(0.5, gt=0.0, le=1.0)
    score: Literal["kl", "entropy"] = "kl"
    num_sigma_points: int | None = Field(None, ge=2)

    @property
    def policy_name(self) -> str:
        return ACTIVE_POLICY_NAMES[self.score]

    def n_steps(self, horizon_steps: int) -> int:
        """N = round(horizon_fraction · horizon_steps), at least 1."""
        return look_ahead_steps(self.horizon_fraction, horizon_steps)


def look_ahead_steps(horizon_fraction: float, horizon_steps: int) -> int:
    """N = round(fraction · steps) (halves up), at least 1: 0.5 · 100 → 50."""
    if horizon_steps < 1:
        raise ValueError(f"horizon_steps must be ≥ 1, got {horizon_steps}")
    return max(1, math.floor(horizon_fraction * horizon_steps + 0.5))


@runtime_checkable
class CandidateSelector(Protocol):
    """Chooses the next push among candidates, given the belief (an active policy's part)."""

    name: str

    def choose(
        self,
        candidates: Sequence[Push],
        belief_mean: torch.Tensor,
        belief_cov: torch.Tensor,
        context_builder: ContextBuilder,
        generator: torch.Generator,
    ) -> int:
        """Index of the chosen candidate. belief_mean (1, D), belief_cov (1, D, D)."""
        ...


class ActivePolicy:
    """Active push selection: the candidate with the highest N-step score
    (`score_candidates`); ties go to the first. `last_scores` (M,) keeps the scores of the
    latest decision for logging.

    horizon_steps: filter steps of one push (T - 1 = t_H · rate, 60 for a 6 s push at
    10 Hz); N = round(horizon_fraction · horizon_steps).
    """

    def __init__(
        self,
        filt: BeliefFilter,
        horizon_steps: int,
        score: ScoreName = "kl",
        horizon_fraction: float = 0.5,
        num_sigma_points: int | None = None,
    ):
        self.config = ActiveConfig(
            horizon_fraction=horizon_fraction, score=score, num_sigma_points=num_sigma_points
        )
        self.filter = filt
        self.horizon_steps = horizon_steps
        self.n_steps = self.config.n_steps(horizon_steps)
        self.name = self.config.policy_name
        self.last_scores: torch.Tensor | None = None

    @classmethod
    def from_config(
        cls, filt: BeliefFilter, config: ActiveConfig, horizon_steps: int
    ) -> ActivePolicy:
        return cls(
            filt, horizon_steps, config.score, config.horizon_fraction, config.num_sigma_points
        )

    def scores(
        self,
        candidates: Sequence[Push],
        belief_mean: torch.Tensor,
        belief_cov: torch.Tensor,
        context_builder: ContextBuilder,
        generator: torch.Generator,
    ) -> torch.Tensor:
        """Scores (M,) of the candidates, one batch."""
        if len(candidates) == 0:
            raise ValueError("no candidate pushes to choose from")
        pushes = list(candidates)
        return score_candidates(
            self.filter,
            belief_mean,
            belief_cov,
            lambda k: context_builder(pushes, k),
            len(pushes),
            self.n_steps,
            self.config.score,
            generator,
            self.config.num_sigma_points,
        )

    def choose(
        self,
        candidates: Sequence[Push],
        belief_mean: torch.Tensor,
        belief_cov: torch.Tensor,
        context_builder: ContextBuilder,
        generator: torch.Generator,
    ) -> int:
        """Index of the candidate with the highest score."""
        scores = self.scores(candidates, belief_mean, belief_cov, context_builder, generator)
        self.last_scores = scores
        return int(torch.argmax(scores))
