"""Checks of a public function's arguments at its boundary: each returns the value or raises a
one-line error naming the argument, what it expects and what it got."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, TypeVar

import numpy as np

from pushtoknow.common.errors import PushToKnowError

T = TypeVar("T")


class ArgumentTypeError(PushToKnowError, TypeError):
    """An argument of a public function has the wrong type; the message names it."""


class ArgumentValueError(PushToKnowError, ValueError):
    """An argument of a public function has a value it cannot take; the message names it."""


def describe(value: object, limit: int = 60) -> str:
    """'TYPE REPR' of a value, the repr cut to `limit` characters (for messages)."""
    text = repr(value)
    if len(text) > limit:
        text = text[: limit - 1] + "…"
    return f"{type(value).__name__} {text}"


def check_instance(
    value: Any, cls: type[T] | tuple[type, ...], name: str, *, optional: bool = False,
    hint: str = "",
) -> Any:  # fmt: skip
    """`value` if it is an instance of `cls` (or None when `optional`); else ArgumentTypeError
    "NAME: expected CLS, got TYPE REPR (HINT)"."""
    if (value is None and optional) or isinstance(value, cls):
        return value
    classes = cls if isinstance(cls, tuple) else (cls,)
    expected = " or ".join(c.__name__ for c in classes) + (" or None" if optional else "")
    raise ArgumentTypeError(
        f"{name}: expected {expected}, got {describe(value)}" + (f" ({hint})" if hint else "")
    )


def check_seed(seed: Any, name: str = "seed") -> int:
    """A seed as an int: an integer ≥ 0 (numpy seeds are non-negative; bools are refused)."""
    if isinstance(seed, (bool, np.bool_)) or not isinstance(seed, (int, np.integer)):
        raise ArgumentTypeError(f"{name}: expected an integer ≥ 0, got {describe(seed)}")
    if seed < 0:
        raise ArgumentValueError(f"{name}: must be ≥ 0 (numpy seeds are non-negative), got {seed}")
    return int(seed)


def check_callable(value: Any, name: str, *, optional: bool = True) -> Callable | None:
    """`value` if callable (or None when `optional`); else ArgumentTypeError naming it."""
    if (value is None and optional) or callable(value):
        return value
    raise ArgumentTypeError(
        f"{name}: expected a callable{' or None' if optional else ''}, got {describe(value)}"
    )


def check_vector(
    value: Any, size: int, name: str, *, optional: bool = True, finite: bool = True
) -> np.ndarray | None:
    """`value` as a float64 array of shape (size,), finite if `finite` (None passes when
    `optional`); else ArgumentTypeError / ArgumentValueError naming it."""
    if value is None and optional:
        return None
    try:
        a = np.asarray(value, dtype=np.float64)
    except (TypeError, ValueError):
        raise ArgumentTypeError(f"{name}: expected {size} numbers, got {describe(value)}") from None
    if a.shape != (size,):
        raise ArgumentValueError(f"{name}: expected shape ({size},), got {a.shape}")
    if finite and not np.isfinite(a).all():
        raise ArgumentValueError(f"{name}: expected finite numbers, got {a.tolist()}")
    return a
