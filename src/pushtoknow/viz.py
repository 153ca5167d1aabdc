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
    from pushtoknow.geometry.affordances import sample_push_affordances
    from pushtoknow.testbed.executor import SimulatedExecutor
    from pushtoknow.testbed.push import Push

    ex = SimulatedExecutor(spec, seed=seed, randomise_pose=False)
    rng = np.random.default_rng(seed)
    view = ex.observe()
    cp, pd = sample_push_affordances(view.s0, ex.camera, 1, rng)
    cfg = ex.sim.config.push
    speed = cfg.speed if profile == "constant" else cfg.release_peak_speed
    rec = ex.execute(Push(tuple(cp[0]), float(pd[0]), profile, speed))
    camera = ex.camera
    ex.close()
    return rec, camera


def save_push_strip(rec, camera, path: Path, title: str = "") -> None:
    """A row of RGB frames (pad and true pose marked), the depth of the last frame, S_0, and the
    tactile force over time."""
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
    fig.savefig(path, dpi=80)
    plt.close(fig)


def plot_estimates(result, path: Path, title: str = "") -> None:
    """The paper's Fig. 5: each parameter's mean ± 2 std (≈95%) versus push number (0 = the
    prior), the truth as a dashed line when known."""
    from pushtoknow.common.params import PARAM_NAMES, PARAM_RANGES

    labels = {
        "mass": "mass (kg)",
        "friction": "friction μ",
        "com_x": "c_x (m)",
        "com_y": "c_y (m)",
        "inertia": "I_z (kg·m²)",
    }
    rows = [result.prior, *result.estimates]
    k = np.array([e.index for e in rows])
    mean = np.stack([e.mean for e in rows])
    std = np.stack([e.std for e in rows])
    fig, axes = plt.subplots(1, len(PARAM_NAMES), figsize=(3.2 * len(PARAM_NAMES), 3))
    for j, (ax, name) in enumerate(zip(axes, PARAM_NAMES, strict=True)):
        ax.fill_between(k, mean[:, j] - 2 * std[:, j], mean[:, j] + 2 * std[:, j], alpha=0.25)
        ax.plot(k, mean[:, j], "o-", ms=3, label="estimate ± 2σ")
        if result.truth is not None:
            ax.axhline(result.truth[j], color="k", ls="--", lw=1, label="truth")
        lo, hi = PARAM_RANGES[name]
        pad = 0.1 * (hi - lo)
        ax.set_ylim(lo - pad, hi + pad)
        ax.set_xlabel("push")
        ax.set_title(labels[name], fontsize=9)
        ax.set_xticks(k)
    axes[0].legend(fontsize=7)
    if title:
        fig.suptitle(title, fontsize=10)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
