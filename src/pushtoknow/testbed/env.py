"""Gymnasium environment over the testbed. **One step is one whole push** (t_H seconds of
simulation, recorded at 10 Hz), not one 10 Hz sample: the decision the agent makes is where,
which way and how fast to push; the 10 Hz record of the push is returned in `info["record"]`.

Action (Box [0, 1]^4, normalised): [s, d, w, profile]
    s: contact point, as a fraction of arc length along the S_0 contour (counter-clockwise);
    d: deviation δ = (2d − 1)·5° of the push direction from the inward normal;
    w: speed v = 0.005 + w·(0.5 − 0.005) m/s (constant speed, or peak speed of "release");
    profile: < 0.5 → "constant", ≥ 0.5 → "release".
Observation (Dict): the view before the next push: rgb (H, W, 3) uint8, depth (H, W) float32 m,
    s0 (H, W) uint8 mask.
Reward: 0. The environment is a testbed for active perception; bring your own reward (for
example the information gain of the filter). An episode is truncated after `max_pushes`.
"""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
from gymnasium import spaces

from pushtoknow.geometry.affordances import mask_contour
from pushtoknow.testbed.executor import SimulatedExecutor, View
from pushtoknow.testbed.object_refs import load_object_spec
from pushtoknow.testbed.objects import ObjectSpec, build_catalogue
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim_config import SimConfig

MAX_DEVIATION = math.radians(5.0)
SPEED_RANGE = (0.005, 0.5)  # m/s


class PushEnv(gym.Env):
    metadata = {"render_modes": ["rgb_array"], "render_fps": 10}

    def __init__(
        self,
        obj: ObjectSpec | str | None = None,
        config: SimConfig | None = None,
        max_pushes: int = 5,
        render_mode: str | None = None,
    ):
        """obj: a spec, a source string ("catalogue:ID", file), or None to draw a catalogue
        object at every reset."""
        self.config = config or SimConfig()
        self.fixed_obj = load_object_spec(obj) if isinstance(obj, str) else obj
        self.max_pushes = max_pushes
        self.render_mode = render_mode
        cam = self.config.camera
        H, W = cam.height, cam.width
        self.observation_space = spaces.Dict(
            {
                "rgb": spaces.Box(0, 255, (H, W, 3), np.uint8),
                "depth": spaces.Box(0.0, 2 * cam.distance, (H, W), np.float32),
                "s0": spaces.Box(0, 1, (H, W), np.uint8),
                "outline_mask": spaces.Box(
                    0, 1, (cam.outline_scale * H, cam.outline_scale * W), np.uint8
                ),
            }
        )
        self.action_space = spaces.Box(0.0, 1.0, (4,), np.float32)
        self._exec: SimulatedExecutor | None = None
        self._view: View | None = None
        self._n = 0

    def _obs(self) -> dict:
        v = self._view
        return {
            "rgb": v.rgb,
            "depth": v.depth,
            "s0": v.s0.astype(np.uint8),
            "outline_mask": v.outline_mask.astype(np.uint8),
        }

    def reset(self, *, seed: int | None = None, options: dict | None = None):
        super().reset(seed=seed)
        spec = self.fixed_obj
        if spec is None:
            cat = build_catalogue().objects
            spec = cat[int(self.np_random.integers(len(cat)))]
        if self._exec is not None:
            self._exec.close()
        self._exec = SimulatedExecutor(spec, self.config, seed=int(self.np_random.integers(2**31)))
        self._view = self._exec.observe()
        self._n = 0
        return self._obs(), {"object": spec.to_dict()}

    def action_to_push(self, action) -> Push:
        """The push of an action (4,) in [0, 1] (values outside are clipped). Raises ValueError
        for an action of another shape or with a non-finite entry (which would otherwise pick
        contour point 0 without a word)."""
        a = np.asarray(action, np.float64)
        if a.shape != self.action_space.shape or not np.isfinite(a).all():
            raise ValueError(
                f"action must be {self.action_space.shape[0]} finite numbers in [0, 1], got "
                f"{np.asarray(action).tolist()}"
            )
        a = np.clip(a, 0.0, 1.0)
        c = mask_contour(self._view.s0, self._exec.camera)
        cum = np.cumsum(c.lengths)
        i = int(np.searchsorted(cum, a[0] * cum[-1]) % len(cum))
        n = -c.normals[i]
        pd = math.atan2(n[1], n[0]) + (2 * a[1] - 1) * MAX_DEVIATION
        speed = SPEED_RANGE[0] + a[2] * (SPEED_RANGE[1] - SPEED_RANGE[0])
        profile = "release" if a[3] >= 0.5 else "constant"
        return Push(tuple(c.points[i]), pd, profile, float(speed))

    def step(self, action):
        if self._exec is None:
            raise RuntimeError("call reset() before step()")
        push = self.action_to_push(action)
        record = self._exec.execute(push)
        self._n += 1
        self._view = self._exec.observe()
        truncated = self._n >= self.max_pushes
        return self._obs(), 0.0, False, truncated, {"record": record, "push": push}

    def render(self):
        return None if self._view is None else self._view.rgb

    def close(self):
        if self._exec is not None:
            self._exec.close()
            self._exec = None
