"""Merwe sigma points and the UKF update: exact on linear-Gaussian problems, equal to filterpy."""

import math

import numpy as np
import pytest
import torch
from filterpy.kalman import MerweScaledSigmaPoints as FpPoints
from filterpy.kalman import UnscentedKalmanFilter

from pushtoknow.filters.sigma_points import MerweScaledSigmaPoints, monte_carlo_points
from pushtoknow.filters.ukf import ukf_update

F64 = torch.float64


def random_spd(b, d, gen):
    a = torch.randn(b, d, d, generator=gen, dtype=F64)
    return a @ a.transpose(-1, -2) + 0.5 * torch.eye(d, dtype=F64)


@pytest.mark.parametrize(
    ("alpha", "beta", "kappa"), [(1.0, 2.0, 0.0), (0.1, 2.0, 1.0), (0.5, 0, -1)]
)
def test_merwe_points_and_weights_equal_filterpy(alpha, beta, kappa):
    gen = torch.Generator().manual_seed(0)
    mean = torch.randn(1, 4, generator=gen, dtype=F64)
    cov = random_spd(1, 4, gen)
    ours = MerweScaledSigmaPoints(alpha, beta, kappa)
    ref = FpPoints(4, alpha=alpha, beta=beta, kappa=kappa)
    wm, wc = ours.weights(4)
    np.testing.assert_allclose(wm.numpy(), ref.Wm, rtol=1e-12)
    np.testing.assert_allclose(wc.numpy(), ref.Wc, rtol=1e-12)
    np.testing.assert_allclose(
        ours.points(mean, cov)[0].numpy(),
        ref.sigma_points(mean[0].numpy(), cov[0].numpy()),
        rtol=1e-9,
        atol=1e-12,
    )
    assert abs(wm.sum().item() - 1) < 1e-12


def test_monte_carlo_points_reproduce_moments_exactly():
    gen = torch.Generator().manual_seed(1)
    mean = torch.randn(2, 3, generator=gen, dtype=F64)
    cov = random_spd(2, 3, gen)
    eps = torch.randn(2, 40, 3, generator=gen, dtype=F64)
    pts = monte_carlo_points(mean, cov, eps)
    torch.testing.assert_close(pts.mean(1), mean)
    dev = pts - mean.unsqueeze(1)
    torch.testing.assert_close(dev.transpose(1, 2) @ dev / 40, cov)


def test_ukf_update_equals_kalman_update_on_linear_gaussian():
    """State (x, v, θ_param) with a constant parameter; linear observation of x and the param."""
    gen = torch.Generator().manual_seed(2)
    b, n = 5, 3
    mean = torch.randn(b, n, generator=gen, dtype=F64)
    cov = random_spd(b, n, gen)
    h = torch.tensor([[1.0, 0.0, 0.5], [0.0, 0.0, 2.0]], dtype=F64)
    r = torch.tensor([0.3, 0.2], dtype=F64).expand(b, 2)
    z = torch.randn(b, 2, generator=gen, dtype=F64)
    out = ukf_update(mean, cov, z, lambda s: s @ h.T, r)
    s = h @ cov @ h.T + torch.diag_embed(r)
    k = cov @ h.T @ torch.linalg.inv(s)
    ref_mean = mean + (k @ (z - mean @ h.T).unsqueeze(-1)).squeeze(-1)
    ref_cov = (torch.eye(n, dtype=F64) - k @ h) @ cov
    torch.testing.assert_close(out.mean, ref_mean, atol=1e-6, rtol=0)
    torch.testing.assert_close(out.cov, ref_cov, atol=1e-6, rtol=0)
    # tighter than required: exact up to rounding
    assert (out.cov - ref_cov).abs().max() < 1e-12


def _circular_mean_np(sigmas, wm, angle_idx):
    mean = np.dot(wm, sigmas)
    ref = sigmas[0, angle_idx]
    dev = np.remainder(sigmas[:, angle_idx] - ref + np.pi, 2 * np.pi) - np.pi
    mean[angle_idx] = ref + np.dot(wm, dev)
    return mean


def _residual_np(a, b, angle_idx):
    y = a - b
    y[angle_idx] = np.remainder(y[angle_idx] + np.pi, 2 * np.pi) - np.pi
    return y


@pytest.mark.parametrize(("alpha", "beta", "kappa"), [(1.0, 2.0, 0.0), (0.3, 2.0, 0.0)])
def test_ukf_update_equals_filterpy_on_nonlinear_range_bearing(alpha, beta, kappa):
    """Range-bearing to a landmark plus a nonlinear parameter channel; bearing is an angle."""
    landmark = np.array([0.4, -0.3])

    def hx_np(s):
        d = landmark - s[:2]
        bearing = math.atan2(d[1], d[0]) - s[2]
        return np.array([np.hypot(*d), bearing, s[3] ** 2 + math.sin(s[2])])

    def hx_torch(s):
        d = torch.as_tensor(landmark, dtype=F64) - s[..., :2]
        bearing = torch.atan2(d[..., 1], d[..., 0]) - s[..., 2]
        return torch.stack([d.norm(dim=-1), bearing, s[..., 3] ** 2 + s[..., 2].sin()], -1)

    gen = torch.Generator().manual_seed(3)
    b = 4
    mean = torch.randn(b, 4, generator=gen, dtype=F64) * 0.2
    mean[:, 2] = torch.tensor([0.1, 3.0, -3.1, 1.0])  # headings near the ±π wrap
    cov = random_spd(b, 4, gen) * 0.01
    z = torch.stack([torch.as_tensor(hx_np(m.numpy())) for m in mean]) + 0.05
    z[:, 1] = torch.remainder(z[:, 1] + math.pi, 2 * math.pi) - math.pi
    r_full = (random_spd(1, 3, gen) * 0.01).expand(b, 3, 3)
    ours = ukf_update(
        mean,
        cov,
        z,
        hx_torch,
        r_full,
        MerweScaledSigmaPoints(alpha, beta, kappa),
        state_angle_indices=(2,),
        obs_angle_indices=(1,),
    )
    for i in range(b):
        pts = FpPoints(4, alpha=alpha, beta=beta, kappa=kappa)
        ukf = UnscentedKalmanFilter(
            dim_x=4,
            dim_z=3,
            dt=1.0,
            hx=hx_np,
            fx=lambda s, dt: s,
            points=pts,
            z_mean_fn=lambda sig, wm: _circular_mean_np(sig, wm, 1),
            residual_z=lambda a, c: _residual_np(a, c, 1),
        )
        ukf.x = mean[i].numpy().copy()
        ukf.P = cov[i].numpy().copy()
        ukf.Q = np.zeros((4, 4))
        ukf.predict()  # identity process, Q = 0: sigmas_f = sigma points of (x, P)
        ukf.update(z[i].numpy(), R=r_full[i].numpy())
        np.testing.assert_allclose(ours.mean[i].numpy(), ukf.x, atol=1e-6, rtol=0)
        np.testing.assert_allclose(ours.cov[i].numpy(), ukf.P, atol=1e-6, rtol=0)
        assert np.abs(ours.cov[i].numpy() - ukf.P).max() < 1e-10
