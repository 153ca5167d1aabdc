"""Plots people look at: frame strips of a push with its tactile trace."""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt
import numpy as np

STRIP_FRAMES = 8


def one_push(spec, profile: str = "constant", seed: int = 0):
    """Place the object at the workspace centre, push it once from a seeded affordance."""
    from pushtoknow.common.random import stream, stream_seed
    from pushtoknow.geometry.affordances import sample_push_affordances
    from pushtoknow.testbed.executor import SimulatedExecutor
    from pushtoknow.testbed.push import Push

    ex = SimulatedExecutor(spec, seed=stream_seed(seed, "simulator"), randomise_pose=False)
    rng = stream(seed, "policy")
    view = ex.observe()
    cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
    cfg = ex.sim.config.push
    speed = cfg.profile_speed(profile)
    rec = ex.execute(Push(tuple(cp[0]), float(pd[0]), profile, speed))
    camera = ex.camera
    ex.close()
    return rec, camera


def save_push_strip(rec, camera, path: Path, title: str = "", fmt: str | None = None) -> None:
    """A row of RGB frames (pad and true pose marked), the depth of the last frame, S_0, and the
    tactile force over time. fmt: the image format (None: from the suffix of `path`)."""
    T = len(rec.time)
    idx = np.linspace(0, T - 1, STRIP_FRAMES).round().astype(int)
    fig = plt.figure(figsize=(2 * STRIP_FRAMES, 5.2))
    gs = fig.add_gridspec(2, STRIP_FRAMES, height_ratios=[1, 0.9])
    for j, k in enumerate(idx):
        ax = fig.add_subplot(gs[0, j])
        ax.imshow(rec.rgb[k], interpolation="nearest")
        u, v = camera.world_to_pixel(rec.pose[k, :2])
        pu, pv = camera.world_to_pixel(rec.pusher[k])
        ax.plot(u, v, "w+", ms=6)
        ax.plot(pu, pv, "c.", ms=4)
        ax.set_title(f"t={rec.time[k]:.1f}s", fontsize=8)
        ax.axis("off")
    ax = fig.add_subplot(gs[1, : STRIP_FRAMES // 2])
    ax.plot(rec.time, rec.tactile[:, 0], label="F_x (noisy)", lw=0.8)
    ax.plot(rec.time, rec.tactile[:, 1], label="F_y (noisy)", lw=0.8)
    if rec.force_clean is not None:  # a simulated push's noiseless force
        ax.plot(rec.time, np.linalg.norm(rec.force_clean, axis=1), "k", label="‖F‖ clean", lw=1.2)
    ax.set_xlabel("time (s)")
    ax.set_ylabel("force on object (N)")
    ax.legend(fontsize=7)
    ax = fig.add_subplot(gs[1, STRIP_FRAMES // 2 : STRIP_FRAMES // 2 + 2])
    ax.imshow(rec.depth[-1], cmap="viridis")
    ax.set_title("depth, last frame (m)", fontsize=8)
    ax.axis("off")
    ax = fig.add_subplot(gs[1, STRIP_FRAMES // 2 + 2 :])
    ax.imshow(rec.s0, cmap="gray")
    ax.set_title("S_0", fontsize=8)
    ax.axis("off")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=80, format=fmt)
    plt.close(fig)


def plot_estimates(result, path: Path, title: str = "") -> None:
    """The paper's Fig. 5 for one inference run (`InferenceResult`): each parameter's mean with
    ±1σ and ±2σ bands versus push number (0 = the prior), the truth as a dashed line when known.
    Drawn by `reporting.figures.plot_estimates_vs_push`."""
    from pushtoknow.common.params import PARAM_NAMES
    from pushtoknow.reporting.figures import plot_estimates_vs_push

    rows = [result.prior, *result.estimates]
    plot_estimates_vs_push(
        np.stack([e.mean for e in rows]),
        np.stack([e.std for e in rows]),
        result.truth,
        path,
        names=PARAM_NAMES,
        title=title,
    )
