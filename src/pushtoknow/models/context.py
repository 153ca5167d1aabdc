"""What the learned models know about a push besides the state: `PushContext` (the first
frame's mask and pose, the push, the camera, the footprint, the pad's track) and its builders.

The filters pass a context through unchanged (`filters.interfaces`); the black-box models
(`models.learned`) and the physics-structured ones (`models.physics`) both read it.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import overload

import torch

from pushtoknow.common.camera import CameraModel
from pushtoknow.common.errors import ShapeError
from pushtoknow.filters.tensor_shapes import expect_shape
from pushtoknow.geometry.action_maps import ActionMapConfig, action_map

STEADY_ACCEL = 0.05  # m/s²: pad accelerations below this are a steady push (tracking noise)


@overload
def _map_field(t: torch.Tensor, fn: Callable[[torch.Tensor], torch.Tensor]) -> torch.Tensor: ...
@overload
def _map_field(
    t: torch.Tensor | None, fn: Callable[[torch.Tensor], torch.Tensor]
) -> torch.Tensor | None: ...
def _map_field(t, fn):
    """fn applied to a context field, which may be None."""
    return None if t is None else fn(t)


@dataclass(frozen=True)
class PushContext:
    """Per-batch inputs of the learned models for one push (opaque to the filter).

    mask0 (B, 1, H, W): S_0 in [0, 1] from the first frame; pose0 (B, 3): pose at the first
    frame (m, m, rad); contact_xy (B, 2): where the action map is centred (m, world; the push's
    contact point, or the pusher's current position if the caller moves it along the push);
    direction (B,): push direction (rad, world); speed (B,): push speed (m/s); camera: the
    camera model of the images; footprint (B, V, 2) or None: footprint polygon (m, object
    frame), used by `ComInFootprintConstraint`; pad_window (B, 4, 2) or None: the pad's
    positions at samples t-2, t-1, t, t+1 around the step that ends at t (m, world; the
    robot's kinematics, see `with_pad_track`), step_dt the time between samples (s): the
    physics-structured models read the pad's velocity and acceleration from them;
    release (B, 3) or None: when each push's pad starts to stop, its speed then and its
    deceleration (`testbed.push.release_point`; t_r = inf for a push that never stops), and
    time (B,) or None: the time of sample t since the push began (s), for the free slide of
    a released object (`models.physics.PhysicsDynamics.release_step`).
    """

    mask0: torch.Tensor
    pose0: torch.Tensor
    contact_xy: torch.Tensor
    direction: torch.Tensor
    speed: torch.Tensor
    camera: CameraModel
    footprint: torch.Tensor | None = None
    pad_window: torch.Tensor | None = None
    step_dt: float = 0.1
    release: torch.Tensor | None = None
    time: torch.Tensor | None = None
    _cache: dict = field(default_factory=dict, init=False, repr=False, compare=False)

    def action_map(self, config: ActionMapConfig, dtype: torch.dtype) -> torch.Tensor:
        """M_t (B, 1, H, W) of this push (`geometry.action_maps.action_map`). Cached per
        (config, dtype) unless a push tensor requires grad."""
        key = (config, dtype)
        needs_grad = any(t.requires_grad for t in (self.contact_xy, self.direction, self.speed))
        if needs_grad or key not in self._cache:
            amap = action_map(
                self.contact_xy.to(dtype),
                self.direction.to(dtype),
                self.speed.to(dtype),
                self.camera,
                config,
            )
            if needs_grad:
                return amap
            self._cache[key] = amap
        return self._cache[key]

    def validate(self, batch: int) -> None:
        """Raise `ShapeError` unless every tensor has batch size `batch` and its shape above."""
        cam = self.camera
        expect_shape(
            self.mask0,
            "context.mask0",
            [("B", batch), ("1", 1), ("H", cam.height), ("W", cam.width)],
        )
        expect_shape(self.pose0, "context.pose0", [("B", batch), ("3", 3)])
        expect_shape(self.contact_xy, "context.contact_xy", [("B", batch), ("2", 2)])
        expect_shape(self.direction, "context.direction", [("B", batch)])
        expect_shape(self.speed, "context.speed", [("B", batch)])
        if self.footprint is not None:
            expect_shape(self.footprint, "context.footprint", [("B", batch), ("V", None), ("2", 2)])
        if self.pad_window is not None:
            expect_shape(self.pad_window, "context.pad_window", [("B", batch), ("4", 4), ("2", 2)])
        if self.release is not None:
            expect_shape(self.release, "context.release", [("B", batch), ("3", 3)])
        if self.time is not None:
            expect_shape(self.time, "context.time", [("B", batch)])

    def pad_kinematics(self) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
        """The pad's velocity over the step (B, 2) (m/s, backward difference t-1 → t) and its
        accelerations at t and at t-1 (B, 2) (m/s², centred differences), world frame."""
        if self.pad_window is None:
            raise ShapeError("this model needs the pad's track: build contexts with with_pad_track")
        w, dt = self.pad_window, self.step_dt
        velocity = (w[:, 2] - w[:, 1]) / dt
        accel = (w[:, 3] - 2 * w[:, 2] + w[:, 1]) / dt**2
        accel_prev = (w[:, 2] - 2 * w[:, 1] + w[:, 0]) / dt**2
        return velocity, accel, accel_prev

    def pad_accelerating(self) -> torch.Tensor:
        """(B,) bool: the pad's acceleration at t or t-1 exceeds `STEADY_ACCEL` (the step is
        part of a push's dynamic phase)."""
        _, accel, accel_prev = self.pad_kinematics()
        return (accel.norm(dim=-1) > STEADY_ACCEL) | (accel_prev.norm(dim=-1) > STEADY_ACCEL)

    def to(self, dtype: torch.dtype | None = None, device: torch.device | str | None = None):
        """A copy with every tensor moved to dtype/device."""

        def mv(t):
            return _map_field(t, lambda x: x.to(device=device, dtype=dtype))

        return PushContext(
            mv(self.mask0),
            mv(self.pose0),
            mv(self.contact_xy),
            mv(self.direction),
            mv(self.speed),
            self.camera,
            mv(self.footprint),
            mv(self.pad_window),
            self.step_dt,
            mv(self.release),
            mv(self.time),
        )

    def repeat_interleave(self, times: int) -> PushContext:
        """A copy with every tensor's rows repeated `times` times each (batch B → B·times,
        object i's rows at i·times … i·times + times − 1)."""

        def rep(t):
            return _map_field(t, lambda x: x.repeat_interleave(times, dim=0))

        return PushContext(
            rep(self.mask0),
            rep(self.pose0),
            rep(self.contact_xy),
            rep(self.direction),
            rep(self.speed),
            self.camera,
            rep(self.footprint),
            rep(self.pad_window),
            self.step_dt,
            rep(self.release),
            rep(self.time),
        )


def pad_windows(paths: torch.Tensor, t: torch.Tensor | int) -> torch.Tensor:
    """Pad positions at samples t-2, t-1, t, t+1 (B, 4, 2) from pad paths (B, T, 2) (m) and
    sample indices t (B,) or one int. Beyond either end the path is extended at constant
    velocity (a recorded push ends while the pad still moves at its push speed)."""
    b, n, _ = paths.shape
    before = 2 * paths[:, :1] - paths[:, 1:2]
    first = torch.cat([2 * before - paths[:, :1], before], dim=1)
    last = 2 * paths[:, -1:] - paths[:, -2:-1]
    ext = torch.cat([first, paths, last], dim=1)  # sample s at index s + 2
    t = torch.as_tensor(t, device=paths.device).long().expand(b)
    if int(t.min()) < 0 or int(t.max()) >= n:
        raise IndexError(f"sample index outside the path of {n} samples")
    idx = t[:, None] + torch.arange(4, device=paths.device)  # s - 2 .. s + 1, shifted by 2
    return ext.gather(1, idx[..., None].expand(b, 4, 2))


def with_pad_track(
    context: PushContext, paths: torch.Tensor, t: torch.Tensor | int, step_dt: float
) -> PushContext:
    """`context` for the step that ends at sample t of pad paths (B, T, 2) (m, world): the pad
    at its position at t, its window for the pad's velocity and acceleration, and the time
    t · step_dt."""
    b = paths.shape[0]
    t_b = torch.as_tensor(t, device=paths.device).long().expand(b)
    return dataclasses.replace(
        context,
        contact_xy=paths[torch.arange(b, device=paths.device), t_b],
        pad_window=pad_windows(paths, t_b),
        step_dt=float(step_dt),
        time=t_b.to(paths.dtype) * float(step_dt),
    )
