"""Task runners: a local process pool and Ray give the same results in job order; a Ray task
whose worker dies is retried; a tiny `simulate`, the identification replays and a tiny
`evaluate` on Ray match the local run exactly (docs/DESIGN.md §13)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from pushtoknow.bench.scaling import arrays_digest
from pushtoknow.common.errors import ClusterError
from pushtoknow.common.parallel import LocalRunner, RayRunner, check_reachable, runner_for

ray = pytest.importorskip("ray")


def _square(x: int) -> tuple[int, int]:
    return x * x, os.getpid()


def _die_once(job: tuple[str, int]) -> int:
    """Kills its worker process the first time it runs for a marker file; returns the value
    on the retry."""
    marker, value = job
    if not os.path.exists(marker):
        Path(marker).write_text("died once")
        os._exit(1)
    return value


def _fail(x: int) -> int:
    raise ValueError(f"job {x} is bad")


@pytest.fixture(scope="module")
def ray_runner():
    """A local Ray instance of 2 CPUs whose workers can import this module's tasks."""
    old = os.environ.get("PYTHONPATH")
    here = str(Path(__file__).parent)
    os.environ["PYTHONPATH"] = here if not old else f"{here}{os.pathsep}{old}"
    try:
        with RayRunner("auto", workers=2) as runner:
            yield runner
    finally:
        if old is None:
            del os.environ["PYTHONPATH"]
        else:
            os.environ["PYTHONPATH"] = old


def test_local_runner_keeps_job_order_and_reports_each_job():
    done: list[int] = []
    with LocalRunner(2) as runner:
        out = runner.map(_square, list(range(7)), on_done=lambda i, _: done.append(i))
        assert runner.map(_square, [3])[0][0] == 9  # reusable; one job runs in this process
    assert [r[0] for r in out] == [i * i for i in range(7)]
    assert sorted(done) == list(range(7))
    with runner_for(1) as serial:
        assert [r[0] for r in serial.map(_square, [1, 2])] == [1, 4]
        assert {r[1] for r in serial.map(_square, [1, 2])} == {os.getpid()}


KILLED_PARENT = """
import threading, time
from pushtoknow.common.parallel import LocalRunner
if __name__ == "__main__":
    runner = LocalRunner(2)
    threading.Thread(target=runner.map, args=(time.sleep, [120, 120]), daemon=True).start()
    time.sleep(4)
    print("running", flush=True)
    time.sleep(120)
"""


def _children(pid: int) -> set[int]:
    out = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            out.add(int(stat.parent.name))
    return out


@pytest.mark.skipif(not Path("/proc/self/stat").exists(), reason="reads /proc (Linux)")
def test_pool_workers_end_with_a_killed_parent(tmp_path):
    """A run killed by a signal (no cleanup runs) leaves no worker running its jobs."""
    import subprocess
    import sys
    import time

    script = tmp_path / "parent.py"
    script.write_text(KILLED_PARENT)
    proc = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "running"
        workers = _children(proc.pid)
        assert len(workers) >= 2  # the two workers (and the resource tracker)
    finally:
        proc.kill()
        proc.wait()
    deadline = time.monotonic() + 15
    while time.monotonic() < deadline and any(Path(f"/proc/{w}").exists() for w in workers):
        time.sleep(0.2)
    alive = [w for w in workers if Path(f"/proc/{w}").exists()]
    for w in alive:
        os.kill(w, 9)
    assert not alive


def test_runner_for_leaves_a_given_runner_open():
    with LocalRunner(2) as runner:
        with runner_for(runner) as same:
            assert same is runner
        assert [r[0] for r in runner.map(_square, [2, 3])] == [4, 9]


def test_ray_runner_keeps_job_order_and_reports_each_job(ray_runner):
    done: list[int] = []
    out = ray_runner.map(_square, list(range(7)), on_done=lambda i, _: done.append(i))
    assert [r[0] for r in out] == [i * i for i in range(7)]
    assert sorted(done) == list(range(7))
    assert ray_runner.workers == 2


def test_ray_retries_a_task_whose_worker_died(ray_runner, tmp_path):
    jobs = [(str(tmp_path / f"marker-{i}"), i) for i in range(3)]
    assert ray_runner.map(_die_once, jobs) == [0, 1, 2]
    assert all((tmp_path / f"marker-{i}").exists() for i in range(3))


def test_a_failing_task_raises_its_error(ray_runner):
    with pytest.raises(Exception, match="job 1 is bad"):
        ray_runner.map(_fail, [1])


def test_unreachable_or_malformed_addresses_are_one_line_errors():
    with pytest.raises(ClusterError, match="no Ray cluster answers"):
        check_reachable("127.0.0.1:1")
    with pytest.raises(ClusterError, match="expected auto, HOST:PORT"):
        check_reachable("somewhere")


@pytest.mark.slow
def test_simulate_on_ray_writes_the_local_runs_arrays(ray_runner, tmp_path):
    from pushtoknow.datasets.generate import GenerationConfig, generate_dataset
    from pushtoknow.testbed.sim_config import PushConfig, SimConfig

    cfg = GenerationConfig(
        objects=3,
        pushes=1,
        seed=5,
        objects_per_shard=1,
        profiles=("constant", "release"),
        sim=SimConfig(push=PushConfig(horizon=1.0)),
    )
    generate_dataset(tmp_path / "local", cfg, workers=1, progress=False)
    generate_dataset(tmp_path / "ray", cfg, workers=ray_runner, progress=False)
    assert len(list((tmp_path / "ray").glob("shard-*.h5"))) == 3
    assert arrays_digest(tmp_path / "local") == arrays_digest(tmp_path / "ray")
    other = cfg.model_copy(update={"seed": 6})  # the digest does see the pushes
    generate_dataset(tmp_path / "other", other, workers=1, progress=False)
    assert arrays_digest(tmp_path / "other") != arrays_digest(tmp_path / "local")


def test_identification_rollouts_on_ray_equal_the_local_ones(ray_runner):
    from pushtoknow.identification.fit import tracks_from_records
    from pushtoknow.identification.replay import ReplayScene, RolloutPool
    from pushtoknow.identification.synthetic import simulate_pushes
    from pushtoknow.testbed.object_refs import load_object_spec
    from pushtoknow.testbed.objects import resolve_shape
    from pushtoknow.testbed.sim_config import SimConfig

    sim = SimConfig(render=False).model_copy(
        update={"push": SimConfig().push.model_copy(update={"horizon": 2.0})}
    )
    spec = load_object_spec("catalogue:117")
    records = simulate_pushes(spec, ["constant", "release"], seed=2, config=sim)
    tracks = tracks_from_records(records, sim)
    scene = ReplayScene(resolve_shape(spec.shape), spec.height, sim)
    phis = np.stack([spec.params.as_array(), spec.params.as_array() * [1.2, 0.9, 1, 1, 1.1]])
    with RolloutPool(1) as local:
        expected = local.run(scene, phis, tracks)
    with RolloutPool(ray_runner) as pool:
        got = pool.run(scene, phis, tracks)
        assert pool.push_rollouts == 4
    for a, b in zip(expected, got):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)


@pytest.mark.slow
def test_evaluate_on_ray_gives_the_local_numbers(ray_runner, tmp_path_factory, tmp_path):
    from pushtoknow.evaluation.suite import EvaluationConfig, run_evaluation
    from tiny_training import tiny_dataset, tiny_run

    data, run_dir = tiny_dataset(tmp_path_factory), tiny_run(tmp_path_factory)
    ci = Path(__file__).parents[2] / "configs" / "evaluate-ci.yaml"
    # the learned filter's uniform rows: the physics filter's replays on Ray are checked above
    # (a catalogue object's replays, and active look-ahead, cost minutes here)
    update = {"novel_objects": 0, "heldout_objects": 2, "physics_policies": ()}
    update |= {"policies": ("uniform",)}
    cfg = EvaluationConfig.from_yaml(ci).model_copy(update=update)
    local = run_evaluation(data, [run_dir], cfg, tmp_path / "local")
    on_ray = run_evaluation(data, [run_dir], cfg, tmp_path / "ray", runner=ray_runner)
    a, b = local.methods, on_ray.methods
    diff = {(m, k) for m in a for k in a[m] if a[m][k] != b[m][k] and k != "seconds_per_object"}
    assert not diff, diff  # every number but the wall time
