"""Where a trained model's parts place an object on the m-against-μ ridge.

At fixed μ·m, a push can separate m from μ only through its dynamic content (docs/DESIGN.md
§10). This scores the model's one-step misfit on recorded pushes, every parameter true except
(m·e^δ, μ·e^−δ), and splits it by the part of the model that produces it: the motion of the step
that starts at a release (the free slide), the other steps of a dynamic phase, the steady steps,
and the force in and out of dynamic phases. A part whose misfit is smallest far from δ = 0 pulls
the filter's m and μ apart from the truth push after push, whatever the calibration.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import torch

from pushtoknow.common.params import normalise_params
from pushtoknow.common.progress import progress_bar
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.models.physics import PhysicsDynamics
from pushtoknow.training.push_tensors import PushTensors
from pushtoknow.training.supervised import observation, push_context

RIDGE_PARTS: tuple[str, ...] = (
    "slide",
    "dynamic_motion",
    "steady_motion",
    "dynamic_force",
    "steady_force",
)


FLAT_NATS = 0.05  # a part whose summed misfit rises less over the scan has no say on m vs μ


@dataclass(frozen=True)
class RidgeMisfit:
    """deltas (D,): δ in log m (log μ moves by −δ); misfit[part] (N, D): each push's summed
    one-step Gaussian misfit (½ r²/σ², nats) of that part; release (N,) bool: release pushes."""

    deltas: np.ndarray
    misfit: dict[str, np.ndarray]
    release: np.ndarray

    def _total(self, part: str, pushes: np.ndarray | None) -> np.ndarray:
        """(D,) the part's misfit summed over `pushes` (bool (N,), default all)."""
        rows = self.misfit[part] if pushes is None else self.misfit[part][pushes]
        return rows.sum(0)

    def best_delta(self, part: str, pushes: np.ndarray | None = None) -> float | None:
        """δ minimising the part's misfit summed over `pushes` (bool (N,), default all); None
        where it barely depends on δ (a rise below FLAT_NATS)."""
        if self.rise(part, pushes) < FLAT_NATS:
            return None
        return round(float(self.deltas[int(np.argmin(self._total(part, pushes)))]), 9)

    def rise(self, part: str, pushes: np.ndarray | None = None) -> float:
        """How much the part's summed misfit rises over the scanned δ (nats): its say on m vs μ."""
        total = self._total(part, pushes)
        return float(total.max() - total.min())


def _one_step_misfits(
    model: TrainedModel, pt: PushTensors, params_norm: torch.Tensor, progress: bool
) -> dict[str, np.ndarray]:
    """Per push and parameter set (N, D) summed misfits of each part; params_norm (N, D, 5).
    The D parameter sets of a push ride as the models' sigma points, so each step's context,
    encoding and measurement are computed once."""
    n, t_len = pt.pose.shape[:2]
    d = params_norm.shape[1]
    push = torch.arange(n)
    out = {p: np.zeros((n, d)) for p in RIDGE_PARTS}
    dyn = model.models.dynamics
    with progress_bar(progress) as bar:
        for t in bar.track(range(t_len - 1), description="ridge misfit (steps)"):
            ctx = push_context(pt, push, torch.full((n,), t + 1))
            state = torch.cat([pt.pose[:, None, t].expand(n, d, -1), params_norm], -1)
            delta, q = dyn(state, ctx)
            target = (pt.pose[:, t + 1] - pt.pose[:, t]).unsqueeze(1)
            motion = (0.5 * (delta - target).square() / q).sum(-1).numpy()
            accelerating = ctx.pad_accelerating().numpy().astype(bool)[:, None]
            slide = np.zeros((n, 1), bool)
            if isinstance(dyn, PhysicsDynamics) and dyn.free_slide:
                slide = PhysicsDynamics.release_step(ctx).numpy()[:, None]
            out["slide"] += np.where(slide, motion, 0.0)
            out["dynamic_motion"] += np.where(~slide & accelerating, motion, 0.0)
            out["steady_motion"] += np.where(~slide & ~accelerating, motion, 0.0)
            after = torch.cat([pt.pose[:, None, t + 1].expand(n, d, -1), params_norm], -1)
            predicted = model.models.observation(after, ctx)
            if predicted.shape[-1] > 3:  # a tactile model
                z = observation(pt, push, torch.full((n,), t + 1))
                r = model.models.observation_noise(z, ctx)[:, None, 3:5]
                resid = predicted[..., 3:5] - z[:, None, 3:5]
                force = (0.5 * resid.square() / r).sum(-1).numpy()
                out["dynamic_force"] += np.where(accelerating, force, 0.0)
                out["steady_force"] += np.where(~accelerating, force, 0.0)
    return out


def ridge_misfit(
    model: TrainedModel,
    pt: PushTensors,
    deltas: np.ndarray | None = None,
    progress: bool = False,
) -> RidgeMisfit:
    """Each part's misfit at (m·e^δ, μ·e^−δ) and the other parameters true, for every δ of
    `deltas` (default −0.4 … 0.4 in steps of 0.05), on the pushes of `pt`."""
    deltas = np.linspace(-0.4, 0.4, 17) if deltas is None else np.asarray(deltas, float)
    params = pt.params.double()[:, None, :].repeat(1, len(deltas), 1)  # (N, D, 5) SI
    shift = torch.as_tensor(deltas, dtype=params.dtype)
    params[..., 0] *= shift.exp()
    params[..., 1] *= (-shift).exp()
    norm = normalise_params(params).to(pt.pose.dtype)
    with torch.no_grad():
        curves = _one_step_misfits(model, pt, norm, progress)
    release = np.isfinite(pt.release[:, 0].numpy())
    return RidgeMisfit(deltas, curves, release)
