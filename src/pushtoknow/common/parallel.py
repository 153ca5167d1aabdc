"""Where fanned-out work runs: a local process pool (the default) or a Ray cluster.

Every command that fans work out (simulation shards, collection shards, evaluation objects,
identification rollouts) hands a module-level function and its jobs to a `TaskRunner`. Each job
carries its own seed, so results do not depend on where or in which order jobs run: a Ray run
gives the local run's bytes (docs/DESIGN.md §13).

* `LocalRunner(workers)`: a spawn process pool (fresh MuJoCo and GL state per process), or this
  process when workers ≤ 1.
* `RayRunner(address)`: Ray tasks, one CPU each. "auto" starts a local Ray instance (or joins
  the cluster named by the RAY_ADDRESS environment variable); any other value is the address of
  a running cluster (`ray://head:10001` or `head:6379`). A task whose worker process dies is
  retried (`max_retries`); output files are written atomically by the tasks themselves, so a
  retried or resumed task never leaves a partial file. Needs the `pushtoknow[ray]` extra.
"""

from __future__ import annotations

import importlib.util
import multiprocessing
import os
import socket
from abc import ABC, abstractmethod
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Future, ProcessPoolExecutor, as_completed
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from typing import Any

from pushtoknow.common.errors import ClusterError, first_line

RAY_AUTO = "auto"
RAY_MAX_RETRIES = 3
CONNECT_TIMEOUT_S = 5.0  # Ray itself waits minutes on an address where nothing listens
LOCAL_OBJECT_STORE_BYTES = 512 * 2**20  # results are small; leave the memory to the tasks
# What a Ray worker needs from the driver's environment (rendering backend, thread counts).
FORWARDED_ENV = ("MUJOCO_GL", "PYOPENGL_PLATFORM", "OMP_NUM_THREADS", "MKL_NUM_THREADS")

OnDone = Callable[[int, Any], None]
Initializer = Callable[[], None]


class TaskRunner(ABC):
    """Runs fn(job) for every job; results in job order. `workers`: how many jobs run at once
    (for a Ray cluster, its CPUs)."""

    workers: int

    @abstractmethod
    def map(
        self,
        fn: Callable[[Any], Any],
        jobs: Sequence[Any],
        on_done: OnDone | None = None,
        initializer: Initializer | None = None,
    ) -> list[Any]:
        """[fn(job) for job in jobs], computed in parallel; on_done(index, result) is called in
        this process as each job finishes (in completion order); `initializer()` runs once in
        each worker process before its first job. fn and initializer: module-level functions."""

    @abstractmethod
    def close(self) -> None:
        """Release the workers (a runner is reusable until closed)."""

    def __enter__(self) -> TaskRunner:
        return self

    def __exit__(self, *exc) -> None:
        self.close()


_initialised: set[int] = set()


def _call(fn: Callable[[Any], Any], initializer: Initializer | None, job: Any) -> Any:
    """fn(job), after `initializer()` once per process."""
    if initializer is not None and id(initializer) not in _initialised:
        initializer()
        _initialised.add(id(initializer))
    return fn(job)


PR_SET_PDEATHSIG = 1  # prctl(2): the signal a process gets when its parent ends


def _start_worker(parent: int, initializer: Initializer | None) -> None:
    """A pool worker's start: it ends with the thread that started it (on Linux, by
    PR_SET_PDEATHSIG; a pool whose parent is killed by a signal would otherwise keep its
    workers running their jobs), then `initializer()`. Workers start in the thread that first
    submits to the pool: a `LocalRunner` is meant to be used from one long-lived thread (the
    main one)."""
    import signal
    import sys

    if sys.platform.startswith("linux"):
        import ctypes

        try:
            ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGTERM)
        except (OSError, AttributeError):  # no prctl: workers end when their queue closes
            pass
        if os.getppid() != parent:  # the parent ended before the signal was armed
            os._exit(1)
    if initializer is not None:
        initializer()


class LocalRunner(TaskRunner):
    """A spawn process pool of `workers` processes (created on first use, kept across calls with
    the same initializer), or this process when workers ≤ 1 or there is a single job."""

    def __init__(self, workers: int = 1):
        self.workers = max(1, int(workers))
        self._pool: ProcessPoolExecutor | None = None
        self._pool_initializer: Initializer | None = None

    def map(self, fn, jobs, on_done=None, initializer=None):
        jobs = list(jobs)
        results: list[Any] = [None] * len(jobs)
        if self.workers <= 1 or len(jobs) <= 1:  # in this process: no worker initializer
            for i, job in enumerate(jobs):
                results[i] = fn(job)
                if on_done:
                    on_done(i, results[i])
            return results
        if self._pool is not None and self._pool_initializer is not initializer:
            self.close()
        if self._pool is None:
            self._pool = ProcessPoolExecutor(
                self.workers,
                mp_context=multiprocessing.get_context("spawn"),  # no forked MuJoCo/GL state
                initializer=_start_worker,
                initargs=(os.getpid(), initializer),
            )
            self._pool_initializer = initializer
        futures: dict[Future, int] = {self._pool.submit(fn, job): i for i, job in enumerate(jobs)}
        try:
            for fut in as_completed(futures):
                i = futures[fut]
                results[i] = fut.result()
                if on_done:
                    on_done(i, results[i])
        except BrokenProcessPool:
            self._pool = None
            raise ClusterError(
                "a worker process ended abruptly: out of memory or killed, or a Python script "
                'without an `if __name__ == "__main__":` guard around its top level (worker '
                "processes are spawned and import it)"
            ) from None
        except BaseException:
            for fut in futures:
                fut.cancel()
            raise
        return results

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(cancel_futures=True)
            self._pool = None


def _import_ray():
    try:
        import ray
    except ImportError:
        raise ClusterError(
            "--ray needs Ray: install the extra, pip install 'pushtoknow[ray]'"
        ) from None
    return ray


def check_reachable(address: str, where: str | None = None, hint: str = "") -> None:
    """Raise `ClusterError` unless something listens at a Ray address ([ray://]HOST:PORT)
    within CONNECT_TIMEOUT_S, and, for a ray:// address, Ray Client's dependencies are
    installed. `where`: how the message names the address (default "--ray ADDRESS"); `hint`:
    appended to the message of an unreachable address."""
    where = where or f"--ray {address}"
    hostport = address.split("://", 1)[-1].rstrip("/")
    host, _, port = hostport.rpartition(":")
    if not host or not port.isdigit():
        raise ClusterError(f"{where}: expected auto, HOST:PORT or ray://HOST:PORT")
    if address.startswith("ray://") and importlib.util.find_spec("grpc") is None:
        raise ClusterError(
            f"{where}: a ray:// address connects through Ray Client, which needs Ray's client "
            "extra (pip install 'ray[client]'); or give the head's GCS address, HOST:6379"
        )
    try:
        socket.create_connection((host, int(port)), timeout=CONNECT_TIMEOUT_S).close()
    except OSError as e:
        raise ClusterError(
            f"{where}: no Ray cluster answers there within {CONNECT_TIMEOUT_S:g} s ({e}){hint}"
        ) from None


class RayRunner(TaskRunner):
    """Ray tasks of one CPU each on the cluster at `address` ("auto": a local instance with
    `workers` CPUs, or the cluster in RAY_ADDRESS). Started instances are shut down on close;
    a cluster joined is left running."""

    def __init__(
        self,
        address: str = RAY_AUTO,
        workers: int | None = None,
        max_retries: int = RAY_MAX_RETRIES,
    ):
        ray = _import_ray()
        self.max_retries = int(max_retries)
        self._started = False
        if not ray.is_initialized():
            env = {k: os.environ[k] for k in FORWARDED_ENV if k in os.environ}
            from_env = os.environ.get("RAY_ADDRESS", "")
            local = address == RAY_AUTO and not from_env
            if address != RAY_AUTO:
                check_reachable(address)
            elif from_env not in ("", "auto", "local"):  # else Ray finds or starts a local one
                check_reachable(
                    from_env,
                    f"--ray auto with RAY_ADDRESS={from_env}",
                    "; unset RAY_ADDRESS to start a local instance",
                )
            try:
                ray.init(
                    address=None if address == RAY_AUTO else address,
                    num_cpus=workers if local else None,
                    object_store_memory=LOCAL_OBJECT_STORE_BYTES if local else None,
                    include_dashboard=False,
                    log_to_driver=False,
                    configure_logging=False,
                    # a local instance's workers inherit this environment; a cluster's get it
                    runtime_env={"env_vars": env} if env and not local else None,
                )
            except (ConnectionError, RuntimeError, ValueError) as e:
                raise ClusterError(
                    f"--ray {address}: cannot reach a Ray cluster ({first_line(e)})"
                ) from None
            self._started = True
        self.workers = max(1, int(ray.cluster_resources().get("CPU", 1)))
        self._remote = ray.remote(num_cpus=1, max_retries=self.max_retries)(_call)

    def map(self, fn, jobs, on_done=None, initializer=None):
        ray = _import_ray()
        refs = [self._remote.remote(fn, initializer, job) for job in jobs]
        index = {ref: i for i, ref in enumerate(refs)}
        results: list[Any] = [None] * len(refs)
        pending = list(refs)
        try:
            while pending:
                done, pending = ray.wait(pending, num_returns=1)
                for ref in done:
                    i = index[ref]
                    results[i] = ray.get(ref)
                    if on_done:
                        on_done(i, results[i])
        except BaseException:
            for ref in pending:
                ray.cancel(ref, force=True)
            raise
        return results

    def close(self) -> None:
        if self._started:
            _import_ray().shutdown()
            self._started = False


def make_runner(workers: int = 1, ray: str | None = None) -> TaskRunner:
    """The runner a command's `--workers` and `--ray` ask for (no --ray: a local pool)."""
    return LocalRunner(workers) if ray is None else RayRunner(ray, workers)


Workers = int | TaskRunner  # a local pool of that many processes, or a runner to use


@contextmanager
def runner_for(workers: Workers) -> Iterator[TaskRunner]:
    """`workers` itself if it is a runner (left open for its owner), else a local pool of that
    many processes, closed on exit."""
    if isinstance(workers, TaskRunner):
        yield workers
        return
    with LocalRunner(workers) as runner:
        yield runner
