"""N-step scores of candidate pushes: exactness on a linear toy, informativeness, degenerate
candidates, batching, angle wrap, learned models."""

import math

import pytest
import torch
from active_toys import (
    F64,
    CouplingContext,
    exact_linear,
    linear_filter,
    linear_prior,
    planar_filter,
    planar_prior,
)

from pushtoknow.active.scores import entropy_reduction, kl_information_gain
from pushtoknow.active.selection import (
    draw_common_noise,
    expected_update_covariance,
    score_candidates,
)
from pushtoknow.common.camera import CameraModel
from pushtoknow.filters import FilterConfig
from pushtoknow.models.context import PushContext
from pushtoknow.models.learned import build_filter


def _coupling_context(couplings):
    ctx = CouplingContext(torch.tensor(couplings, dtype=F64))
    return lambda k: ctx


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_linear_toy_scores_are_exact(score):
    """Linear-Gaussian: moment-matched prediction and the unscented update are exact, so the
    scores equal the Kalman recursion's."""
    filt = linear_filter()
    mean, cov = linear_prior()
    couplings, n = [0.0, 0.5, 1.0], 6
    got = score_candidates(
        filt, mean, cov, _coupling_context(couplings), 3, n, score, torch.Generator().manual_seed(0)
    )
    want = []
    for c in couplings:
        mn, sn = exact_linear(c, n, entropy=score == "entropy")
        if score == "kl":
            want.append(kl_information_gain(mn[None], sn[None], mean, cov)[0])
        else:
            want.append(entropy_reduction(cov, sn[None], slice(1, None))[0])
    torch.testing.assert_close(got, torch.stack(want), rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_informative_candidate_wins_and_degenerate_is_finite(score):
    """Coupling 0 (the pusher misses: Δx independent of φ) versus coupling 1."""
    filt = linear_filter()
    mean, cov = linear_prior()
    s = score_candidates(
        filt,
        mean,
        cov,
        _coupling_context([0.0, 1.0]),
        2,
        10,
        score,
        torch.Generator().manual_seed(1),
    )
    assert torch.isfinite(s).all()
    assert int(torch.argmax(s)) == 1
    if score == "entropy":  # nothing learnt about φ from a push that does not depend on it
        assert abs(s[0].item()) < 1e-9 and s[1].item() > 0.1
    else:  # only the process noise spreads the pose
        assert 0.0 <= s[0].item() < s[1].item()


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_zero_dynamics_gives_finite_scores(score):
    """A degenerate candidate on the nonlinear toy (coupling 0: no motion, no force) beside an
    informative one. Its entropy score is zero up to the Monte-Carlo error of the
    heteroscedastic process noise (C = 24); its KL comes from the process noise alone."""
    filt = planar_filter()
    mean, cov = planar_prior()
    s = score_candidates(
        filt,
        mean,
        cov,
        _coupling_context([0.0, 1.0]),
        2,
        4,
        score,
        torch.Generator().manual_seed(2),
    )
    assert torch.isfinite(s).all()
    assert s[0].item() < s[1].item()
    if score == "entropy":
        assert abs(s[0].item()) < 0.01


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_batched_equals_one_by_one(score):
    filt = planar_filter()
    mean, cov = planar_prior()
    couplings = [0.0, 0.3, 1.0, 2.0]
    batched = score_candidates(
        filt,
        mean,
        cov,
        _coupling_context(couplings),
        4,
        5,
        score,
        torch.Generator().manual_seed(3),
    )
    single = torch.cat(
        [
            score_candidates(
                filt,
                mean,
                cov,
                _coupling_context([c]),
                1,
                5,
                score,
                torch.Generator().manual_seed(3),
            )
            for c in couplings
        ]
    )
    torch.testing.assert_close(batched, single, rtol=1e-10, atol=1e-12)
    # pre-drawn noise is the same as the generator's draws
    noise = draw_common_noise(filt, 5, torch.Generator().manual_seed(3), F64)
    again = score_candidates(
        filt, mean, cov, _coupling_context(couplings), 4, 5, score, noise=noise
    )
    torch.testing.assert_close(again, batched, rtol=0, atol=0)


def test_entropy_score_is_invariant_to_the_angle_wrap():
    """The toy is rotation invariant in its information content; near θ = π the observed
    (wrapped) angle of the sigma points straddles ±π."""
    filt = planar_filter()
    ctx = _coupling_context([0.5, 1.0])
    scores = []
    for theta in (0.0, math.pi - 1e-3):
        mean, cov = planar_prior(theta)
        scores.append(
            score_candidates(
                filt, mean, cov, ctx, 2, 3, "entropy", torch.Generator().manual_seed(4)
            )
        )
    torch.testing.assert_close(scores[0], scores[1], rtol=1e-9, atol=1e-12)


def test_expected_update_shrinks_the_covariance():
    filt = planar_filter()
    mean, cov = planar_prior()
    ctx = CouplingContext(torch.tensor([1.0], dtype=F64))
    post = expected_update_covariance(filt, mean, cov, ctx)
    assert torch.linalg.eigvalsh(cov - post).min() > -1e-12  # Σ⁺ ≤ Σ̄
    assert torch.linalg.eigvalsh(post).min() > 0
    assert post[0, 0, 0] < cov[0, 0, 0]


def test_arguments_are_checked():
    filt = linear_filter()
    mean, cov = linear_prior()
    ctx = _coupling_context([1.0])
    with pytest.raises(ValueError, match="generator"):
        score_candidates(filt, mean, cov, ctx, 1, 2, "kl")
    with pytest.raises(ValueError, match="unknown score"):
        score_candidates(filt, mean, cov, ctx, 1, 2, "nope", torch.Generator())
    with pytest.raises(ValueError, match="n_steps"):
        score_candidates(filt, mean, cov, ctx, 1, 0, "kl", torch.Generator())


def _learned_context(pads: torch.Tensor) -> PushContext:
    """A disc of radius 4 cm at the origin; pads (M, 2)."""
    camera = CameraModel()
    m = pads.shape[0]
    px = (torch.arange(camera.width) - camera.principal_point[0]) * camera.metres_per_pixel()
    disc = (px.view(1, -1).square() + px.view(-1, 1).square() <= 0.04**2).float()
    angles = torch.linspace(0, 2 * math.pi, 13)[:-1]
    poly = 0.04 * torch.stack([angles.cos(), angles.sin()], -1)
    return PushContext(
        mask0=disc.expand(m, 1, -1, -1).contiguous(),
        pose0=torch.zeros(m, 3),
        contact_xy=pads,
        direction=torch.zeros(m),
        speed=torch.full((m,), 0.02),
        camera=camera,
        footprint=poly.expand(m, -1, -1).contiguous(),
    )


@pytest.mark.parametrize("score", ["kl", "entropy"])
def test_learned_models_with_a_missing_pusher_give_finite_scores(score):
    torch.manual_seed(0)
    filt = build_filter("dual", filter_config=FilterConfig(num_sigma_points=24)).eval()
    mean = torch.zeros(1, 8)
    cov = torch.diag(torch.tensor([1e-4, 1e-4, 1e-2, 0.3, 0.3, 0.3, 0.3, 0.3])).unsqueeze(0)
    # candidate 0 touches the disc; candidate 1's pad is far off to the side
    ctx = _learned_context(torch.tensor([[-0.04, 0.0], [-0.04, 0.3]]))
    s = score_candidates(
        filt, mean, cov, lambda k: ctx, 2, 3, score, torch.Generator().manual_seed(5)
    )
    assert s.shape == (2,) and s.dtype == torch.float32
    assert torch.isfinite(s).all()
