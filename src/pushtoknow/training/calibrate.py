"""Calibration of the evidence each push keeps, on whole push sequences of validation objects.

The filter runs each validation object's recorded pushes in order, its parameter belief
carried from push to push as at inference (`models.calibration.keep_evidence` after each push;
every push starts at its recorded pose). For each candidate weight the negative log-likelihood
of the true parameters is measured in each direction of `models.calibration.DIRECTIONS` after
every push; each direction takes the weight with the lowest mean NLL over all pushes. With
`dynamic_noise_scales`, the R scale on the samples of a push's dynamic phase
(`InferenceSettings.dynamic_noise_scale`) is chosen with them: the candidate whose best weights
give the lowest NLL summed over the directions. With `profile_rounds`, each speed profile's
weights are then chosen in turn with the others' held (coordinate descent, as many rounds): a
release push's model errors are not a constant push's, and a policy that mostly chooses one
profile must not inherit weights set for the mix. With `correlations`, the correlation r of
the model errors of two pushes of one profile (`models.calibration.evidence_discount`) is
chosen per direction with the weights, between the common choice and the profile rounds: each
candidate r is scanned over the weights, and a direction keeps the (w, r) of lowest NLL. As in
every scan here, all directions share a run's setting and each direction is judged on its own
NLL (the basis separates them; the combination chosen is not scored as a whole). With
`max_weights`, a direction takes no weight above its cap (the first push's weight). With
`tolerance_se`, a weight whose NLL lies within that many standard errors of the lowest (the
standard error over the objects of its paired difference to the lowest) ties with it, and the
smallest tied weight is chosen (the one-standard-error rule): a direction keeps evidence only
where the validation objects show that it pays, so a parameter the pushes barely reveal keeps
its prior's width. The choice is made on validation objects only (never on the evaluation's
held-out ones). A trial under which the filter's belief stops being a covariance on a
validation sequence (`filters.gaussian.CovarianceError`) scores an infinite NLL, so its weight is
never chosen, and a candidate R scale with such a trial is dropped whole (the weights chosen are
never run together); its row of the log says why.
"""

from __future__ import annotations

import math

import torch
from pydantic import Field, field_validator, model_validator

from pushtoknow.common.frozen_config import Config
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.filters.gaussian import CovarianceError
from pushtoknow.filters.tensor_shapes import expect_shape
from pushtoknow.models.calibration import (
    DIRECTIONS,
    check_correlations,
    evidence_basis,
    evidence_discount,
    keep_evidence,
)
from pushtoknow.models.checkpoint import InferenceSettings, TrainedModel
from pushtoknow.testbed.push import PROFILES
from pushtoknow.training.end_to_end import run_window
from pushtoknow.training.push_tensors import PushTensors


class SequenceCalibrationConfig(Config):
    weights: tuple[float, ...] = (0.0, 0.1, 0.25, 0.5, 1.0)
    dynamic_noise_scales: tuple[float, ...] = Field(
        (), description="candidate R scales for dynamic samples; empty: R's calibrated scale"
    )
    max_objects: int = Field(40, ge=2, description="validation objects used")
    profile_rounds: int = Field(
        0,
        ge=0,
        description="rounds of per-profile weight choice after the common one (0: one set of "
        "weights for every speed profile)",
    )
    correlations: tuple[float, ...] = Field(
        (0.0,),
        description="candidate correlations r ∈ [0, 1) of the model errors of two pushes of "
        "one profile, beside 0 (independent pushes), which is always one",
    )
    tolerance_se: float = Field(
        0.0,
        ge=0.0,
        description="standard errors of the NLL within which a smaller weight ties with the "
        "lowest NLL's and is chosen (0: the lowest NLL's weight)",
    )
    num_sigma_points: int = Field(32, ge=MIN_SIGMA_POINTS)
    init_pose_std: tuple[float, float, float] = (1e-3, 1e-3, 0.01)
    max_weights: dict[str, float] = Field(
        {},
        description="highest weight a direction may take (keys: "
        + ", ".join(DIRECTIONS)
        + "); the validation objects are of the training shapes, on which the models fit "
        "better than on unseen ones",
    )

    @field_validator("max_weights")
    @classmethod
    def _known_directions(cls, v: dict[str, float]) -> dict[str, float]:
        for name, cap in v.items():
            if name not in DIRECTIONS:
                raise ValueError(f"unknown direction {name!r}; expected one of {DIRECTIONS}")
            if not 0.0 <= cap <= 1.0:
                raise ValueError(f"max_weights.{name} = {cap}: a weight lies in [0, 1]")
        return v

    @field_validator("correlations")
    @classmethod
    def _correlations(cls, v: tuple[float, ...]) -> tuple[float, ...]:
        if not v:
            raise ValueError("correlations: give one or more candidates in [0, 1)")
        check_correlations(v)
        return v

    @model_validator(mode="after")
    def _some_weight_allowed(self) -> SequenceCalibrationConfig:
        for name, cap in self.max_weights.items():
            if cap < min(self.weights) - 1e-12:
                raise ValueError(f"max_weights.{name} = {cap} is below every candidate weight")
        return self

    def allowed(self) -> torch.Tensor:
        """(W, K) bool: which of `weights` each direction may take."""
        caps = torch.tensor([self.max_weights.get(d, 1.0) for d in DIRECTIONS])
        return torch.tensor(self.weights)[:, None] <= caps[None, :] + 1e-12


def push_sequences(pt: PushTensors, max_objects: int) -> torch.Tensor:
    """(N objects, P pushes) row indices of `pt`: each object's pushes in recorded order, the
    same number P (the smallest any object has) for all."""
    rows: dict[int, list[tuple[int, int]]] = {}
    for i, (o, k) in enumerate(zip(pt.object_index.tolist(), pt.push_index.tolist())):
        rows.setdefault(o, []).append((k, i))
    seqs = [[i for _, i in sorted(v)] for _, v in sorted(rows.items())][:max_objects]
    p = min(len(s) for s in seqs)
    return torch.tensor([s[:p] for s in seqs])


@torch.no_grad()
def run_sequences(
    model: TrainedModel,
    pt: PushTensors,
    seqs: torch.Tensor,
    weights: torch.Tensor,
    settings: InferenceSettings,
    cfg: SequenceCalibrationConfig,
    seed: int,
    correlation: torch.Tensor | None = None,
) -> list[tuple[torch.Tensor, torch.Tensor]]:
    """Parameter beliefs (mean (N, K), cov (N, K, K)) after each push of each sequence.

    weights: (P, K) evidence weights per speed profile (`PROFILES` order); correlation (K,):
    r per direction (None: 0), the n-th push of a profile keeping weight × g_r(n)."""
    gen = torch.Generator().manual_seed(seed)
    filt = model.build_filter(
        cfg.num_sigma_points, settings.noise_scale, settings.dynamic_noise_scale
    )
    n, p = seqs.shape
    k = model.prior.mean.shape[0]
    mean_par = model.prior.mean.expand(n, k).clone()
    cov_par = model.prior.cov.expand(n, k, k).clone()
    pose_std = torch.tensor(cfg.init_pose_std)
    corr = torch.zeros(k, dtype=weights.dtype) if correlation is None else correlation
    counts = torch.zeros(n, len(PROFILES), dtype=torch.long)
    rows = torch.arange(n)
    out = []
    for j in range(p):
        push = seqs[:, j]
        pose0 = pt.pose[push, 0] + torch.randn(n, 3, generator=gen) * pose_std
        mean0 = torch.cat([pose0, mean_par], -1)
        cov0 = torch.zeros(n, 3 + k, 3 + k)
        cov0[:, :3, :3] = torch.diag(pose_std.square())
        cov0[:, 3:, 3:] = cov_par
        for _, mean, cov in run_window(  # noqa: B007 (the last belief is used below)
            filt, pt, push, 0, pt.horizon_steps - 1, mean0, cov0, gen, cfg.num_sigma_points,
            model.vision_only, settings.update_every,
        ):  # fmt: skip
            pass
        profile = pt.action[push, 4].long()
        counts[rows, profile] += 1
        kept = weights[profile] * evidence_discount(counts[rows, profile], corr.to(weights))
        mean_par, cov_par = keep_evidence(mean_par, cov_par, mean[:, 3:], cov[:, 3:, 3:], kept)
        out.append((mean_par, cov_par))
    return out


def direction_nll(mean: torch.Tensor, cov: torch.Tensor, truth: torch.Tensor) -> torch.Tensor:
    """(N, K) Gaussian NLL of the truth's coordinates in the evidence basis, per direction."""
    r = evidence_basis().to(mean)
    err = (truth - mean) @ r.T
    var = torch.diagonal(r @ cov @ r.T, dim1=-2, dim2=-1).clamp_min(1e-12)
    return 0.5 * (err.square() / var + var.log() + math.log(2 * math.pi))


def choose_weights(
    nll: torch.Tensor, weights: torch.Tensor, allowed: torch.Tensor, tolerance_se: float
) -> tuple[torch.Tensor, torch.Tensor]:
    """(mean NLL (K,), index (K,)) of the weight each direction takes.

    nll: (W, N, K) per candidate weight, object and direction; weights: (W,); allowed: (W, K).
    The lowest mean NLL among the allowed weights wins, unless a smaller allowed weight lies
    within `tolerance_se` standard errors of it (of the paired per-object difference): then
    the smallest such weight. Non-finite means never win."""
    w = weights.shape[0]
    expect_shape(nll, "nll", [("W", w), ("N", None), ("K", None)])
    expect_shape(allowed, "allowed", [("W", w), ("K", nll.shape[2])])
    mean = nll.mean(1)
    mean = mean.masked_fill(~allowed | ~torch.isfinite(mean), math.inf)
    lowest, best = mean.min(0)
    diff = nll - nll.gather(0, best[None, None, :].expand(1, *nll.shape[1:]))
    n = nll.shape[1]
    se = diff.std(1).nan_to_num(0.0) / math.sqrt(n) if n > 1 else torch.zeros_like(mean)
    tied = torch.isfinite(mean) & (mean <= lowest + tolerance_se * se)
    order = weights[:, None].expand_as(mean).masked_fill(~tied, math.inf)
    index = torch.where(torch.isfinite(lowest), order.argmin(0), best)
    return mean.gather(0, index[None]).squeeze(0), index


def calibrate_evidence(
    model: TrainedModel,
    val: PushTensors,
    cfg: SequenceCalibrationConfig,
    seed: int,
    log=None,
    progress=None,
) -> InferenceSettings:
    """`model.inference` with `evidence_weights` chosen per direction (see module doc)."""
    seqs = push_sequences(val, cfg.max_objects)
    truth = val.params_norm[seqs[:, 0]].float()
    candidates = [model.inference] + [
        model.inference.model_copy(update={"dynamic_noise_scale": float(d)})
        for d in cfg.dynamic_noise_scales
    ]
    present = sorted(set(val.action[seqs.flatten(), 4].long().tolist()))
    correlations = sorted({float(r) for r in cfg.correlations if r != 0.0})
    runs = len(candidates) + len(correlations) + cfg.profile_rounds * len(present)
    task = (
        progress.add_task("sequence calibration", total=len(cfg.weights) * runs)
        if progress
        else None
    )

    def scan(
        settings: InferenceSettings,
        table: torch.Tensor,
        rows: list[int],
        label: str,
        corr: torch.Tensor,
    ):
        """(lowest NLL (K,), the weight index reaching it (K,)) over `cfg.weights`, each put in
        `rows` of `table` (P, K), the other rows held; corr (K,) the correlations."""
        nll = []
        for w in cfg.weights:
            trial = table.clone()
            trial[rows] = float(w)
            failure = ""
            try:
                beliefs = run_sequences(model, val, seqs, trial, settings, cfg, seed, corr)
                per_push = torch.stack([direction_nll(m, c, truth) for m, c in beliefs])
                nll.append(per_push.mean(0))  # (N, K): each object's mean over its pushes
            except CovarianceError as e:  # the filter breaks down under these settings: a
                # setting it cannot run with is never chosen (its NLL is infinite)
                failure = str(e)
                failures.append(settings)
                nll.append(torch.full((seqs.shape[0], len(DIRECTIONS)), math.inf))
            if log:
                log(
                    {
                        "dynamic_noise_scale": settings.dynamic_noise_scale or "",
                        "profile": label,
                        "correlation": " ".join(f"{r:g}" for r in corr.tolist()),
                        "weight": w,
                        "pushes": seqs.shape[1],
                        "objects": seqs.shape[0],
                    }
                    | {
                        f"nll_{d}": float(v)
                        for d, v in zip(DIRECTIONS, nll[-1].mean(0), strict=True)
                    }
                    | ({"failed": failure} if failure else {})
                )
            if progress:
                progress.advance(task)
        return choose_weights(torch.stack(nll), grid, allowed, cfg.tolerance_se)

    allowed = cfg.allowed()
    # float64 tables hold the grid's weights exactly, so the chosen ones are its values
    grid = torch.tensor(cfg.weights, dtype=torch.float64)
    every = list(range(len(PROFILES)))
    blank = torch.zeros(len(PROFILES), len(DIRECTIONS), dtype=grid.dtype)
    independent = torch.zeros(len(DIRECTIONS), dtype=grid.dtype)
    best_total, best, best_lowest = math.inf, model.inference, None
    failures: list[InferenceSettings] = []  # the settings of every trial that broke down
    for settings in candidates:
        lowest, index = scan(settings, blank, every, "all", independent)
        if settings in failures:  # a candidate R scale that broke down under one weight may
            continue  # under the weights combined: never chosen
        if float(lowest.sum()) < best_total:
            best_total, best_lowest = float(lowest.sum()), lowest
            best = settings.model_copy(
                update={
                    "evidence_weights": tuple(grid[index].tolist()),
                    "evidence_correlation": tuple(independent.tolist()),
                }
            )
    if best_lowest is None:
        raise ValueError("no setting of the sequence calibration gave a finite NLL")
    if correlations:
        weights = torch.tensor(best.evidence_weights, dtype=grid.dtype)
        corr = independent.clone()
        for r in correlations:
            lowest, index = scan(best, blank, every, "all", torch.full_like(corr, r))
            better = lowest < best_lowest
            best_lowest = torch.where(better, lowest, best_lowest)
            weights = torch.where(better, grid[index], weights)
            corr = torch.where(better, torch.full_like(corr, r), corr)
        best = best.model_copy(
            update={
                "evidence_weights": tuple(weights.tolist()),
                "evidence_correlation": tuple(corr.tolist()),
            }
        )
    if cfg.profile_rounds:
        table = best.evidence_weight_table(grid.dtype)
        corr = torch.tensor(best.evidence_correlation, dtype=grid.dtype)
        for _ in range(cfg.profile_rounds):
            for p in present:
                table[p] = grid[scan(best, table, [p], PROFILES[p], corr)[1]]
        best = best.model_copy(
            update={
                "profile_evidence_weights": {PROFILES[p]: tuple(table[p].tolist()) for p in present}
            }
        )
    return best
