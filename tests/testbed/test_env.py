"""Gymnasium environment and executors."""

import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env

from pushtoknow.testbed.env import PushEnv
from pushtoknow.testbed.executor import RecordedExecutor, SimulatedExecutor
from pushtoknow.testbed.objects import catalogue_object
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim_config import PushConfig, SimConfig

FAST = SimConfig(push=PushConfig(horizon=1.5))


def test_env_passes_gymnasium_checker():
    env = PushEnv("catalogue:7", FAST, max_pushes=2)
    check_env(env, skip_render_check=True)
    env.close()


def test_env_step_is_one_push():
    env = PushEnv("catalogue:7", FAST, max_pushes=2)
    obs, info = env.reset(seed=3)
    assert obs["s0"].any()
    k = FAST.camera.outline_scale
    assert obs["outline_mask"].reshape(64, k, 64, k).any((1, 3))[obs["s0"] == 1].all()
    obs2, r, term, trunc, info = env.step(np.array([0.25, 0.5, 0.03, 0.0], np.float32))
    rec = info["record"]
    assert len(rec.time) == 16  # 1.5 s at 10 Hz + t = 0
    assert np.linalg.norm(rec.pose[-1, :2] - rec.pose[0, :2]) > 0.005  # it moved
    assert not term and not trunc
    *_, trunc = env.step(np.array([0.75, 0.9, 0.8, 1.0], np.float32))[:4]
    assert trunc
    env.close()


def test_env_refuses_a_nan_or_misshapen_action_without_pushing():
    env = PushEnv("catalogue:7", FAST, max_pushes=2)
    env.reset(seed=3)
    for bad in ([np.nan, 0.5, 0.5, 0.0], [0.2, 0.5, 0.5], [0.2, np.inf, 0.5, 1.0]):
        with pytest.raises(ValueError, match="action must be 4 finite numbers"):
            env.step(np.array(bad))
    assert env._n == 0  # nothing was executed
    env.close()


def test_env_is_seeded():
    def roll(seed):
        env = PushEnv(None, FAST)
        env.reset(seed=seed)
        rec = env.step(np.array([0.5, 0.5, 0.03, 0.0], np.float32))[4]["record"]
        env.close()
        return rec.pose

    assert np.array_equal(roll(1), roll(1))


def test_recorded_executor_replays():
    ex = SimulatedExecutor(catalogue_object(1), FAST, seed=0)
    v = ex.observe()
    rec = ex.execute(Push((0.0, 0.0), 0.0))
    rex = RecordedExecutor([rec], ex.camera)
    assert np.array_equal(rex.observe().s0, rec.s0)
    assert rex.execute(Push((1.0, 1.0), 1.0)) is rec
    with pytest.raises(IndexError):
        rex.execute(Push((0.0, 0.0), 0.0))
    assert v.s0.shape == (64, 64)
