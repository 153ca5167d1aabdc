"""Closed-form scores against hand computations."""

import math

import pytest
import torch

from pushtoknow.active.scores import entropy_reduction, kl_information_gain, log_det
from pushtoknow.common.errors import ShapeError

F64 = torch.float64


def _spd(b: int, d: int, gen: torch.Generator) -> torch.Tensor:
    a = torch.randn(b, d, d, generator=gen, dtype=F64)
    return a @ a.mT + 0.5 * torch.eye(d, dtype=F64)


def _kl_by_hand(mn, sn, m0, s0):
    k = mn.shape[-1]
    inv0 = torch.linalg.inv(s0)
    dm = (m0 - mn).unsqueeze(-1)
    return 0.5 * (
        torch.diagonal(inv0 @ sn, dim1=-2, dim2=-1).sum(-1)
        + (dm.mT @ inv0 @ dm)[..., 0, 0]
        - k
        + torch.logdet(s0)
        - torch.logdet(sn)
    )


def test_kl_matches_formula():
    gen = torch.Generator().manual_seed(0)
    mn, m0 = (
        torch.randn(4, 5, generator=gen, dtype=F64),
        torch.randn(4, 5, generator=gen, dtype=F64),
    )
    sn, s0 = _spd(4, 5, gen), _spd(4, 5, gen)
    kl = kl_information_gain(mn, sn, m0, s0)
    assert kl.shape == (4,) and kl.dtype == F64
    torch.testing.assert_close(kl, _kl_by_hand(mn, sn, m0, s0), rtol=1e-10, atol=1e-12)
    # identical beliefs: zero
    torch.testing.assert_close(kl_information_gain(m0, s0, m0, s0), torch.zeros(4, dtype=F64))


def test_kl_on_a_block_is_the_marginal_kl():
    gen = torch.Generator().manual_seed(1)
    mn, m0 = (
        torch.randn(3, 6, generator=gen, dtype=F64),
        torch.randn(3, 6, generator=gen, dtype=F64),
    )
    sn, s0 = _spd(3, 6, gen), _spd(3, 6, gen)
    idx = [2, 4, 5]
    want = _kl_by_hand(mn[:, idx], sn[:, idx][:, :, idx], m0[:, idx], s0[:, idx][:, :, idx])
    torch.testing.assert_close(kl_information_gain(mn, sn, m0, s0, dims=idx), want)
    torch.testing.assert_close(
        kl_information_gain(mn, sn, m0, s0, dims=slice(2, None))[0],
        _kl_by_hand(mn[:1, 2:], sn[:1, 2:, 2:], m0[:1, 2:], s0[:1, 2:, 2:])[0],
    )


def test_kl_in_float32_returns_float32_and_is_finite_for_tiny_pose_variances():
    mean = torch.zeros(2, 8)
    var = torch.tensor([1e-8, 1e-8, 1e-6, 0.3, 0.3, 0.3, 0.3, 0.3])
    cov = torch.diag(var).expand(2, 8, 8)
    shifted = mean.clone()
    shifted[:, 0] = 1e-4  # one standard deviation of x
    kl = kl_information_gain(shifted, cov, mean, cov)
    assert kl.dtype == torch.float32
    torch.testing.assert_close(kl, torch.full((2,), 0.5), rtol=1e-5, atol=1e-6)


def test_entropy_reduction_matches_log_det():
    gen = torch.Generator().manual_seed(2)
    s0, sn = _spd(3, 8, gen), _spd(3, 8, gen)
    want = 0.5 * (torch.logdet(s0[:, 3:, 3:]) - torch.logdet(sn[:, 3:, 3:]))
    torch.testing.assert_close(entropy_reduction(s0, sn, slice(3, None)), want)
    whole = 0.5 * (torch.logdet(s0) - torch.logdet(sn))
    torch.testing.assert_close(entropy_reduction(s0, sn), whole)
    torch.testing.assert_close(log_det(s0), torch.logdet(s0))


def test_entropy_reduction_of_halved_variances():
    s0 = torch.diag(torch.tensor([1.0, 2.0, 3.0], dtype=F64)).unsqueeze(0)
    torch.testing.assert_close(
        entropy_reduction(s0, 0.5 * s0, [1, 2]), torch.tensor([math.log(2.0)], dtype=F64)
    )


def test_singular_block_gets_jitter_not_nan():
    s0 = torch.eye(3, dtype=F64).unsqueeze(0)
    sn = s0.clone()
    sn[0, 2, 2] = 0.0  # a fully known component
    sn[0, 2, 2] += 1e-20
    out = entropy_reduction(s0, sn)
    assert torch.isfinite(out).all() and out.item() > 0


def test_shapes_are_checked():
    with pytest.raises(ShapeError):
        kl_information_gain(
            torch.zeros(2, 3),
            torch.eye(3).expand(2, 3, 3),
            torch.zeros(2, 4),
            torch.eye(3).expand(2, 3, 3),
        )
    with pytest.raises(ValueError, match="selects no component"):
        entropy_reduction(torch.eye(3).unsqueeze(0), torch.eye(3).unsqueeze(0), [])
