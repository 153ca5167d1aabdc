"""Where a trained model's parts place an object on the m-against-μ ridge.

At fixed μ·m, a push can separate m from μ only through its dynamic content (docs/DESIGN.md
§10). This scores the model's one-step misfit on recorded pushes, every parameter true except
(m·e^δ, μ·e^−δ), and splits it by the part of the model that produces it: the motion of the step
that starts at a release (the free slide), the other steps of a dynamic phase, the steady steps,
and the force in and out of dynamic phases. A part whose misfit is smallest far from δ = 0 pulls
the filter's m and μ apart from the truth push after push, whatever the calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import torch

from pushtoknow.common.params import normalise_params
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.models.physics import PhysicsDynamics
from pushtoknow.training.data import PushTensors
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

    def best_delta(self, part: str, pushes: np.ndarray | None = None) -> float | None:
        """δ minimising the part's misfit summed over `pushes` (bool (N,), default all); None
        where it barely depends on δ (a rise below FLAT_NATS)."""
        rows = self.misfit[part] if pushes is None else self.misfit[part][pushes]
        total = rows.sum(0)
        if total.max() - total.min() < FLAT_NATS:
            return None
        return round(float(self.deltas[int(np.argmin(total))]), 9)

    def rise(self, part: str, pushes: np.ndarray | None = None) -> float:
        """How much the part's summed misfit rises over the scanned δ (nats): its say on m vs μ."""
        rows = self.misfit[part] if pushes is None else self.misfit[part][pushes]
        total = rows.sum(0)
        return float(total.max() - total.min())


def _one_step_misfits(model: TrainedModel, pt: PushTensors, params_norm: torch.Tensor) -> dict:
    """Per push (N,) summed misfits of each part at the given normalised parameters (N, 5)."""
    n, t_len = pt.pose.shape[:2]
    push = torch.arange(n)
    out = {p: np.zeros(n) for p in RIDGE_PARTS}
    dyn = model.models.dynamics
    for t in range(t_len - 1):
        ctx = push_context(pt, push, torch.full((n,), t + 1))
        state = torch.cat([pt.pose[:, t], params_norm], -1).unsqueeze(1)
        delta, q = dyn(state, ctx)
        target = (pt.pose[:, t + 1] - pt.pose[:, t]).unsqueeze(1)
        motion = (0.5 * (delta - target).square() / q).sum(-1)[:, 0].numpy()
        accelerating = ctx.pad_accelerating().numpy().astype(bool)
        slide = np.zeros(n, bool)
        if isinstance(dyn, PhysicsDynamics) and dyn.free_slide:
            slide = PhysicsDynamics.release_step(ctx).numpy()
        out["slide"] += np.where(slide, motion, 0.0)
        out["dynamic_motion"] += np.where(~slide & accelerating, motion, 0.0)
        out["steady_motion"] += np.where(~slide & ~accelerating, motion, 0.0)
        after = torch.cat([pt.pose[:, t + 1], params_norm], -1).unsqueeze(1)
        predicted = model.models.observation(after, ctx)[:, 0]
        if predicted.shape[-1] > 3:  # a tactile model
            z = observation(pt, push, torch.full((n,), t + 1))
            r = model.models.observation_noise(z, ctx)
            force = (0.5 * (predicted[:, 3:5] - z[:, 3:5]).square() / r[:, 3:5]).sum(-1).numpy()
            out["dynamic_force"] += np.where(accelerating, force, 0.0)
            out["steady_force"] += np.where(~accelerating, force, 0.0)
    return out


def ridge_misfit(
    model: TrainedModel, pt: PushTensors, deltas: np.ndarray | None = None
) -> RidgeMisfit:
    """Each part's misfit at (m·e^δ, μ·e^−δ) and the other parameters true, for every δ of
    `deltas` (default −0.4 … 0.4 in steps of 0.05), on the pushes of `pt`."""
    deltas = np.linspace(-0.4, 0.4, 17) if deltas is None else np.asarray(deltas, float)
    curves = {p: np.zeros((len(pt), len(deltas))) for p in RIDGE_PARTS}
    with torch.no_grad():
        for j, d in enumerate(deltas):
            params = pt.params.clone().double()
            params[:, 0] *= math.exp(d)
            params[:, 1] *= math.exp(-d)
            norm = torch.as_tensor(normalise_params(params.numpy()), dtype=pt.pose.dtype)
            for part, values in _one_step_misfits(model, pt, norm).items():
                curves[part][:, j] = values
    release = np.isfinite(pt.release[:, 0].numpy())
    return RidgeMisfit(deltas, curves, release)
