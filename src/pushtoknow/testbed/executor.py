"""The executor interface: anything that can show the object and push it.

The filter and the push policies talk only to a `PushExecutor`, so a real robot (or a replay of
recorded pushes) can stand in for the simulator. One call to `observe` gives the view before a
push (for S_0 and push affordances); `execute` runs one push and returns its `PushRecord`
(fields that a real robot cannot know, like the true pose, may be NaN).
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from dataclasses import dataclass

import numpy as np

from pushtoknow.common.camera import CameraModel
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord, PushSimulator
from pushtoknow.testbed.sim_config import SimConfig


@dataclass(frozen=True)
class View:
    """What the camera shows before a push: RGB (H, W, 3) uint8, depth (H, W) m, S_0 (H, W),
    and S_0 at the outline resolution (kH, kW) (None where the camera gives none).

    moved_by: (dx, dy) m by which the executor translated the object since the end of the
    previous push (re-centring), None if it did not or does not know."""

    rgb: np.ndarray
    depth: np.ndarray
    s0: np.ndarray
    outline_mask: np.ndarray | None = None
    moved_by: tuple[float, float] | None = None

    @classmethod
    def before(cls, record: PushRecord) -> View:
        """What the camera showed before a recorded push (its first frame and masks)."""
        return cls(record.rgb[0], record.depth[0], record.s0, record.outline_mask)


class PushExecutor(ABC):
    camera: CameraModel

    @abstractmethod
    def observe(self) -> View:
        """Image the object as it rests now (before the next push)."""

    @abstractmethod
    def execute(self, push: Push) -> PushRecord:
        """Run one push and return what was recorded."""


class SimulatedExecutor(PushExecutor):
    """The MuJoCo testbed behind the executor interface.

    Before each push the object is placed at rest at a random pose (x, y uniform within
    ±`workspace_half_extent`, θ uniform): like a robot that re-centres the object so every
    push stays in view. With `recentre` (inference on one object), only the first placement
    is random; afterwards the object keeps the orientation the push left it in and is
    translated back to its first position (`View.moved_by` reports the translation), like a
    robot sliding it back into view. Deterministic given `seed`.
    """

    def __init__(
        self,
        spec: ObjectSpec,
        config: SimConfig | None = None,
        seed: int = 0,
        randomise_pose: bool = True,
        recentre: bool = False,
    ):
        self.sim = PushSimulator(spec, config)
        self.camera = self.sim.camera
        self.rng = np.random.default_rng(seed)
        self.randomise_pose = randomise_pose
        self.recentre = recentre
        self._placed = False
        self._first_pose: np.ndarray | None = None
        self._last_pose: np.ndarray | None = None
        self._moved_by: tuple[float, float] | None = None

    @property
    def spec(self) -> ObjectSpec:
        return self.sim.spec

    def place(self) -> np.ndarray:
        h = self.sim.config.workspace_half_extent
        self._moved_by = None
        if self.recentre and self._last_pose is not None:
            x0, y0 = self._first_pose[:2]
            x, y, th = self._last_pose
            self._moved_by = (float(x0 - x), float(y0 - y))
            pose = (x0, y0, th)
        elif self.randomise_pose:
            pose = (
                self.rng.uniform(-h, h),
                self.rng.uniform(-h, h),
                self.rng.uniform(-math.pi, math.pi),
            )
        else:
            pose = (0.0, 0.0, 0.0)
        self._placed = True
        placed = self.sim.reset(pose)
        if self._first_pose is None:
            self._first_pose = placed
        return placed

    @property
    def initial_pose(self) -> np.ndarray:
        """(3,) the true pose of the first placement (placing the object if not yet done)."""
        if self._first_pose is None:
            self.place()
        return self._first_pose.copy()

    def observe(self) -> View:
        if not self._placed:
            self.place()
        return View(*self.sim.observe(), moved_by=self._moved_by)

    def execute(self, push: Push) -> PushRecord:
        if not self._placed:
            self.place()
        rec = self.sim.execute(push, self.rng)
        self._last_pose = np.asarray(rec.pose[-1], dtype=float)
        self._placed = False  # the next observe/execute places the object afresh
        return rec

    def close(self) -> None:
        self.sim.close()


class RecordedExecutor(PushExecutor):
    """Replays recorded pushes in order (a dataset or a real recording). The push asked for is
    ignored: a recording cannot be re-pushed, so only non-active policies make sense here."""

    def __init__(self, records: list[PushRecord], camera: CameraModel):
        self.records = list(records)
        self.camera = camera
        self._i = 0

    def observe(self) -> View:
        r = self._current()
        return View.before(r)

    def execute(self, push: Push) -> PushRecord:
        r = self._current()
        self._i += 1
        return r

    def _current(self) -> PushRecord:
        if self._i >= len(self.records):
            raise IndexError(f"the recording holds only {len(self.records)} pushes")
        return self.records[self._i]
