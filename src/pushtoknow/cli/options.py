"""Options shared by the commands: one definition each."""

from __future__ import annotations

import enum
from pathlib import Path

import typer
from rich.markup import escape

from pushtoknow.common.estimators import DEFAULT_ESTIMATOR, ESTIMATOR_NAMES
from pushtoknow.common.params import MIN_SIGMA_POINTS
from pushtoknow.common.policy_names import POLICY_NAMES

SEED_HELP = "random seed (≥ 0): same seed, same result on the CPU"


def seed_option(default: int | None = 0, help: str = SEED_HELP):
    """The `--seed` option of every command (numpy seeds are non-negative)."""
    return typer.Option(default, "--seed", min=0, help=help)


def sigma_points_option(default: int | None = None, help: str = "default: the model's"):
    """The `--sigma-points` option of every command that runs the filter (at least
    `common.params.MIN_SIGMA_POINTS`)."""
    return typer.Option(
        default,
        "--sigma-points",
        min=MIN_SIGMA_POINTS,
        help=f"Monte-Carlo sigma points of the filter, ≥ {MIN_SIGMA_POINTS} ({help})",
    )


MAX_PUSHES = 200  # per object: a push's record (images) is ≈ 1.8 MB, held until written
PUSH_COST = "≈ 1.8 MB of images per push, held in memory until written"


def _bounded_pushes(value: int) -> int:
    if value > MAX_PUSHES:
        raise typer.BadParameter(
            f"{value}: at most {MAX_PUSHES} pushes per object ({PUSH_COST}: {value} would hold "
            f"≈ {value * 1.8 / 1000:.1f} GB)"
        )
    return value


def pushes_option(default: int, help: str = "pushes per object"):
    """The `--pushes` option of the commands that push objects on the testbed (at most
    MAX_PUSHES per object: a run holds every push's images until it writes them)."""
    return typer.Option(
        default,
        "--pushes",
        min=1,
        callback=_bounded_pushes,
        help=f"{help}, 1–{MAX_PUSHES} ({PUSH_COST})",
    )


PolicyChoice = enum.Enum("PolicyChoice", {p: p for p in POLICY_NAMES}, type=str)  # CLI choices


def policy_option(default: str | None = "uniform", help: str = "push policy"):
    """The `--policy` option of every command that pushes with a policy (choices from
    `inference.policies.POLICY_NAMES`)."""
    return typer.Option(None if default is None else PolicyChoice(default), "--policy", help=help)


EstimatorChoice = enum.Enum("EstimatorChoice", {e: e for e in ESTIMATOR_NAMES}, type=str)


def estimator_option(default: str = DEFAULT_ESTIMATOR):
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
    "joins the cluster in RAY_ADDRESS), ADDRESS joins a running cluster (HEAD:6379, or "
    "ray://HEAD:10001 with Ray Client: ray[client]); same results as the local pool; needs the "
    "pushtoknow[ray] extra"
)


def ray_option():
    """The `--ray` option of every command that fans work out (`common.parallel`)."""
    return typer.Option(None, "--ray", metavar="auto|ADDRESS", help=escape(RAY_HELP))


EXPORT_HELP = (
    "write the estimated object for a simulator: mjcf PATH (MuJoCo) or urdf PATH (with an OBJ "
    "mesh beside it); mass, CoM, I_z, friction and the outline as geometry"
)


def export_option():
    """The `--export KIND PATH` option of the commands that estimate an object."""
    return typer.Option(None, "--export", metavar="KIND PATH", help=EXPORT_HELP)


def checked_export(export: tuple[str, Path] | None) -> tuple[str, Path] | None:
    """`--export`'s (kind, path), checked before any work (`testbed.export`); None if not
    given. Raises ExportError naming the bad kind or the missing folder."""
    from pushtoknow.common.errors import ExportError
    from pushtoknow.testbed.export import EXPORT_KINDS

    if export is None:
        return None
    kind, path = export
    if kind not in EXPORT_KINDS:
        raise ExportError("--export", kind, f"KIND must be one of {', '.join(EXPORT_KINDS)}")
    if not Path(path).parent.is_dir():
        raise ExportError("--export", str(path), "its folder does not exist")
    return kind, Path(path)


PRIOR_HELP = (
    "range LOW,HIGH the prior spreads {name} over, uniformly ({unit}; default: the testbed "
    "catalogue's for simulated pushes, everyday objects' for real ones: {everyday})"
)


def _prior_range(value: str | None) -> tuple[float, float] | None:
    """`--prior-*`'s LOW,HIGH as two numbers (None if not given)."""
    if value is None:
        return None
    try:
        lo, hi = (float(v) for v in value.split(","))
    except ValueError:
        raise typer.BadParameter(f"{value!r}: give LOW,HIGH, e.g. 0.05,1.2") from None
    return lo, hi


def prior_option(name: str):
    """A `--prior-mass|friction|inertia LOW,HIGH` option (`identification.prior.PriorRanges`)."""
    from pushtoknow.identification.prior import EVERYDAY_PRIOR

    unit = {"mass": "kg", "friction": "Coulomb coefficient", "inertia": "kg·m²"}[name]
    lo, hi = getattr(EVERYDAY_PRIOR, name)
    return typer.Option(
        None,
        f"--prior-{name}",
        metavar="LOW,HIGH",
        callback=_prior_range,
        help=PRIOR_HELP.format(name=name, unit=unit, everyday=f"{lo:g}–{hi:g}"),
    )


def prior_ranges(default, mass=None, friction=None, inertia=None):
    """`default` (`PriorRanges`) with the ranges the `--prior-*` options gave; raises
    ConfigError naming the option for an impossible range."""
    from pydantic import ValidationError

    from pushtoknow.common.errors import ConfigError
    from pushtoknow.identification.prior import PriorRanges

    given = {"mass": mass, "friction": friction, "inertia": inertia}
    given = {k: v for k, v in given.items() if v is not None}
    if not given:
        return default
    try:
        return PriorRanges(**{**default.model_dump(), **given})
    except ValidationError as e:
        err = e.errors()[0]
        raise ConfigError(
            f"--prior-{err['loc'][0]}", err["msg"].removeprefix("Value error, ")
        ) from None
