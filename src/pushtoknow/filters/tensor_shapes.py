"""Shape checks for public tensor boundaries: errors name the expected and received shapes."""

from __future__ import annotations

from collections.abc import Sequence

import torch

from pushtoknow.common.errors import ShapeError

Dim = tuple[str, "int | None"]


def _fmt(expected: Sequence[Dim]) -> str:
    parts = [label if size is None else f"{label}={size}" for label, size in expected]
    return "(" + ", ".join(parts) + ")"


def expect_shape(tensor: object, name: str, expected: Sequence[Dim]) -> torch.Tensor:
    """Raise `ShapeError` unless `tensor` is a tensor of the expected shape.

    expected: sequence of (label, size) pairs; size None accepts any size for that axis.
    Example: ``expect_shape(mean, "mean", [("B", B), ("D", 8)])``. Returns the tensor.
    """
    if not isinstance(tensor, torch.Tensor):
        raise ShapeError(f"{name}: expected a tensor of shape {_fmt(expected)}, got {type(tensor)}")
    shape = tuple(tensor.shape)
    ok = len(shape) == len(expected) and all(
        size is None or size == got for (_, size), got in zip(expected, shape)
    )
    if not ok:
        raise ShapeError(f"{name}: expected shape {_fmt(expected)}, got {shape}")
    return tensor


def expect_floating(tensor: torch.Tensor, name: str, like: torch.Tensor | None = None) -> None:
    """Raise `ShapeError` unless `tensor` is floating point (and of `like`'s dtype and device)."""
    if not tensor.is_floating_point():
        raise ShapeError(f"{name}: expected a floating-point tensor, got dtype {tensor.dtype}")
    if like is not None and (tensor.dtype != like.dtype or tensor.device != like.device):
        raise ShapeError(
            f"{name}: expected dtype {like.dtype} on {like.device}, "
            f"got {tensor.dtype} on {tensor.device}"
        )
