"""The evaluation's `oracle` row and the identification benchmark's bookkeeping."""

import numpy as np

from pushtoknow.common.params import ObjectParams
from pushtoknow.evaluation.heldout import HeldoutRun
from pushtoknow.evaluation.identification import oracle_run, push_profiles
from pushtoknow.evaluation.suite import summarise_method
from pushtoknow.identification.synthetic import simulate_pushes
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.sim import stack_records, unstack_records
from pushtoknow.testbed.sim_config import SimConfig

SHORT = SimConfig(render=False).model_copy(
    update={"push": SimConfig().push.model_copy(update={"horizon": 2.0})}
)


def test_push_profiles_alternate():
    assert push_profiles(["constant", "release"], 5) == [
        "constant",
        "release",
        "constant",
        "release",
        "constant",
    ]


def test_oracle_row_from_the_pushes_a_model_made():
    spec = ObjectSpec("rect1", ObjectParams(0.4, 0.6, 0.0, 0.01, 1.0e-3), name="o")
    records = simulate_pushes(spec, ["constant"], seed=1, config=SHORT)
    (back,) = unstack_records(stack_records([records]))  # the cache's packing, by field name
    assert back == [r.tracks_only() for r in records]
    assert back[0].rgb is None and back[0].force_clean is not None
    truth = spec.params.as_array()
    base = HeldoutRun(
        mean=np.zeros((1, 2, 5)),
        std=np.ones((1, 2, 5)),
        zscore=np.zeros((1, 2, 5)),
        product=np.zeros((1, 2)),
        truth=truth[None],
        ids=["o"],
        seconds=[0.0],
        pushes=[back],
    )
    run = oracle_run(base, [spec.to_json()], SHORT, seed=0, workers=1, progress=None)
    assert base.pushes == [[r.tracks_only() for r in records]]  # the noise goes on a copy
    assert run.mean.shape == (1, 2, 5) and run.zscore.shape == (1, 2, 5)
    assert abs(run.product[0, 1] / (0.4 * 0.6) - 1) < 0.02  # μ·m from one constant push
    assert abs(run.product[0, 0] / (0.4 * 0.6) - 1) > 0.02  # the prior row does not know it
    summary = summarise_method(run, [np.array([0])])
    assert set(summary["coverage90_per_param"]) >= {"mass", "inertia", "overall"}
    # each row's 90% interval, from the distribution its mean comes from: the mean lies inside
    assert run.lower.shape == run.upper.shape == (1, 2, 5)
    assert (run.lower < run.upper).all()
    assert summary["outside_interval"] == 0


def test_the_oracle_reruns_a_cached_run_without_pushes(tmp_path, monkeypatch):
    """A cached inference run is reused, unless the oracle needs the pushes it lacks."""
    import numpy as np

    from pushtoknow.evaluation import suite
    from pushtoknow.evaluation.heldout import HeldoutRun
    from pushtoknow.testbed.push import Push
    from pushtoknow.testbed.sim import PushRecord

    t = np.arange(4.0)
    push = PushRecord(Push((0.0, -0.05), 1.5), t, np.zeros((4, 3)), np.zeros((4, 3)), None,
                      np.zeros((4, 2)), None, None, None)  # fmt: skip

    def run(pushes: bool) -> HeldoutRun:
        z = np.zeros((1, 2, 5))
        return HeldoutRun(z, z, z, np.zeros((1, 2)), np.zeros((1, 5)), ["o"], [1.0],
                          np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), [["constant"]],
                          [[push]] if pushes else None)  # fmt: skip

    calls = []
    monkeypatch.setattr(suite, "evaluate_heldout", lambda *a, **k: calls.append(1) or run(True))
    cfg = suite.EvaluationConfig(heldout_objects=1, novel_objects=0)
    cache = tmp_path / "run.npz"
    model = tmp_path / "model.pt"
    model.write_bytes(b"weights")
    key = suite._cache_key(model, "uniform", ["o"], cfg, ("constant",))
    suite._save_run(cache, key, run(False))
    args = (model, "uniform", ["o"], cfg, ("constant",), cache, None)
    assert suite._inference_run(*args).pushes is None and not calls  # from the cache
    assert suite._inference_run(*args, need_pushes=True).pushes == [[push]] and calls
    assert suite._inference_run(*args, need_pushes=True).pushes == [[push]]  # re-cached
    assert len(calls) == 1


def test_the_oracle_row_is_cached_by_the_pushes_it_replays(tmp_path, monkeypatch):
    """A second evaluation on the same pushes reuses the oracle row; other pushes recompute it."""
    from pushtoknow.evaluation import identification, suite
    from pushtoknow.evaluation.heldout import HeldoutRun
    from pushtoknow.evaluation.metrics import MethodRun
    from pushtoknow.testbed.push import Push
    from pushtoknow.testbed.sim import PushRecord

    def base(track_value: float) -> HeldoutRun:
        z = np.zeros((1, 2, 5))
        a = np.full((4, 3), track_value)
        push = PushRecord(Push((0.0, -0.05), 1.5), np.arange(4.0), a, a, None, a[:, :2],
                          None, None, None)  # fmt: skip
        return HeldoutRun(z, z, z, np.zeros((1, 2)), np.zeros((1, 5)), ["o"], [1.0],
                          np.zeros((1, 1, 3)), np.zeros((1, 1, 3)), [["constant"]],
                          [[push]])  # fmt: skip

    calls = []

    def fake_oracle(b, objects, sim_config, seed, workers, progress):
        calls.append(1)
        v = float(len(calls))
        full = np.full((1, 2, 5), v)
        return MethodRun(full, np.ones((1, 2, 5)), np.zeros((1, 5)), ["o"], np.full((1, 2), v),
                         2.5, np.zeros((1, 2, 5)), lower=full - 1, upper=full + 1)  # fmt: skip

    monkeypatch.setattr(identification, "oracle_run", fake_oracle)
    cache = tmp_path / "oracle.npz"
    args = (["o"], SHORT, 0, 1, None, cache)
    first = suite._oracle_run(base(0.0), *args)
    again = suite._oracle_run(base(0.0), *args)
    assert len(calls) == 1  # from the cache
    np.testing.assert_array_equal(again.mean, first.mean)
    np.testing.assert_array_equal(again.product, first.product)
    np.testing.assert_array_equal(again.lower, first.lower)  # the intervals are cached too
    np.testing.assert_array_equal(again.upper, first.upper)
    assert again.seconds_per_object == 2.5 and again.ids == ["o"]
    other = suite._oracle_run(base(1.0), *args)  # other recorded tracks
    assert len(calls) == 2 and other.mean[0, 0, 0] == 2.0
    suite._oracle_run(base(1.0), ["o"], SHORT, 1, 1, None, cache)  # another seed
    assert len(calls) == 3
    suite._oracle_run(base(1.0), ["o"], SHORT, 1, 1, None, cache)
    assert len(calls) == 3
    # other identification settings: recomputed
    changed = identification.ORACLE_SETTINGS.model_copy(update={"restart_chi2": 2.0})
    monkeypatch.setattr(identification, "ORACLE_SETTINGS", changed)
    suite._oracle_run(base(1.0), ["o"], SHORT, 1, 1, None, cache)
    assert len(calls) == 4


def test_product_relative_error_of_the_final_estimates():
    import numpy as np

    from pushtoknow.evaluation.metrics import MethodRun
    from pushtoknow.evaluation.suite import product_relative_error

    truth = np.array([[0.5, 0.4, 0, 0, 1e-3], [1.0, 0.5, 0, 0, 1e-3]])
    product = np.array([[0.3, 0.202], [0.4, 0.45]])  # final: +1 % and −10 %
    run = MethodRun(np.zeros((2, 2, 5)), np.ones((2, 2, 5)), truth, ["a", "b"], product)
    r = product_relative_error(run)
    assert abs(r["max"] - 0.1) < 1e-12
    assert abs(r["median"] - 0.055) < 1e-12 and r["share_within_2pct"] == 0.5


def test_tracking_noise_has_its_std_and_spares_the_start_pose():
    from pushtoknow.identification.synthetic import add_tracking_noise

    spec = ObjectSpec("rect1", ObjectParams(0.4, 0.6, 0.0, 0.01, 1.0e-3), name="o")
    from copy import deepcopy

    record = simulate_pushes(spec, ["constant"], seed=1, config=SHORT)[0]
    records = [deepcopy(record) for _ in range(40)]
    add_tracking_noise(records, (5e-4, 0.01), np.random.default_rng(0))
    noise = np.stack([r.pose - record.pose for r in records])  # (40, T, 3)
    assert (noise[:, 0] == 0).all()
    np.testing.assert_allclose(noise[:, 1:].std(axis=(0, 1)), [5e-4, 5e-4, 0.01], rtol=0.1)
