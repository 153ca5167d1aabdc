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
