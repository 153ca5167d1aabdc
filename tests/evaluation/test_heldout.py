"""Per-object evaluation runs (`evaluation.heldout`) with either estimator."""

import inspect

import numpy as np

from pushtoknow.evaluation.heldout import evaluate_heldout
from tiny_training import tiny_run


def test_the_learned_filter_stays_the_default_estimator():
    # collect and evaluate-heldout call evaluate_heldout without naming an estimator
    assert inspect.signature(evaluate_heldout).parameters["estimator"].default == "vt-addf"


def test_the_physics_run_replays_the_learned_runs_pushes(tmp_path_factory):
    """Same object and seed: the uniform policy draws the same candidates and offsets (its own
    random stream, `common.random`), but picks by bearing in the object frame, i.e. by the
    estimator's orientation estimate, so the physics run is given the learned run's pushes
    (`push_actions`) and executes exactly those, while its estimates are its own."""
    run = tiny_run(tmp_path_factory)
    args = (run, ["catalogue:10"], 2, "uniform", 3)
    learned = evaluate_heldout(*args, estimator="vt-addf")
    physics = evaluate_heldout(*args, estimator="physics", push_actions=learned.push_actions)
    assert learned.push_actions.shape == physics.push_actions.shape == (1, 2, 5)
    np.testing.assert_array_equal(physics.push_actions, learned.push_actions)
    assert physics.profiles == learned.profiles
    np.testing.assert_array_equal(physics.truth, learned.truth)
    # each run used its estimator: the learned filter's first push is the same push
    assert physics.pushes[0][0] == learned.pushes[0][0]
    assert not np.allclose(physics.mean[:, 1:], learned.mean[:, 1:])
    # the pushes follow the seed: another seed, other pushes
    other = evaluate_heldout(run, ["catalogue:10"], 1, "uniform", 4)
    assert not np.array_equal(other.push_actions[:, 0], physics.push_actions[:, 0])


def test_a_stopped_run_keeps_its_finished_objects(tmp_path_factory, monkeypatch):
    """Each object's result is kept as it finishes; a rerun reads the finished ones back and
    runs only the others, to the same run."""
    from pushtoknow.evaluation import heldout

    run = tiny_run(tmp_path_factory)
    folder = tmp_path_factory.mktemp("finished")
    args = (run, ["catalogue:10", "catalogue:11"], 1, "uniform", 3)
    whole = evaluate_heldout(*args, finished=folder)
    assert sorted(p.name for p in folder.iterdir()) == ["0.pkl", "1.pkl"]
    (folder / "1.pkl").unlink()  # the run stopped before object 1 finished
    ran = []
    real = heldout._run_one
    monkeypatch.setattr(heldout, "_run_one", lambda job: ran.append(job[1]) or real(job))
    again = evaluate_heldout(*args, finished=folder)
    assert ran == ["catalogue:11"]
    kept = {p.name: heldout.pickle.loads(p.read_bytes())["ref"] for p in folder.iterdir()}
    assert kept == {"0.pkl": "catalogue:10", "1.pkl": "catalogue:11"}
    np.testing.assert_array_equal(again.mean, whole.mean)
    np.testing.assert_array_equal(again.push_actions, whole.push_actions)
    assert again.ids == whole.ids
