"""Options shared by the commands: one definition each."""

from __future__ import annotations

import enum

import typer

from pushtoknow.common.estimators import ESTIMATOR_NAMES
from pushtoknow.common.policies import POLICY_NAMES

SEED_HELP = "random seed (≥ 0): same seed, same result on the CPU"
MIN_SIGMA_POINTS = 10


def seed_option(default: int | None = 0, help: str = SEED_HELP):
    """The `--seed` option of every command (numpy seeds are non-negative)."""
    return typer.Option(default, "--seed", min=0, help=help)


def sigma_points_option(default: int | None = None, help: str = "default: the model's"):
    """The `--sigma-points` option of every command that runs the filter."""
    return typer.Option(default, "--sigma-points", min=MIN_SIGMA_POINTS, help=help)


PolicyChoice = enum.Enum("PolicyChoice", {p: p for p in POLICY_NAMES}, type=str)  # CLI choices


def policy_option(default: str | None = "uniform", help: str = "push policy"):
    """The `--policy` option of every command that pushes with a policy (choices from
    `inference.policies.POLICY_NAMES`)."""
    return typer.Option(None if default is None else PolicyChoice(default), "--policy", help=help)


EstimatorChoice = enum.Enum("EstimatorChoice", {e: e for e in ESTIMATOR_NAMES}, type=str)


def estimator_option(default: str = "vt-addf"):
    """The `--estimator` option of every command that estimates with a model (choices from
    `common.estimators.ESTIMATOR_NAMES`)."""
    return typer.Option(
        EstimatorChoice(default),
        "--estimator",
        help="vt-addf: the paper's learned dual filter; physics: the dual filter whose model is "
        "the simulator (docs/DESIGN.md §12)",
    )


RAY_HELP = (
    "run the work as Ray tasks: 'auto' starts a local Ray instance with --workers CPUs (or "
    "joins the cluster in RAY_ADDRESS), ADDRESS joins a running cluster (ray://HEAD:10001 or "
    "HEAD:6379); same results as the local pool; needs the pushtoknow[ray] extra"
)


def ray_option():
    """The `--ray` option of every command that fans work out (`common.parallel`)."""
    return typer.Option(None, "--ray", metavar="auto|ADDRESS", help=RAY_HELP)
