"""The physics filter's update against exact references: on a simulator that is linear in the
fit coordinates, the iterated update is the Kalman update and the expected information is the
Gaussian entropy reduction."""

import dataclasses

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from pushtoknow.common.params import normalise_params
from pushtoknow.identification.prior import fit_transform, prior_moments
from pushtoknow.identification.recursive import (
    OFFSET_UNIT,
    PhysicsFilterConfig,
    expected_information,
    iterated_update,
    refit,
    widened_after_jump,
)
from pushtoknow.identification.replay import PushTrack, ReplayScene
from pushtoknow.testbed.push import Push
from pushtoknow.testbed.sim_config import SimConfig

T = 8  # samples per push
SQUARE = {"type": "polygon", "vertices": [[-0.1, -0.1], [0.1, -0.1], [0.1, 0.1], [-0.1, 0.1]]}
EXACT = PhysicsFilterConfig(
    huber=1e9,
    misfit_noise=False,
    flat_information=0.0,
    information_scale=1.0,
    poor_fit_chi2=1e12,
    max_iterations=30,
    step_tolerance=1e-12,
    cost_tolerance=1e-14,
    max_step=10.0,
    contact_offset_std=0.0,
    inflation=(),
    rest_as_one=False,
    pose_correlation=0.0,
)
START = np.array([0.0, -0.12])
SIGMAS = np.array([0.05, 0.05, 5e-4, 5e-4, 0.01])


class LinearPool:
    """A stand-in for `RolloutPool` whose replay of φ is A·u + b + g·s (u the fit coordinates,
    s the pad's shift along the push from its recorded start, in `OFFSET_UNIT`)."""

    def __init__(self, a: np.ndarray, b: np.ndarray, g: np.ndarray | None = None):
        self.a, self.b = a, b
        self.g = np.zeros(len(b)) if g is None else g
        self.rollouts = self.push_rollouts = 0

    def run_each(self, scene, phis, tracks):
        tmat = fit_transform()
        out = []
        for phi, trs in zip(np.atleast_2d(phis), tracks, strict=True):
            u = tmat @ normalise_params(phi)
            shift = [float((tr.start - START) @ tr.push.unit) / OFFSET_UNIT for tr in trs]
            sims = [(self.a @ u + self.b + self.g * s).reshape(T, 5) for s in shift]
            self.alter(u, sims)
            out.append(sims)
        self.rollouts += len(out)
        self.push_rollouts += len(out) * len(tracks[0])
        return out

    def alter(self, u: np.ndarray, sims: list[np.ndarray]) -> None:
        """Change the replays `sims` (each (T, 5)) of fit coordinates u in place (here: none)."""

    def run(self, scene, phis, tracks):
        return self.run_each(scene, phis, [tracks] * len(np.atleast_2d(phis)))


def problem(seed: int, profile: str = "release"):
    rng = np.random.default_rng(seed)
    a = rng.normal(size=(T * 5, 5)) * SIGMAS.repeat(1)[np.arange(T * 5) % 5][:, None] * 3
    b = rng.normal(size=T * 5) * 0.01
    z, p_z = prior_moments()
    tmat = fit_transform()
    mean = tmat @ z
    cov = 0.02 * tmat @ p_z @ tmat.T
    truth = mean + np.linalg.cholesky(cov) @ rng.normal(size=5)
    y = (a @ truth + b + rng.normal(size=T * 5) * np.tile(SIGMAS, T)).reshape(T, 5)
    speed = 0.4 if profile == "release" else 0.02
    track = PushTrack(
        Push((0.0, -0.1), np.pi / 2, profile, speed), START.copy(), np.zeros(3), y[:, :2], y[:, 2:]
    )
    scene = ReplayScene(SQUARE, 0.013, SimConfig())
    return a, b, mean, cov, track, scene


def kalman(a, b, mean, cov, y, rho: float = 0.0):
    """The exact posterior of u ~ N(mean, cov), y = A u + b + e, samples ≥ 1; e Gaussian,
    independent across channels, the force's white, each pose channel's AR(1) with lag-1
    correlation rho (covariance σ² ρ^|i − j|)."""
    rows = np.arange(5, T * 5)  # the first sample is the start state: not a measurement
    lag = np.abs(np.arange(T - 1)[:, None] - np.arange(T - 1)[None])
    r = np.zeros((len(rows), len(rows)))
    for c, sigma in enumerate(SIGMAS):
        corr = rho**lag if c >= 2 else np.eye(T - 1)
        r[c::5, c::5] = sigma**2 * corr
    w = np.linalg.inv(r)
    ar, br, yr = a[rows], b[rows], y.reshape(-1)[rows]
    post = np.linalg.inv(np.linalg.inv(cov) + ar.T @ w @ ar)
    return post @ (np.linalg.solve(cov, mean) + ar.T @ w @ (yr - br)), post


@settings(max_examples=15, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0.0, 0.7]))
def test_the_iterated_update_is_the_kalman_update_on_a_linear_simulator(seed, rho):
    """Exact against the Kalman update, with white and with AR(1) pose noise (whitened)."""
    a, b, mean, cov, track, scene = problem(seed)
    cfg = EXACT.model_copy(update={"pose_correlation": rho})
    up = iterated_update(mean, cov, track, scene, LinearPool(a, b), SIGMAS, cfg)
    y = np.column_stack([track.force, track.pose])
    want_mean, want_cov = kalman(a, b, mean, cov, y, rho)
    np.testing.assert_allclose(up.mean, want_mean, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(up.cov, want_cov, rtol=1e-5, atol=1e-12)
    assert up.identified == 5 and not up.poor_fit


@settings(max_examples=10, deadline=None)
@given(st.integers(0, 10_000), st.sampled_from([0.0, 0.7]))
def test_an_end_pose_is_one_more_measurement_of_the_replays_last_pose(seed, rho):
    """A track's `end_pose` (the pose at rest registered in an image after the push) is the
    Kalman update's measurement of the replay's last pose with its own noise, independent of
    the track's; without `end_pose_noise` it is unused."""
    a, b, mean, cov, track, scene = problem(seed)
    end_sigmas = np.array([3e-4, 3e-4, 0.004])
    rng = np.random.default_rng(seed + 1)
    truth = mean + np.linalg.cholesky(cov) @ rng.normal(size=5)
    last = slice((T - 1) * 5 + 2, T * 5)
    end = a[last] @ truth + b[last] + rng.normal(size=3) * end_sigmas
    ended = dataclasses.replace(track, end_pose=end)
    cfg = EXACT.model_copy(update={"pose_correlation": rho, "end_pose_noise": (3e-4, 0.004)})
    up = iterated_update(mean, cov, ended, scene, LinearPool(a, b), SIGMAS, cfg)
    # the exact reference: the track's posterior updated by the end pose
    y = np.column_stack([track.force, track.pose])
    m1, p1 = kalman(a, b, mean, cov, y, rho)
    h = a[last]
    gain = p1 @ h.T @ np.linalg.inv(h @ p1 @ h.T + np.diag(end_sigmas**2))
    want_mean, want_cov = m1 + gain @ (end - h @ m1 - b[last]), p1 - gain @ h @ p1
    np.testing.assert_allclose(up.mean, want_mean, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(up.cov, want_cov, rtol=1e-5, atol=1e-12)
    unused = iterated_update(
        mean, cov, ended, scene, LinearPool(a, b), SIGMAS,
        cfg.model_copy(update={"end_pose_noise": None}),
    )  # fmt: skip
    np.testing.assert_allclose(unused.mean, m1, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    assert np.linalg.det(up.cov) < np.linalg.det(unused.cov)


def test_the_contact_offset_is_estimated_jointly_and_marginalised():
    """With the pad's offset along the push in the state, the update is the Kalman update of
    the augmented Gaussian (u, s), its u block the marginal."""
    a, b, mean, cov, track, scene = problem(11)
    rng = np.random.default_rng(11)
    g = rng.normal(size=T * 5) * np.tile(SIGMAS, T) * 2
    s_true, s_std = 1.2, 1.5  # mm
    y = np.column_stack([track.force, track.pose]).reshape(-1) + g * s_true
    y = y.reshape(T, 5)
    track = PushTrack(track.push, track.start, track.pose0, y[:, :2], y[:, 2:])
    cfg = EXACT.model_copy(update={"contact_offset_std": s_std * OFFSET_UNIT})
    up = iterated_update(mean, cov, track, scene, LinearPool(a, b, g), SIGMAS, cfg)
    aug_a = np.column_stack([a, g])
    aug_mean = np.append(mean, 0.0)
    aug_cov = np.pad(cov, ((0, 1), (0, 1)))
    aug_cov[5, 5] = s_std**2
    want_mean, want_cov = kalman(aug_a, b, aug_mean, aug_cov, y)
    np.testing.assert_allclose(up.mean, want_mean[:5], atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(up.cov, want_cov[:5, :5], rtol=1e-5, atol=1e-12)
    assert up.contact_offset == pytest.approx(want_mean[5] * OFFSET_UNIT, abs=1e-9)


def test_a_refit_of_every_push_is_the_kalman_update_of_them_all_from_the_prior():
    """Two pushes with their own contact offsets refitted at once from the prior, the search
    started far from the optimum: the Kalman update of the prior by both pushes, each with its
    offset in the state and marginalised (the same as filtering them one by one)."""
    a, b, mean, cov, track, scene = problem(12)
    rng = np.random.default_rng(12)
    g = rng.normal(size=T * 5) * np.tile(SIGMAS, T) * 2
    s_std = 1.5  # mm
    tracks, ys = [], []
    for s_true in (0.8, -1.1):
        y = np.column_stack([track.force, track.pose]).reshape(-1) + g * s_true
        y = (y + rng.normal(size=T * 5) * np.tile(SIGMAS, T)).reshape(T, 5)
        tracks.append(PushTrack(track.push, track.start, track.pose0, y[:, :2], y[:, 2:]))
        ys.append(y)
    cfg = EXACT.model_copy(update={"contact_offset_std": s_std * OFFSET_UNIT})
    far = mean + 2 * np.sqrt(np.diag(cov))
    up = refit(mean, cov, tracks, scene, LinearPool(a, b, g), SIGMAS, cfg, [far])
    want_mean, want_cov = mean, cov
    for y in ys:
        aug_cov = np.pad(want_cov, ((0, 1), (0, 1)))
        aug_cov[5, 5] = s_std**2
        m, c = kalman(np.column_stack([a, g]), b, np.append(want_mean, 0.0), aug_cov, y)
        want_mean, want_cov = m[:5], c[:5, :5]
    np.testing.assert_allclose(up.mean, want_mean, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(up.cov, want_cov, rtol=1e-5, atol=1e-12)
    one = iterated_update(mean, cov, tracks[0], scene, LinearPool(a, b, g), SIGMAS, cfg)
    assert np.trace(up.cov) < np.trace(one.cov)  # the second push adds its information


class BoxPool(LinearPool):
    """The linear replay inside a box of fit coordinates (|u − centre| ≤ radius in every
    coordinate) and a replay that reproduces nothing outside it (every sample 100 noise units
    off, whatever u: a flat misfit the search cannot leave)."""

    def __init__(self, a, b, centre: np.ndarray, radius: np.ndarray):
        super().__init__(a, b)
        self.centre, self.radius = centre, radius

    def alter(self, u, sims):
        if np.any(np.abs(u - self.centre) > self.radius):
            for sim in sims:
                sim[:] = 100.0 * SIGMAS


def test_a_push_still_poor_is_searched_again_from_the_restarts_and_keeps_the_best_fit():
    """The belief's mean lies where the replay reproduces nothing: the descent stays there, a
    poor fit. With `restart_chi2` the search starts again from each restart, and the one
    inside the basin gives the Kalman update; without it, the restarts are not used."""
    a, b, mean, cov, track, scene = problem(6)
    y = np.column_stack([track.force, track.pose])
    want_mean, want_cov = kalman(a, b, mean, cov, y)
    std = np.sqrt(np.diag(cov))
    pool = BoxPool(a, b, want_mean, 3 * std)
    far = mean.copy()
    far[2] = want_mean[2] + 5 * std[2]  # the CoM's first coordinate, outside the basin
    cfg = EXACT.model_copy(update={"poor_fit_chi2": 2.0, "linearisation_rounds": 0})
    restarts = [far + 1.0 * std, want_mean + 0.5 * std]
    stuck = iterated_update(far, cov, track, scene, pool, SIGMAS, cfg, restarts=restarts)
    assert stuck.poor_fit
    found = iterated_update(
        far, cov, track, scene, pool, SIGMAS,
        cfg.model_copy(update={"restart_chi2": 2.0}), restarts=restarts,
    )  # fmt: skip
    assert not found.poor_fit
    want_mean, want_cov = kalman(a, b, far, cov, y)  # the same data from the belief at `far`
    np.testing.assert_allclose(found.mean, want_mean, atol=1e-5 * std.max())
    np.testing.assert_allclose(found.cov, want_cov, rtol=1e-4, atol=1e-12)


def test_a_quasi_static_push_leaves_mass_at_fixed_mu_m_and_inertia_at_the_prior():
    a, b, mean, cov, track, scene = problem(3, profile="constant")
    up = iterated_update(mean, cov, track, scene, LinearPool(a, b), SIGMAS, EXACT)
    added = np.linalg.inv(up.cov) - np.linalg.inv(cov)  # the push's information
    scale = np.abs(added).max()
    blind = [1, 4]  # log m at fixed μ·m, log I_z
    np.testing.assert_allclose(added[blind], 0.0, atol=1e-6 * scale)
    assert np.all(np.diag(added)[[0, 2, 3]] > 1e-3 * scale)


def test_a_push_the_replay_cannot_reproduce_teaches_neither_mass_nor_inertia():
    a, b, mean, cov, track, scene = problem(4)
    bad = PushTrack(track.push, track.start, track.pose0, track.force + 1.0, track.pose)
    cfg = EXACT.model_copy(update={"poor_fit_chi2": 2.0})
    up = iterated_update(mean, cov, bad, scene, LinearPool(a, b), SIGMAS, cfg)
    assert up.poor_fit and up.chi2 > 2.0
    added = np.linalg.inv(up.cov) - np.linalg.inv(cov)
    np.testing.assert_allclose(added[[1, 4]], 0.0, atol=1e-6 * np.abs(added).max())


def test_a_belief_too_sure_of_itself_is_inflated_until_the_push_fits():
    """A belief 3 prior std from the truth and a thousand times surer than the prior: the push
    cannot be fitted from it, and the update is the Kalman update from the belief inflated by
    the first factor that fits."""
    a, b, mean, cov, track, scene = problem(7)
    y = np.column_stack([track.force, track.pose])
    pool = LinearPool(a, b)
    truth_mean = kalman(a, b, mean, cov, y)[0]
    sure = 1e-6 * cov
    wrong = truth_mean + 3 * np.sqrt(np.diag(cov))
    cfg = EXACT.model_copy(update={"poor_fit_chi2": 2.0, "inflation": (10.0, 1e4, 1e6)})
    up = iterated_update(wrong, sure, track, scene, pool, SIGMAS, cfg)
    assert up.inflation > 1.0 and not up.poor_fit
    want_mean, want_cov = kalman(a, b, wrong, up.inflation * sure, y)
    np.testing.assert_allclose(up.mean, want_mean, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(up.cov, want_cov, rtol=1e-5, atol=1e-14)
    stuck = iterated_update(wrong, sure, track, scene, pool, SIGMAS, EXACT.model_copy(
        update={"poor_fit_chi2": 2.0}))  # fmt: skip
    assert stuck.poor_fit and stuck.inflation == 1.0


def test_an_update_that_jumps_beyond_the_belief_is_widened_along_the_jump():
    """The Kalman update stands where its move is consistent with the belief before it; from a
    belief 5 of its std off on every coordinate, the push moves the mean beyond the gate, and
    the covariance gains (1 − gate / d²) ΔΔᵀ, along Δ only."""
    a, b, mean, cov, track, scene = problem(11)
    y = np.column_stack([track.force, track.pose])
    post_mean, post_cov = kalman(a, b, mean, cov, y)
    delta = post_mean - mean
    d2 = float(delta @ np.linalg.solve(cov, delta))
    cfg = EXACT.model_copy(update={"jump_chi2": 2.0 * d2})  # a consistent move: unchanged
    up = iterated_update(mean, cov, track, scene, LinearPool(a, b), SIGMAS, cfg)
    np.testing.assert_allclose(up.cov, post_cov, rtol=1e-5, atol=1e-12)
    off = post_mean + 5 * np.sqrt(np.diag(cov))
    cfg = EXACT.model_copy(update={"jump_chi2": 20.0})
    up = iterated_update(off, cov, track, scene, LinearPool(a, b), SIGMAS, cfg)
    want_mean, want_cov = kalman(a, b, off, cov, y)
    move = want_mean - off
    jump = float(move @ np.linalg.solve(cov, move))
    assert jump > 20.0
    np.testing.assert_allclose(up.mean, want_mean, atol=1e-6 * np.sqrt(np.diag(cov)).max())
    np.testing.assert_allclose(
        up.cov, want_cov + (1 - 20.0 / jump) * np.outer(move, move), rtol=1e-5, atol=1e-12
    )
    # orthogonal to the move (in the belief's metric) nothing changes
    widened = widened_after_jump(off, cov, want_mean, want_cov, 20.0)
    ortho = np.linalg.svd(move[None])[2][1:]  # (4, 5) directions with v·Δ = 0
    np.testing.assert_allclose(ortho @ widened @ ortho.T, ortho @ want_cov @ ortho.T, atol=1e-14)
    assert widened_after_jump(off, cov, off, want_cov, 20.0) is want_cov
    # under a ceiling (the prior) no variance grows beyond it, and the result is a covariance
    ceiling = 0.5 * np.diag(np.diagonal(widened))
    capped = widened_after_jump(off, cov, want_mean, want_cov, 20.0, ceiling)
    bound = np.maximum(np.diagonal(ceiling), np.diagonal(want_cov))
    np.testing.assert_allclose(np.diagonal(capped), np.minimum(np.diagonal(widened), bound))
    assert np.linalg.eigvalsh(capped).min() > 0


def test_misfit_noise_widens_the_posterior_where_the_replay_misses():
    a, b, mean, cov, track, scene = problem(5)
    bad = PushTrack(track.push, track.start, track.pose0, track.force + 0.3, track.pose)
    pool = LinearPool(a, b)
    tight = iterated_update(mean, cov, bad, scene, pool, SIGMAS, EXACT)
    honest = iterated_update(
        mean, cov, bad, scene, pool, SIGMAS, EXACT.model_copy(update={"misfit_noise": True})
    )
    assert honest.noise_scale[0] > 2.0
    assert np.trace(honest.cov) > np.trace(tight.cov)


class SteppedPool(LinearPool):
    """A linear replay with a step of `amp` noise units in every pose sample where the fit
    coordinate u_1 exceeds `at`: a contact that begins one simulation step later."""

    def __init__(self, a, b, at: float, amp: float):
        super().__init__(a, b)
        self.at, self.amp = at, amp

    def alter(self, u, sims):
        if u[1] > self.at:
            for sim in sims:
                sim[:, 2:] += self.amp * SIGMAS[2:]


def test_posterior_linearisation_counts_a_replays_step_as_noise_not_information():
    """Nothing in the linear replay reveals u_1, but a step in it lies just beyond the optimum,
        inside the forward difference: that difference reads the step as a steep slope and the
        update grows sure of u_1; linearised across the posterior's spread, the update is the Kalman
    update of the linear replay."""
    a, b, mean, cov, track, scene = problem(8)
    a[:, 1] = 0.0
    y = np.column_stack([track.force, track.pose])
    optimum, want_cov = kalman(a, b, mean, cov, y)
    cfg = EXACT.model_copy(update={"fd_steps": (0.01, 0.4, 0.02, 0.02, 0.15)})
    at = optimum[1] + 0.2
    assert np.sqrt(want_cov[1, 1]) < 0.2  # no sigma point reaches the step
    pool = SteppedPool(a, b, at, amp=5.0)
    forward = iterated_update(
        mean, cov, track, scene, pool, SIGMAS, cfg.model_copy(update={"linearisation_rounds": 0})
    )
    assert forward.cov[1, 1] < 0.1 * want_cov[1, 1]
    linearised = iterated_update(mean, cov, track, scene, pool, SIGMAS, cfg)
    np.testing.assert_allclose(linearised.cov, want_cov, rtol=1e-5, atol=1e-12)
    # the descent's own forward differences still see the step: its mean within the spread
    assert np.all(np.abs(linearised.mean - optimum) < np.sqrt(np.diag(want_cov)))


def test_expected_information_is_the_gaussian_entropy_reduction():
    a, b, mean, cov, track, scene = problem(6)
    got = expected_information(mean, cov, [track], scene, LinearPool(a, b), SIGMAS, EXACT)
    rows = np.arange(5, T * 5)
    ar = a[rows] / np.tile(SIGMAS, T)[rows][:, None]
    chol = np.linalg.cholesky(cov)
    want = 0.5 * np.linalg.slogdet(np.eye(5) + chol.T @ ar.T @ ar @ chol)[1]
    assert got[0] == pytest.approx(want, rel=1e-6)
    quasi = PushTrack(Push((0.0, -0.1), np.pi / 2, "constant", 0.02), *[track.start,
                      track.pose0, track.force, track.pose])  # fmt: skip
    assert (
        expected_information(mean, cov, [quasi], scene, LinearPool(a, b), SIGMAS, EXACT)[0] < got[0]
    )
