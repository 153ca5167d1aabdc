"""The push policies' names, defined once (the policies themselves: `inference.policies`).
Light on purpose: configs and the CLI's choices import it without the testbed."""

from __future__ import annotations

from typing import Literal, get_args

PolicyName = Literal["uniform", "random", "active-kl", "active-entropy"]
POLICY_NAMES: tuple[str, ...] = get_args(PolicyName)
