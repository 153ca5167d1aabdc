"""Angle helpers. θ is kept unwrapped inside a trajectory; residuals are wrapped to (-π, π]."""

from __future__ import annotations

import math

import numpy as np


def wrap_angle(a):
    """Wrap angles to (-π, π]. numpy arrays, floats or torch tensors."""
    if isinstance(a, (float, int)):
        w = math.remainder(a, 2 * math.pi)
        return math.pi if w == -math.pi else w
    if isinstance(a, np.ndarray):
        w = np.mod(a + np.pi, 2 * np.pi) - np.pi
        return np.where(w <= -np.pi, w + 2 * np.pi, w)
    # torch
    import torch

    w = torch.remainder(a + math.pi, 2 * math.pi) - math.pi
    return torch.where(w <= -math.pi, w + 2 * math.pi, w)
