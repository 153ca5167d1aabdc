"""Inference on a novel object (docs/DESIGN.md §9): K pushes, the parameter posterior carried over.

Per push k:
1. The executor shows the object at rest: S_0 and the first RGB-D frame.
2. The pose at the push's start, pose0: for the first push the object frame is *defined* by
   the given initial pose (in simulation the true pose: CoM and inertia are reported in the
   object's geometric frame, so the frame must match the truth's); without one, the frame is
   S_0's centroid with θ = 0. For later pushes VisNet measures it, comparing the new image
   with the previous push's S_0 at a reference pose = the previous posterior pose moved by
   the executor's re-centring translation.
3. The policy picks a push among affordances of S_0; the executor runs it.
4. The filter runs over the push at 10 Hz: the belief starts at N(pose0, diag(init std²)) ×
   the parameter posterior of the previous push (the catalogue prior before the first);
   VisNet's reference pose at each frame is the filter's predicted mean; z = (VisNet pose,
   measured force) (V-DDF: pose only); the update runs every `update_every` samples.
5. The parameter marginal is the estimate; it becomes the next push's prior.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np
import torch
from pydantic import Field
from scipy.stats import norm

from pushtoknow.common.config import Config
from pushtoknow.common.errors import UntrainedProfileError
from pushtoknow.common.params import (
    PARAM_NAMES,
    denormalise_params,
    normalise_params,
    si_moments,
)
from pushtoknow.common.policies import PolicyName
from pushtoknow.geometry.affordances import mask_contour
from pushtoknow.inference.policies import (
    PushDecision,
    PushPolicy,
    candidate_pushes,
    make_policy,
)
from pushtoknow.models.calibration import keep_evidence
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.models.learned import PushContext, with_pad_track
from pushtoknow.perception.footprint import footprint_seen
from pushtoknow.perception.visnet import frames_as_tensors, visnet_measure
from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.executor import PushExecutor, SimulatedExecutor, View
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.push import PROFILES, ProfileName, Push, release_points
from pushtoknow.testbed.sim import PushRecord


class InferenceConfig(Config):
    pushes: int = Field(5, ge=1)
    policy: PolicyName = "uniform"
    candidates: int = Field(16, ge=1, description="affordances sampled per push decision")
    num_sigma_points: int | None = Field(None, ge=10, description="None: the model's")
    init_pose_std: tuple[float, float, float] = Field(
        (0.002, 0.002, 0.03), description="pose std at a push's start (m, m, rad)"
    )
    active_horizon_fraction: float = Field(0.5, gt=0, le=1)
    profiles: tuple[ProfileName, ...] = Field(
        ("constant",),
        min_length=1,
        description="speed profiles the policy may use: each candidate gets one (in turn); "
        "uniform cycles through them push by push, random draws one",
    )


def profile_speeds(sim_config: SimConfig) -> dict[str, float]:
    """The characteristic speed v (m/s) of each profile under the testbed's push settings."""
    return {p: sim_config.push.profile_speed(p) for p in PROFILES}


INTERVAL_LEVEL = 0.9  # the interval every estimate reports
COM_SLICE = slice(PARAM_NAMES.index("com_x"), PARAM_NAMES.index("com_y") + 1)
COM_MARGIN_PX = 1.0  # a reported CoM lies this many image pixels inside the footprint seen


@dataclass
class PushEstimate:
    """The parameter belief after push `index` (1-based; 0 = the prior): Gaussian over the
    normalised parameters, mean_norm (K,), cov_norm (K, K); mean/std (K,) are its SI moments
    (log-normal for m, μ and I_z, so always positive), in PARAM_NAMES order."""

    index: int
    mean: np.ndarray
    std: np.ndarray
    mean_norm: np.ndarray
    cov_norm: np.ndarray
    push: Push | None = None

    @property
    def std_norm(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diagonal(self.cov_norm), 0.0, None))

    def interval(self, level: float = INTERVAL_LEVEL) -> tuple[np.ndarray, np.ndarray]:
        """Equal-tailed SI interval (lo, hi) (K,) holding `level` of the belief (asymmetric
        for m, μ and I_z)."""
        k = float(norm.ppf(0.5 + level / 2))
        lo = denormalise_params(self.mean_norm - k * self.std_norm)
        return lo, denormalise_params(self.mean_norm + k * self.std_norm)

    def zscore(self, truth: np.ndarray) -> np.ndarray:
        """(K,) standardised error of an SI truth in the belief's own (normalised) space: the
        truth lies in the level-L interval iff |zscore| ≤ the two-sided L quantile."""
        z = normalise_params(np.asarray(truth, dtype=np.float64))
        return (z - self.mean_norm) / np.maximum(self.std_norm, 1e-12)

    def as_dict(self) -> dict:
        lo, hi = self.interval()
        key = f"interval{round(100 * INTERVAL_LEVEL)}"
        return {
            n: {"mean": float(m), "std": float(s), key: [float(a), float(b)]}
            for n, m, s, a, b in zip(PARAM_NAMES, self.mean, self.std, lo, hi, strict=True)
        }


@dataclass
class InferenceResult:
    """prior: the belief before any push; estimates: one per push; truth: SI (K,) or None;
    records: the executed pushes; poses: the filtered pose means (T, 3) of each push."""

    prior: PushEstimate
    estimates: list[PushEstimate]
    truth: np.ndarray | None
    records: list[PushRecord] = field(default_factory=list)
    poses: list[np.ndarray] = field(default_factory=list)
    object_name: str = ""

    def to_json(self) -> dict:
        out: dict = {
            "object": self.object_name,
            "prior": {"estimate": self.prior.as_dict()},
            "pushes": [
                {
                    "estimate": e.as_dict(),
                    "push": None if e.push is None else _push_dict(e.push),
                }
                for e in self.estimates
            ],
            "truth": None
            if self.truth is None
            else {n: float(v) for n, v in zip(PARAM_NAMES, self.truth, strict=True)},
        }
        return out


def _push_dict(p: Push) -> dict:
    return {
        "contact": [float(c) for c in p.contact],
        "direction": float(p.direction),
        "profile": p.profile,
        "speed": float(p.speed),
    }


def keep_inside(point: np.ndarray, polygon: np.ndarray, margin: float) -> np.ndarray:
    """(2,) point moved to the nearest point at least `margin` (m) inside polygon (V, 2), or
    returned unchanged if it already is; for a polygon too thin for the margin, its centroid."""
    from shapely.geometry import Point, Polygon

    poly = Polygon(polygon).buffer(0)  # a resampled outline may touch itself
    inner = poly.buffer(-margin)
    p = Point(*point)
    if inner.is_empty:
        return np.asarray(poly.centroid.coords[0])
    if inner.contains(p):
        return np.asarray(point, dtype=np.float64)
    if inner.geom_type != "Polygon":
        inner = min(inner.geoms, key=lambda g: g.distance(p))
    ring = inner.exterior
    q = np.asarray(ring.interpolate(ring.project(p)).coords[0])
    # a hair inside the eroded region, so the point is strictly inside the footprint
    c = np.asarray(inner.representative_point().coords[0])
    return q + 1e-6 * (c - q) / max(np.linalg.norm(c - q), 1e-12)


def belief_to_estimate(index: int, mean: torch.Tensor, cov: torch.Tensor, push=None):
    """Normalised parameter belief (K,), (K, K) → `PushEstimate` (SI moments)."""
    m = mean.detach().double().numpy()
    c = cov.detach().double().numpy()
    si, std = si_moments(m, c)
    return PushEstimate(index, si, std, m, c, push)


class ObjectEstimator:
    """Runs the trained filter on pushes of one object; see the module docstring."""

    def __init__(self, model: TrainedModel, config: InferenceConfig = InferenceConfig(), seed=0):
        self.model = model.eval()
        self.config = config
        self.filter = model.build_filter(config.num_sigma_points)
        self.filter.eval()
        self.camera = model.camera
        self.gen = torch.Generator().manual_seed(seed)
        self.rng = np.random.default_rng(seed)
        self.num_sigma_points = config.num_sigma_points or model.inference.num_sigma_points
        self.param_mean = model.prior.mean.clone()
        self.param_cov = model.prior.cov.clone()
        self._prev: tuple[np.ndarray, np.ndarray] | None = None  # (S_0, pose0) of last push
        self._last_pose: np.ndarray | None = None
        self._footprint: torch.Tensor | None = None  # (V, 2) object frame, first push's S_0
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
        pushes: list[Push],
    ) -> PushContext:
        """PushContext for len(pushes) pushes of the object seen in `view` at pose0, pads at
        pad_xy (B, 2). The footprint is `perception.footprint.footprint_seen` in the view."""
        b = len(pushes)
        mask0 = torch.as_tensor(view.s0, dtype=torch.float32)[None, None].expand(b, -1, -1, -1)
        fp = footprint_seen(view.s0, view.depth, view.outline_mask, self.camera, pose0)
        fp = torch.as_tensor(fp, dtype=torch.float32)
        if self._footprint is None:  # the first push's view defines the object frame exactly;
            self._footprint = fp  # later ones depend on the estimated start θ
        return PushContext(
            mask0=mask0,
            pose0=torch.as_tensor(pose0, dtype=torch.float32)[None].expand(b, -1),
            contact_xy=pad_xy.float(),
            direction=torch.tensor([p.direction for p in pushes], dtype=torch.float32),
            speed=torch.tensor([p.speed for p in pushes], dtype=torch.float32),
            camera=self.camera,
            footprint=fp[None].expand(b, -1, -1),
            release=torch.as_tensor(
                release_points(pushes, self.model.sim_config.push), dtype=torch.float32
            ),
        )

    def estimate(self, index: int, push: Push | None = None) -> PushEstimate:
        """The parameter belief as an estimate. m, μ and I_z are positive by construction
        (log space); the reported CoM mean is kept inside the footprint seen before the first
        push (the view that defines the object frame), at least an image pixel (9 mm) from its
        outline (traced to a few millimetres, its corners rounded by about 5 mm): if
        the Gaussian's mean lies closer to the outline or outside, it is moved to the nearest
        such point, as the mean of the belief restricted to the footprint would be."""
        est = belief_to_estimate(index, self.param_mean, self.param_cov, push)
        if self._footprint is not None:
            margin = COM_MARGIN_PX * self.camera.metres_per_pixel()
            est.mean[COM_SLICE] = keep_inside(est.mean[COM_SLICE], self._footprint.numpy(), margin)
        return est

    @torch.no_grad()
    def start_pose(self, view: View, initial_pose: np.ndarray | None) -> np.ndarray:
        """pose0 of the next push (see module docstring, step 2)."""
        if self._prev is None:
            if initial_pose is not None:
                return np.asarray(initial_pose, dtype=float)
            c = mask_contour(view.s0, self.camera).centroid
            return np.array([c[0], c[1], 0.0])
        s0_prev, pose0_prev = self._prev
        ref = self._last_pose.copy()
        if view.moved_by is not None:
            ref[:2] += np.asarray(view.moved_by)
        rgbd = frames_as_tensors(view.rgb[None], view.depth[None], self.camera)
        meas = visnet_measure(
            self.model.visnet,
            rgbd,
            torch.as_tensor(s0_prev, dtype=torch.float32)[None, None],
            torch.as_tensor(pose0_prev, dtype=torch.float32)[None],
            torch.as_tensor(ref, dtype=torch.float32)[None],
            self.camera,
        )
        return meas[0].double().numpy()

    @torch.no_grad()
    def filter_push(self, rec: PushRecord, view: View, pose0: np.ndarray) -> np.ndarray:
        """Run the filter over one executed push of the object seen in `view` before it;
        updates the parameter belief. Returns the filtered pose means (T, 3)."""
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


def infer_object(
    model: TrainedModel,
    executor: PushExecutor,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    initial_pose: np.ndarray | None = None,
    truth: np.ndarray | None = None,
    object_name: str = "",
    on_push=None,
    policy: PushPolicy | None = None,
) -> InferenceResult:
    """K pushes on the executor's object with `model`; `on_push(estimate)` after each push.

    `policy` chooses each push (default: `make_policy(config.policy)` with the model's testbed
    settings). Speed profiles the model never saw in training are refused: its estimates on
    them are extrapolation (a constant-push model's CoM error more than doubles on release
    pushes, with 90% coverage near 0.7)."""
    trained = model.info.get("profiles")
    unseen = sorted(set(config.profiles) - set(trained or config.profiles))
    if unseen:
        raise UntrainedProfileError(
            f"profiles {', '.join(unseen)}: the model was trained on {', '.join(trained)} "
            "pushes only; train it on data with those profiles (pushtoknow simulate --profiles)"
        )
    if policy is None:
        policy = make_policy(config.policy, model.sim_config, config.active_horizon_fraction)
    est = ObjectEstimator(model, config, seed)
    speeds = profile_speeds(model.sim_config)
    result = InferenceResult(est.estimate(0), [], truth, object_name=object_name)
    for k in range(config.pushes):
        view = executor.observe()
        pose0 = est.start_pose(view, initial_pose)
        cands, contacts = candidate_pushes(
            view, est.camera, config.candidates, est.rng, speeds, config.profiles
        )
        decision = PushDecision(
            k,
            config.pushes,
            cands,
            contacts,
            view,
            est.camera,
            pose0,
            est.rng,
            config.profiles,
            speeds,
            est,
        )
        push = policy.choose(decision)
        rec = executor.execute(push)
        result.poses.append(est.filter_push(rec, view, pose0))
        result.records.append(rec)
        e = est.estimate(k + 1, push)
        result.estimates.append(e)
        if on_push is not None:
            on_push(e)
    return result


def infer_simulated(
    model: TrainedModel,
    spec: ObjectSpec,
    config: InferenceConfig = InferenceConfig(),
    seed: int = 0,
    with_truth: bool = True,
    on_push=None,
    policy: PushPolicy | None = None,
) -> InferenceResult:
    """`infer_object` on the testbed: `spec` simulated with the model's testbed settings,
    recentred under the camera, seeded by `seed`, the first push starting from its true pose
    (so the CoM and I_z compare with the truth, reported when `with_truth`)."""
    executor = SimulatedExecutor(spec, model.sim_config, seed=seed, recentre=True)
    try:
        return infer_object(
            model,
            executor,
            config,
            seed,
            initial_pose=executor.initial_pose,
            truth=spec.params.as_array() if with_truth else None,
            object_name=(spec.name or "") if with_truth else "",
            on_push=on_push,
            policy=policy,
        )
    finally:
        executor.close()
