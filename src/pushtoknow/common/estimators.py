"""The estimators' names, defined once (the estimators themselves: `inference`). Light on
purpose: configs and the CLI's choices import it without the models."""

from __future__ import annotations

from typing import Literal, get_args

EstimatorName = Literal["physics", "vt-addf"]
ESTIMATOR_NAMES: tuple[str, ...] = get_args(EstimatorName)
DEFAULT_ESTIMATOR: EstimatorName = "physics"  # the simulator as the filter's model (DESIGN §12)
