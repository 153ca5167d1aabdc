"""Benchmarks behind `pushtoknow bench` (speed and memory targets live here, not in tests)."""

import platform
import resource
import statistics
from collections.abc import Sequence


def machine_description() -> str:
    import os

    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    return f"{cpu}, {os.cpu_count()} cores, Python {platform.python_version()}"


def peak_rss_mb() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0


def median_or_nan(values: Sequence[float]) -> float:
    """The median of `values`, NaN when there are none."""
    return float(statistics.median(values)) if values else float("nan")


def pooled_accuracy(rows: Sequence) -> tuple[dict[str, float], float, dict[str, float]]:
    """Rows with `error_norm` and `zscore` ({parameter: value}) pooled over objects: the mean
    |error| / catalogue range per parameter, their mean (overall) and the 90% coverage per
    parameter; NaN where there are no rows."""
    import numpy as np

    from pushtoknow.common.params import PARAM_NAMES
    from pushtoknow.evaluation.metrics import coverage

    if not rows:
        nan = dict.fromkeys(PARAM_NAMES, float("nan"))
        return nan, float("nan"), dict(nan)
    error_mean = {p: float(np.mean([r.error_norm[p] for r in rows])) for p in PARAM_NAMES}
    z = np.array([[r.zscore[p] for p in PARAM_NAMES] for r in rows])
    covered = coverage(z, 0.9)
    return (
        error_mean,
        float(np.mean(list(error_mean.values()))),
        {p: covered[p] for p in PARAM_NAMES},
    )
