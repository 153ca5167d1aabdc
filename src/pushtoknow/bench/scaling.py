"""Scaling of fanned-out work: `simulate` on 1 and N workers, on the local process pool and on
Ray, its throughput ratios, and whether every run wrote the same arrays (docs/DESIGN.md §13)."""

from __future__ import annotations

import hashlib
import tempfile
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import h5py

from pushtoknow.bench import machine_description
from pushtoknow.common.parallel import LocalRunner, RayRunner, TaskRunner
from pushtoknow.reporting.tables import markdown_table


@dataclass(frozen=True)
class ScalingRun:
    """One `simulate` run: backend ("local" or "ray"), workers, wall seconds of the simulation
    (Ray's start excluded, `start_s`), objects per second, and the arrays' SHA-256."""

    backend: str
    workers: int
    start_s: float
    seconds: float
    objects_per_s: float
    arrays_sha256: str


@dataclass(frozen=True)
class ScalingReport:
    objects: int
    pushes: int
    objects_per_shard: int
    seed: int
    runs: list[ScalingRun]
    speedup: dict[str, float]  # backend → throughput(N workers) / throughput(1 worker)
    identical: bool  # every run wrote the same arrays
    machine: str

    def to_dict(self) -> dict:
        return asdict(self)


def arrays_digest(root: Path) -> str:
    """SHA-256 over every dataset array of every shard in `root` (names and bytes, in order):
    equal digests mean equal pushes, whatever the files' metadata and timestamps."""
    h = hashlib.sha256()
    for shard in sorted(root.glob("shard-*.h5")):
        with h5py.File(shard, "r") as f:

            def visit(name: str, obj, shard_name: str = shard.name) -> None:
                if isinstance(obj, h5py.Dataset):
                    h.update(f"{shard_name}/{name}".encode())
                    h.update(obj[()].tobytes())

            f.visititems(visit)
    return h.hexdigest()


def _one_run(backend: str, workers: int, cfg, ray_address: str, work: Path) -> ScalingRun:
    from pushtoknow.datasets.generate import generate_dataset

    t0 = time.perf_counter()
    runner: TaskRunner = (
        RayRunner(ray_address, workers) if backend == "ray" else LocalRunner(workers)
    )
    start = time.perf_counter() - t0
    out = work / f"{backend}-{workers}"
    with runner:
        t1 = time.perf_counter()
        generate_dataset(out, cfg, workers=runner, progress=False)
        seconds = time.perf_counter() - t1
    return ScalingRun(backend, workers, start, seconds, cfg.objects / seconds, arrays_digest(out))


def run_scaling_bench(
    objects: int = 8,
    pushes: int = 2,
    workers: int = 2,
    seed: int = 0,
    objects_per_shard: int = 4,
    ray_address: str | None = "auto",
) -> ScalingReport:
    """`simulate --objects N --pushes K` on 1 and `workers` local processes, and on a local Ray
    instance (or the cluster at `ray_address`; None: local pool only)."""
    from pushtoknow.datasets.generate import GenerationConfig

    cfg = GenerationConfig(
        objects=objects, pushes=pushes, seed=seed, objects_per_shard=objects_per_shard
    )
    backends = ["local"] + (["ray"] if ray_address is not None else [])
    runs: list[ScalingRun] = []
    with tempfile.TemporaryDirectory(prefix="pushtoknow-scaling-") as tmp:
        for backend in backends:
            for n in sorted({1, workers}):
                runs.append(_one_run(backend, n, cfg, ray_address or "auto", Path(tmp)))
    speedup = {}
    for backend in backends:
        by_n = {r.workers: r for r in runs if r.backend == backend}
        speedup[backend] = by_n[workers].objects_per_s / by_n[1].objects_per_s
    return ScalingReport(
        objects,
        pushes,
        objects_per_shard,
        seed,
        runs,
        speedup,
        len({r.arrays_sha256 for r in runs}) == 1,
        machine_description(),
    )


def scaling_markdown(report: ScalingReport) -> str:
    """The scaling table (docs/DESIGN.md §13)."""
    lines = [
        f"`simulate --objects {report.objects} --pushes {report.pushes}` "
        f"({report.objects_per_shard} objects per shard, seed {report.seed}); "
        f"machine: {report.machine}.",
        "",
    ]
    rows = []
    for r in report.runs:
        base = next(x for x in report.runs if x.backend == r.backend and x.workers == 1)
        rows.append(
            [
                r.backend,
                str(r.workers),
                f"{r.start_s:.1f}",
                f"{r.seconds:.1f}",
                f"{r.objects_per_s:.3f}",
                f"{r.objects_per_s / base.objects_per_s:.2f}×",
            ]
        )
    header = ["backend", "workers", "start (s)", "simulation (s)", "objects/s", "speed-up"]
    lines += markdown_table(header, rows)
    lines += ["", f"Same arrays in every run: {'yes' if report.identical else 'NO'}."]
    return "\n".join(lines) + "\n"
