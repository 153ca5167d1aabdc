"""The paper's learned dual filter as an `Estimator` (docs/DESIGN.md §9; the paper, §III).

Per push k:
1. The executor shows the object at rest: S_0 and the first RGB-D frame.
2. The pose at the push's start, pose0: for the first push the object frame is *defined* by
   the given initial pose (in simulation the true pose: CoM and inertia are reported in the
   object's geometric frame, so the frame must match the truth's); without one, the frame is
   S_0's centroid with θ = 0. For later pushes VisNet measures it, comparing the new image
   with the previous push's S_0 at a reference pose = the previous posterior pose moved by
   the executor's re-centring translation.
3. The filter runs over the push at 10 Hz: the belief starts at N(pose0, diag(init std²)) ×
   the parameter posterior of the previous push (the catalogue prior before the first);
   VisNet's reference pose at each frame is the filter's predicted mean; z = (VisNet pose,
   measured force) (V-DDF: pose only); the update runs every `update_every` samples.
4. The parameter marginal is the estimate; it becomes the next push's prior.
"""

from __future__ import annotations

import functools
from collections import Counter
from collections.abc import Mapping, Sequence

import numpy as np
import torch

from pushtoknow.active.information_policy import ActivePolicy
from pushtoknow.active.selection import ScoreName
from pushtoknow.common.errors import DatasetError, PushToKnowError
from pushtoknow.common.estimate import com_region
from pushtoknow.common.params import PARAM_RANGES
from pushtoknow.inference.estimator import (
    Estimator,
    InferenceConfig,
    PushEstimate,
    belief_to_estimate,
)
from pushtoknow.models.calibration import keep_evidence
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.models.context import PushContext, with_pad_track
from pushtoknow.perception.footprint import footprint_seen, object_top
from pushtoknow.perception.visnet import frames_as_tensors, start_pose, visnet_measure
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.objects import COM_MARGIN, MIN_HEIGHT
from pushtoknow.testbed.push import Push, pad_positions, release_points
from pushtoknow.testbed.shapes import CATALOGUE_SHAPES, Footprint, footprint_from_shape
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig


class LearnedFilterEstimator(Estimator):
    """The trained dual filter (VT-ADDF, VT-JDF or V-DDF) on pushes of one object; see the
    module docstring. `seed` seeds its torch generator (filter noise, active look-ahead);
    `sim_config`: the testbed settings the pushes run with (the look-ahead's pad paths;
    default: the model's)."""

    name = "vt-addf"

    def __init__(
        self,
        model: TrainedModel,
        config: InferenceConfig = InferenceConfig(),
        seed: int = 0,
        sim_config: SimConfig | None = None,
    ):
        self.model = model.eval()
        self.sim_config = sim_config or model.sim_config  # the pushes' testbed settings
        self.config = config
        self.filter = model.build_filter(config.num_sigma_points)
        self.filter.eval()
        self.camera = model.camera
        self.gen = torch.Generator().manual_seed(seed)
        self.num_sigma_points = config.num_sigma_points or model.inference.num_sigma_points
        self.param_mean = model.prior.mean.clone()
        self.param_cov = model.prior.cov.clone()
        self._prev: tuple[np.ndarray, np.ndarray] | None = None  # (S_0, pose0) of last push
        self._last_pose: np.ndarray | None = None
        self._footprint: torch.Tensor | None = None  # (V, 2) object frame, first push's S_0
        self._height = 0.0  # m, the first push's depth
        self._pushes_of: Counter[str] = Counter()  # pushes filtered so far, per speed profile

    def start_belief(self, pose0: np.ndarray) -> tuple[torch.Tensor, torch.Tensor]:
        """Belief (mean (1, D), cov (1, D, D)) at a push's start: N(pose0, init std²) × the
        current parameter belief."""
        k_dim = self.param_mean.shape[0]
        mean = torch.cat([torch.as_tensor(pose0, dtype=torch.float32), self.param_mean])[None]
        cov = torch.zeros(1, 3 + k_dim, 3 + k_dim)
        cov[0, :3, :3] = torch.diag(torch.tensor(self.config.init_pose_std).square())
        cov[0, 3:, 3:] = self.param_cov
        return mean, cov

    def context(
        self,
        view: View,
        pose0: np.ndarray,
        pad_xy: torch.Tensor,
        pushes: Sequence[Push],
    ) -> PushContext:
        """PushContext for len(pushes) pushes of the object seen in `view` at pose0, pads at
        pad_xy (B, 2). The footprint is `perception.footprint.footprint_seen` in the view."""
        b = len(pushes)
        mask0 = torch.as_tensor(view.s0, dtype=torch.float32)[None, None].expand(b, -1, -1, -1)
        fp = footprint_seen(view.s0, view.depth, view.outline_mask, self.camera, pose0)
        fp = torch.as_tensor(fp, dtype=torch.float32)
        if self._footprint is None:  # the first push's view defines the object frame exactly;
            self._keep_footprint(fp, view)  # later ones depend on the estimated start θ
        return PushContext(
            mask0=mask0,
            pose0=torch.as_tensor(pose0, dtype=torch.float32)[None].expand(b, -1),
            contact_xy=pad_xy.float(),
            direction=torch.tensor([p.direction for p in pushes], dtype=torch.float32),
            speed=torch.tensor([p.speed for p in pushes], dtype=torch.float32),
            camera=self.camera,
            footprint=fp[None].expand(b, -1, -1),
            release=torch.as_tensor(
                release_points(list(pushes), self.model.sim_config.push), dtype=torch.float32
            ),
        )

    def _keep_footprint(self, fp: torch.Tensor, view: View) -> None:
        """The footprint (V, 2) seen in the first push's view, and the height in its depth."""
        self._footprint = fp
        self._height = max(object_top(view.depth, view.s0, self.camera), MIN_HEIGHT)

    def see_object(self, view: View, pose0: np.ndarray) -> None:
        """The footprint seen in the first push's view (`perception.footprint.footprint_seen`)
        becomes the filter's context and bounds its estimates; the learned prior stays."""
        if self._footprint is None:
            fp = footprint_seen(view.s0, view.depth, view.outline_mask, self.camera, pose0)
            self._keep_footprint(torch.as_tensor(fp, dtype=torch.float32), view)

    def estimate(self, index: int, push: Push | None = None) -> PushEstimate:
        """The parameter belief as an estimate. m, μ and I_z are positive by construction
        (log space); once the first push's view (which defines the object frame) is seen, the
        CoM's belief is truncated to the convex hull of the footprint seen there, less the
        testbed's margin, and I_z's with m's to I_z ≤ m·r² on that footprint
        (`common.estimate`): means and intervals come from those distributions."""
        region = outline = None
        if self._footprint is not None:
            outline = self._footprint.numpy().astype(np.float64)
            region = com_region(outline, COM_MARGIN)
        return belief_to_estimate(index, self.param_mean, self.param_cov, push, region, outline)

    def seen_object(self) -> tuple[np.ndarray, float] | None:
        """The footprint seen at the first push (the filter's context) and the object's height
        in that push's depth."""
        if self._footprint is None:
            return None
        return self._footprint.numpy().astype(np.float64), self._height

    def start_pose(self, view: View, initial_pose: np.ndarray | None) -> np.ndarray:
        """pose0 of the next push (`perception.visnet.start_pose`)."""
        previous = None if self._prev is None else (*self._prev, self._last_pose)
        return start_pose(self.model.visnet, self.camera, view, initial_pose, previous)

    @torch.no_grad()
    def update(self, record: PushRecord, view: View | None, pose0: np.ndarray) -> np.ndarray:
        """Run the filter over one executed push of the object seen in `view` before it;
        updates the parameter belief. Returns the filtered pose means (T, 3). Raises
        DatasetError for a push without images (the filter measures the pose with VisNet)."""
        if view is None or record.rgb is None:
            raise DatasetError(
                "a push without images",
                f"the learned filter ({self.name}) measures the pose in RGB-D frames; the "
                "physics estimator runs on tracked poses",
            )
        rec = record
        filt, cam = self.filter, self.camera
        mean, cov = self.start_belief(pose0)
        base = self.context(view, pose0, torch.zeros(1, 2), [rec.push])
        frames = frames_as_tensors(rec.rgb, rec.depth, cam)
        pusher = torch.as_tensor(rec.pusher, dtype=torch.float32)
        tactile = torch.as_tensor(rec.tactile, dtype=torch.float32)
        every = self.model.inference.update_every
        dt = 1.0 / self.model.sim_config.tactile.rate_hz
        steps = len(rec.time) - 1
        poses = [mean[0, :3].numpy().copy()]
        for t in range(1, steps + 1):
            ctx = with_pad_track(base, pusher[None], t, dt)
            noise = filt.draw_noise(1, self.gen, num_sigma_points=self.num_sigma_points)
            mean, cov = filt.predict(mean, cov, ctx, noise)
            if t % every == 0 or t == steps:
                z_pose = visnet_measure(
                    self.model.visnet, frames[t : t + 1], base.mask0, base.pose0, mean[:, :3], cam
                )
                z = (
                    z_pose
                    if self.model.vision_only
                    else torch.cat([z_pose, tactile[t : t + 1, :2]], -1)
                )
                mean, cov, _ = filt.update(mean, cov, z, ctx, noise)
            poses.append(mean[0, :3].numpy().copy())
        self._pushes_of[rec.push.profile] += 1
        weights = self.model.inference.kept_evidence(
            rec.push.profile, self._pushes_of[rec.push.profile]
        )
        param_mean, param_cov = keep_evidence(
            self.param_mean[None], self.param_cov[None], mean[:, 3:], cov[:, 3:, 3:], weights
        )
        self.param_mean = param_mean[0].clone()
        self.param_cov = param_cov[0].clone()
        self._prev = (view.s0, pose0)
        self._last_pose = mean[0, :3].double().numpy()
        return np.stack(poses)

    @torch.no_grad()
    def information(
        self,
        candidates: Sequence[Push],
        view: View,
        pose0: np.ndarray,
        score: ScoreName,
        horizon_fraction: float,
    ) -> np.ndarray:
        """N-step score (`active.information_policy.ActivePolicy`) of each candidate: rollouts
        of this filter over the candidates' commanded pad paths (`testbed.push.pad_positions`),
        all candidates in one batch, over N = horizon_fraction of a push's steps."""
        sim_config = self.sim_config
        dt = 1.0 / sim_config.tactile.rate_hz
        steps = int(round(sim_config.push.horizon * sim_config.tactile.rate_hz))
        selector = ActivePolicy(self.filter, steps, score, horizon_fraction, self.num_sigma_points)
        mean, cov = self.start_belief(pose0)
        times = np.arange(steps + 1) * dt
        paths = torch.as_tensor(
            np.stack([pad_positions(p, times, sim_config.push) for p in candidates]),
            dtype=torch.float32,
        )  # (M, T, 2)
        base = self.context(view, pose0, paths[:, 0], candidates)

        def builder(_: object, step: int) -> PushContext:
            return with_pad_track(base, paths, step + 1, dt)

        scores = selector.scores(candidates, mean, cov, builder, self.gen)
        return scores.double().numpy()


TRAINING_MARGIN = 0.1  # relative: a reading this far beyond the training range lies outside it


@functools.lru_cache(maxsize=4)
def _dataset_footprint_bounds(
    objects_from: str, objects: int, seed: int
) -> tuple[tuple[float, float], tuple[float, float]]:
    """((lo, hi) largest radius from the object frame's origin (m), (lo, hi) area (m²)) over a
    dataset's objects (`datasets.generate.select_objects`)."""
    from pushtoknow.datasets.generate import select_objects

    shapes = [s.footprint for s in select_objects(objects_from, objects, seed)]
    return _bounds(shapes)


def _bounds(shapes: Sequence[Footprint]) -> tuple[tuple[float, float], tuple[float, float]]:
    radius = [s.max_radius_from((0.0, 0.0)) for s in shapes]
    area = [s.polygon.area for s in shapes]
    return (min(radius), max(radius)), (min(area), max(area))


def training_footprint_bounds(
    info: Mapping | None,
) -> tuple[tuple[float, float], tuple[float, float]]:
    """((lo, hi) largest radius from the object frame's origin (m), (lo, hi) area (m²)) of the
    footprints a model was trained on: its dataset's objects, regenerated from the provenance
    its checkpoint records (`TrainedModel.info`: objects_from, objects, data_seed); the
    catalogue's shapes (`testbed.objects.CATALOGUE_SHAPES`) where that provenance is missing
    or names objects that cannot be regenerated (a file since moved)."""
    info = info or {}
    source, n, seed = info.get("objects_from"), info.get("objects"), info.get("data_seed")
    if isinstance(source, str) and isinstance(n, int) and isinstance(seed, int):
        try:
            return _dataset_footprint_bounds(source, n, seed)
        except (PushToKnowError, OSError, ValueError):
            pass
    return _bounds([footprint_from_shape(s) for s in CATALOGUE_SHAPES.values()])


def outside_training(
    records: Sequence[PushRecord],
    footprint: Footprint | None,
    sim_config: SimConfig,
    training: Mapping | None = None,
) -> tuple[str, ...]:
    """Why an object lies outside what the learned filter was trained on (its training
    objects' footprints, `training_footprint_bounds` of `training`, the checkpoint's
    `TrainedModel.info`, and the parameter ranges, `common.params.PARAM_RANGES`), read off the
    object and its pushes without its truth; empty where nothing shows it. Each reason is one
    sentence:
    - μ·m from the steady force of a constant push (`identification.fit.closed_form_start`; at
      most μ·m on an off-centre push) above the largest training μ·m, or below half the least;
    - m or μ read off a release push outside their training ranges;
    - the footprint (`footprint`: seen or known, object frame) larger or smaller than every
      training shape (its largest radius from the centroid, its area).
    sim_config: the settings the pushes were made with (their release profile).
    Margins: `TRAINING_MARGIN`."""
    from pushtoknow.identification.fit import closed_form_start

    reasons = []
    (m0, m1), (f0, f1) = PARAM_RANGES["mass"], PARAM_RANGES["friction"]
    grow, shrink = 1.0 + TRAINING_MARGIN, 1.0 - TRAINING_MARGIN
    reading = closed_form_start(records, sim_config)
    mu_m = reading.mu_m
    if mu_m is not None and not 0.5 * m0 * f0 * shrink <= mu_m <= m1 * f1 * grow:
        reasons.append(
            f"μ·m ≈ {mu_m:.3g} kg from the steady push force, outside the "
            f"{0.5 * m0 * f0:.3g}–{m1 * f1:.3g} kg the training objects' pushes read (half "
            f"their least μ·m, {m0 * f0:.3g} kg, on an off-centre push, to their largest)"
        )
    for name, v, (lo, hi), unit in (
        ("mass", reading.mass, (m0, m1), " kg"),
        ("friction", reading.friction, (f0, f1), ""),
    ):
        if v is not None and not lo * shrink <= v <= hi * grow:
            reasons.append(
                f"{name} ≈ {v:.3g}{unit} from a release push, outside the training range "
                f"{lo:g}–{hi:g}{unit}"
            )
    if footprint is not None:
        radius, area = training_footprint_bounds(training)
        for what, value, (lo, hi), unit, scale in (
            ("largest radius", footprint.max_radius_from((0.0, 0.0)), radius, "cm", 100.0),
            ("area", footprint.polygon.area, area, "cm²", 1e4),
        ):
            if not lo * shrink <= value <= hi * grow:
                reasons.append(
                    f"its footprint's {what} {value * scale:.3g} {unit} is outside the training "
                    f"shapes' {lo * scale:.3g}–{hi * scale:.3g} {unit}"
                )
    return tuple(reasons)
