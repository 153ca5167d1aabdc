"""The physics filter: a dual filter whose model is the simulator (docs/DESIGN.md §12), as an
`Estimator`.

Perception is the learned filter's (the paper's dual structure), except for the outline: the
footprint is traced on the first push's mask with its corners kept sharp
(`perception.footprint.replay_outline`) and fixes the object frame; a later push's start
pose is VisNet's refined geometrically, the first push's contour registered to the push's
mask (`perception.registration.register`); each push's pose track is VisNet's from there,
frame by frame, each frame's reference pose the previous measurement, and its end pose, at rest
after the push, is registered the same way on the outline mask taken then (`end_pose`).
With `PhysicsFilterConfig.outline_views` set, once that many views are registered (the first
push's and each push's end) the replayed outline is traced again from all of them together
(`perception.footprint.fused_outline`: the pixel staircase falls elsewhere in each), once, and
the pushes before are refit on it.
The parameter belief (a Gaussian over `identification.prior.fit_transform`'s coordinates,
starting at the prior of the footprint seen, `identification.prior.footprint_prior`) is
updated after each push by replaying it in the testbed's scene with that footprint
(`identification.recursive.iterated_update`), carried to the next push; up to
`PhysicsFilterConfig.max_refits` times per object (2 by default), a push the replay cannot
reproduce from the belief refits every push so far from the prior
(`identification.recursive.refit`), kept when it explains them much better. Active policies score
candidates by the entropy the same update would remove, from replays of the candidates at the
belief's mean (`identification.recursive.expected_information`).
"""

from __future__ import annotations

import dataclasses
import logging
from collections.abc import Sequence

import numpy as np
import torch

from pushtoknow.active.selection import ScoreName
from pushtoknow.common.angles import wrap_angle
from pushtoknow.common.errors import DatasetError
from pushtoknow.common.estimate import com_region
from pushtoknow.common.params import denormalise_params, normalise_params, space_scale
from pushtoknow.identification.fit import (
    UNKNOWN_FORCE_NOISE,
    closed_form_start,
    tracks_from_records,
)
from pushtoknow.identification.prior import (
    fit_transform,
    footprint_prior,
    polygon_moments,
    prior_moments,
)
from pushtoknow.identification.recursive import (
    PhysicsFilterConfig,
    PhysicsUpdate,
    expected_information,
    iterated_update,
    refit,
)
from pushtoknow.identification.replay import PushTrack, ReplayScene, RolloutPool, shared_pool
from pushtoknow.inference.estimator import (
    Estimator,
    InferenceConfig,
    PushEstimate,
    belief_to_estimate,
)
from pushtoknow.models.checkpoint import TrainedModel
from pushtoknow.perception.footprint import (
    fused_outline,
    object_top,
    outline_contour,
    outline_shape,
    replay_contour,
    replay_outline,
    to_object_frame,
)
from pushtoknow.perception.registration import outline_points, register
from pushtoknow.perception.visnet import start_pose, visnet_poses
from pushtoknow.testbed.executor import View
from pushtoknow.testbed.objects import COM_MARGIN, MIN_HEIGHT
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim import PushRecord
from pushtoknow.testbed.sim_config import SimConfig

log = logging.getLogger(__name__)


class PhysicsFilterEstimator(Estimator):
    """The simulator-in-the-loop dual filter on pushes of one object (module doc). `model`
    provides perception (VisNet, camera); `sim_config`: the testbed settings the pushes run
    with; `seed` has nothing to draw (the update is deterministic); `scene`: the object's
    outline and height when known (a recording's), instead of the one traced in the first
    view."""

    name = "physics"

    def __init__(
        self,
        model: TrainedModel,
        config: InferenceConfig = InferenceConfig(),
        seed: int = 0,
        sim_config: SimConfig | None = None,
        filter_config: PhysicsFilterConfig | None = None,
        scene: ReplayScene | None = None,
    ):
        self.model = model.eval()
        self.config = config
        self.filter_config = filter_config or PhysicsFilterConfig()
        self.sim_config = (sim_config or model.sim_config).model_copy(update={"render": False})
        self.camera = model.camera
        self.tmat = fit_transform()
        self.t_inv = np.linalg.inv(self.tmat)
        z, p_z = prior_moments(self.filter_config.prior)
        self.mean = self.prior_mean = self.tmat @ z
        self.cov = self.prior_cov = self.tmat @ p_z @ self.tmat.T
        self.scene: ReplayScene | None = None
        self.com_region: np.ndarray | None = None  # (V, 2) where the CoM can lie, scene frame
        if scene is not None:
            self._use_scene(scene)
        self.updates: list[PhysicsUpdate] = []
        self.tracks: list[PushTrack] = []  # the pushes seen, as replayed
        self._refits_tried = 0
        self._pool: RolloutPool | None = None
        self._prev: tuple[np.ndarray, np.ndarray] | None = None  # (S_0, pose0) of last push
        self._last_pose: np.ndarray | None = None
        self._outline: np.ndarray | None = None  # (N, 2) first view's contour, object frame
        self._top: float | None = None  # m: the object's top seen in the first view
        # outline masks and their poses (pose0 frame) the outline is refined from; None where
        # the outline was given or a view lacks the outline-resolution mask
        self._views: list[tuple[np.ndarray, np.ndarray]] | None = None
        self._frame: np.ndarray | None = None  # (2,) the scene frame's origin, pose0 frame
        cfg = self.filter_config
        tactile = self.sim_config.tactile.force_noise_std
        force = cfg.force_noise or (tactile if tactile > 0 else UNKNOWN_FORCE_NOISE)
        self.sigmas = np.array(
            [force, force, cfg.position_noise, cfg.position_noise, cfg.angle_noise]
        )

    @property
    def pool(self) -> RolloutPool:
        """The replay processes: this process's shared pool (`replay.shared_pool`), kept for
        the next object's estimator."""
        if self._pool is None:
            self._pool = shared_pool(self.filter_config.workers)
        return self._pool

    def replays(self) -> int:
        """Single-push replays the last update ran (`PhysicsUpdate.replays`)."""
        return self.updates[-1].replays if self.updates else 0

    def close(self) -> None:
        """Let go of the pool (the shared pool's processes stay for the next object)."""
        self._pool = None

    def belief_norm(self, cov_u: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The belief over the normalised parameters, the CoM in the object frame: mean (5,),
        cov (5, 5), of the filter's covariance or `cov_u` (5, 5) in fit coordinates. (The
        filter's own CoM is in the replayed outline's centroid frame.)"""
        cov = self.t_inv @ (self.cov if cov_u is None else cov_u) @ self.t_inv.T
        mean = self.t_inv @ self.mean
        if self.scene is not None:
            mean[2:4] += np.asarray(self.scene.frame_offset) / space_scale()[2:4]
        return mean, 0.5 * (cov + cov.T)

    def estimate(self, index: int, push: Push | None = None) -> PushEstimate:
        """The belief as an estimate, with the split of μ·m's floor (`split_floor`), the
        outline's placement error (`com_floor`) and the replay's I_z floor (`inertia_floor`)
        added in quadrature once pushes were seen."""
        cov_u = self.cov.copy()
        if self.updates:  # fit coordinates (`prior.fit_transform`): u_1 = z_m at fixed μ·m,
            # u_2..4 = z_cx, z_cy, z_Iz; each floor in the units of its parameter's scale
            cfg, scale = self.filter_config, space_scale()
            floors = np.array(
                [0.0, cfg.split_floor, cfg.com_floor, cfg.com_floor, cfg.inertia_floor]
            )
            cov_u[np.diag_indices(5)] += (floors / scale[[0, 0, 2, 3, 4]]) ** 2
        mean, cov = self.belief_norm(cov_u)
        region = outline = None
        if self.scene is not None:
            offset = np.asarray(self.scene.frame_offset)
            region = self.com_region + offset
            outline = self.scene.footprint.vertices + offset
        return belief_to_estimate(index, mean, cov, push, region, outline)

    def _scene(self, view: View | None, pose0: np.ndarray) -> ReplayScene:
        """The replay scene of the footprint seen in the first push's view (it fixes the
        object frame) at the height seen in its depth."""
        if self.scene is None:
            if view is None:
                raise DatasetError(
                    "a push without images",
                    "no outline given: the physics estimator needs the object's outline (a "
                    "recording's, or one traced in an image)",
                )
            contour = replay_contour(view.s0, view.depth, view.outline_mask, self.camera)
            height = max(object_top(view.depth, view.s0, self.camera), MIN_HEIGHT)
            shape, offset = outline_shape(replay_outline(contour, pose0))
            self._use_scene(ReplayScene(shape, height, self.sim_config, offset))
            if view.outline_mask is not None:
                self._views = [(view.outline_mask, np.asarray(pose0, dtype=np.float64))]
                self._frame = to_object_frame(contour.centroid[None], pose0[:2], pose0)[0]
        assert self.scene is not None
        return self.scene

    def see_object(self, view: View, pose0: np.ndarray) -> None:
        """The replay scene of the outline seen in the first push's view (`_scene`); the
        prior becomes its footprint's (`prior.footprint_prior`)."""
        self._scene(view, pose0)

    def _use_scene(self, scene: ReplayScene) -> None:
        """Replay pushes in `scene`; the prior becomes its footprint's."""
        self.scene = dataclasses.replace(scene, sim_config=self.sim_config)
        self.com_region = com_region(self.scene.footprint.vertices, COM_MARGIN)
        self._prior_from_footprint(self.scene)

    def _prior_from_footprint(self, scene: ReplayScene) -> None:
        """The prior once the footprint is seen (`prior.footprint_prior`): the CoM anywhere
        in its convex hull, I_z about the uniform plate's."""
        region = scene.footprint.com_region(COM_MARGIN)
        if region.is_empty or region.geom_type != "Polygon":
            return  # too thin for the margin: the catalogue prior stays
        _, plate = polygon_moments(scene.footprint.vertices)
        z, p_z = footprint_prior(
            np.asarray(region.exterior.coords)[:-1],
            float(np.sqrt(np.trace(plate))),
            self.filter_config.prior,
        )
        self.mean = self.prior_mean = self.tmat @ z
        self.cov = self.prior_cov = self.tmat @ p_z @ self.tmat.T

    def _refine_outline(self, mask: np.ndarray | None, pose: np.ndarray | None) -> bool:
        """Add a view of the object, its outline mask (kH, kW) seen at `pose` (3,); once
        `PhysicsFilterConfig.outline_views` are in, replay from the outline traced on all of
        them (`perception.footprint.fused_outline`) from now on, once per object: the belief's
        CoM moved into the new scene's frame, the prior's CoM recentred on its hull. Returns
        whether the outline changed."""
        views, least = self._views, self.filter_config.outline_views
        if views is None or least is None or self.scene is None or self._top is None:
            return False
        if mask is None or pose is None:
            self._views = None  # a view without the outline mask: keep the first view's
            return False
        views.append((mask, np.asarray(pose, dtype=np.float64)))
        if len(views) < least:
            return False
        self._views = None  # refined once
        masks, poses = zip(*views)
        fp = fused_outline(masks, poses, self.camera, self._top) - self._frame
        shape, offset = outline_shape(fp)
        z, cov = self.t_inv @ self.mean, self.cov
        z[2:4] += (np.asarray(self.scene.frame_offset) - offset) / space_scale()[2:4]
        self._use_scene(ReplayScene(shape, self.scene.height, self.sim_config, offset))
        self.mean, self.cov = self.tmat @ z, cov  # the belief stays; the prior is the new one's
        return True

    def seen_object(self) -> tuple[np.ndarray, float] | None:
        """The outline the pushes are replayed with (`replay_outline`) and its height."""
        if self.scene is None:
            return None
        verts = self.scene.footprint.vertices + np.asarray(self.scene.frame_offset)
        return verts, float(self.scene.height)

    def start_pose(self, view: View, initial_pose: np.ndarray | None) -> np.ndarray:
        """pose0 of the next push: VisNet's (`perception.visnet.start_pose`), refined by
        registering the first view's contour to this view's mask
        (`perception.registration.register`)."""
        previous = None if self._prev is None else (*self._prev, self._last_pose)
        guess = start_pose(self.model.visnet, self.camera, view, initial_pose, previous)
        if self._outline is None:
            return guess
        contour = replay_contour(view.s0, view.depth, view.outline_mask, self.camera)
        return register(self._outline, contour, guess).pose

    @torch.no_grad()
    def pose_track(self, record: PushRecord, view: View, pose0: np.ndarray) -> np.ndarray:
        """(T, 3) the push's pose track seen by VisNet: frame t measured about frame t − 1's
        measurement (pose0 at t = 0)."""
        track = [np.asarray(pose0, dtype=np.float64)]
        for t in range(1, len(record.time)):
            frame = (record.rgb[t : t + 1], record.depth[t : t + 1])
            z = visnet_poses(self.model.visnet, self.camera, *frame, view.s0, pose0, track[-1])
            track.append(z[0])
        return np.stack(track)

    def perceive(self, record: PushRecord, view: View | None, pose0: np.ndarray) -> np.ndarray:
        """The executed push's pose track (T, 3) as perceived (VisNet's, or a recording's
        tracked poses without images), remembered for the next push's start pose."""
        if record.rgb is not None and view is not None:
            poses = self.pose_track(record, view, pose0)
        else:  # a recording with tracked poses and no images
            poses = np.asarray(record.pose, dtype=np.float64)
        if view is not None:
            self._prev = (view.s0, pose0)
            if self._outline is None:
                contour = replay_contour(view.s0, view.depth, view.outline_mask, self.camera)
                self._outline = outline_points(contour, pose0)
                self._top = object_top(view.depth, view.s0, self.camera)
        self._last_pose = poses[-1]
        return poses

    def end_pose(self, record: PushRecord, guess: np.ndarray) -> np.ndarray | None:
        """(3,) the object's pose at rest after the push: the first view's contour registered
        (`perception.registration.register`) on the outline mask taken then
        (`PushRecord.outline_mask_end`) from `guess` (3,), θ unwrapped near it; None without
        that mask."""
        if record.outline_mask_end is None or self._outline is None or self._top is None:
            return None
        contour = outline_contour(record.outline_mask_end, self.camera, self._top)
        pose = register(self._outline, contour, guess).pose.copy()
        pose[2] = guess[2] + wrap_angle(pose[2] - guess[2])
        return pose

    def update(self, record: PushRecord, view: View | None, pose0: np.ndarray) -> np.ndarray:
        """The belief after the executed push (module doc); returns VisNet's pose track."""
        self._scene(view, pose0)
        poses = self.perceive(record, view, pose0)
        seen = dataclasses.replace(record, pose=poses)
        (track,) = tracks_from_records([seen], self.sim_config)
        end = self.end_pose(record, poses[-1])
        if end is not None and self.filter_config.end_pose_noise is not None:
            track = dataclasses.replace(track, end_pose=end)
        refitted = None
        if self._refine_outline(record.outline_mask_end, end) and self.tracks:
            refitted = self._refit_on_outline()
        scene = self.scene
        extra = self._closed_form_start(seen) if not self.updates else []
        cfg = self.filter_config
        up = iterated_update(
            self.mean,
            self.cov,
            track,
            scene,
            self.pool,
            self.sigmas,
            cfg,
            extra,
            ceiling=self.prior_cov,
            restarts=self._refit_starts(self.mean)[1:] if cfg.restart_chi2 is not None else (),
        )
        self.tracks.append(track)
        if up.poor_fit and len(self.tracks) > 1 and self._refits_tried < cfg.max_refits:
            self._refits_tried += 1
            batch = refit(
                self.prior_mean,
                self.prior_cov,
                self.tracks,
                scene,
                self.pool,
                self.sigmas,
                cfg,
                self._refit_starts(up.mean),
            )
            log.debug("push %d: refit reduced chi2 %.2f", len(self.tracks), batch.chi2)
            replays = up.replays + batch.replays  # the refit's count, kept or not
            if batch.chi2 <= cfg.refit_gain * batch.start_chi2[1]:  # against the belief's mean
                up = dataclasses.replace(batch, refit=True, replays=replays)
            else:
                up = dataclasses.replace(up, replays=replays)
        if refitted is not None:
            up = dataclasses.replace(up, replays=up.replays + refitted.replays)
        self.mean, self.cov = up.mean, up.cov
        self.updates.append(up)
        log.debug(
            "push %d (%s): reduced chi2 %.2f, noise raised %s, information %s, %d replays, "
            "%d iterations%s",
            len(self.updates),
            record.push.profile,
            up.chi2,
            np.round(up.noise_scale, 2),
            np.round(up.information, 1),
            up.replays,
            up.iterations,
            ", poor fit" if up.poor_fit else "",
        )
        return poses

    def _refit_on_outline(self) -> PhysicsUpdate:
        """The pushes so far read again on the refined outline (`_refine_outline`): every one
        refit from the prior (`identification.recursive.refit`), the search begun at the
        belief's mean, which becomes the refit's."""
        batch = refit(
            self.prior_mean,
            self.prior_cov,
            self.tracks,
            self.scene,
            self.pool,
            self.sigmas,
            self.filter_config,
            [self.mean],
        )
        self.mean, self.cov = batch.mean, batch.cov
        return batch

    def _refit_starts(self, mean: np.ndarray) -> list[np.ndarray]:
        """Starts (5,) of a `refit`: `mean`, and `mean` with its CoM at the prior's (the
        outline's hull's centroid) and moved `refit_spread` prior standard deviations either
        way along each principal axis of the prior's CoM covariance (fit coordinates)."""
        spread = self.filter_config.refit_spread
        centre = self.prior_mean[2:4]
        lam, vecs = np.linalg.eigh(self.prior_cov[2:4, 2:4])
        shifts = [np.zeros(2)] + [
            sign * spread * np.sqrt(lam[j]) * vecs[:, j] for j in range(2) for sign in (1, -1)
        ]
        starts = [mean]
        for shift in shifts:
            u = mean.copy()
            u[2:4] = centre + shift
            starts.append(u)
        return starts

    def _closed_form_start(self, record: PushRecord) -> list[np.ndarray]:
        """The prior's mean with μ·m (and m, μ after a release) read off the push in closed
        form (`identification.fit.closed_form_start`), as a second start of the first update."""
        cf = closed_form_start([record], self.sim_config)
        if cf.mu_m is None:
            return []
        phi = denormalise_params(self.t_inv @ self.mean)
        mass = cf.mass if cf.mass is not None else phi[0]
        phi[0], phi[1] = mass, cf.mu_m / mass
        z_cf = normalise_params(phi)
        return [self.tmat @ z_cf]

    def information(
        self,
        candidates: Sequence[Push],
        view: View,
        pose0: np.ndarray,
        score: ScoreName,
        horizon_fraction: float,
    ) -> np.ndarray:
        """Entropy (nats) each candidate would remove, from replays at the belief's mean over
        `horizon_fraction` of a push (`recursive.expected_information`; both scores rank by
        it). Only the first `look_ahead_candidates` candidates are scored (the others get
        −inf): each costs six replays."""
        scene = self._scene(view, pose0)
        horizon = self.sim_config.push.horizon * horizon_fraction
        sim = self.sim_config.model_copy(
            update={"push": self.sim_config.push.model_copy(update={"horizon": horizon})}
        )
        look = dataclasses.replace(scene, sim_config=sim)
        k = min(len(candidates), self.filter_config.look_ahead_candidates)
        samples = int(round(horizon * sim.tactile.rate_hz)) + 1
        force, pose = np.zeros((samples, 2)), np.zeros((samples, 3))  # unused by the scores
        tracks = [PushTrack(p, None, np.asarray(pose0), force, pose) for p in candidates[:k]]
        scores = expected_information(
            self.mean, self.cov, tracks, look, self.pool, self.sigmas, self.filter_config
        )
        return np.concatenate([scores, np.full(len(candidates) - k, -np.inf)])
