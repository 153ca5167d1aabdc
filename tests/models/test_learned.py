def test_pad_features_are_in_the_object_frame():
    """The pad 5 cm ahead along the object's +x axis reads (0.5, 0) in units of L = 0.1 m,
    whatever the object's world orientation."""
    import math

    import torch

    from pushtoknow.common.camera import CameraModel
    from pushtoknow.models.context import PushContext
    from pushtoknow.models.encoding import sigma_point_features

    th = 1.2
    state = torch.tensor([[[0.1, -0.05, th, 0, 0, 0, 0, 0]]])
    pad_xy = torch.tensor([[0.1 + 0.05 * math.cos(th), -0.05 + 0.05 * math.sin(th)]])
    ctx = PushContext(
        torch.zeros(1, 1, 64, 64),
        torch.zeros(1, 3),
        pad_xy,
        torch.tensor([th + 0.3]),
        torch.tensor([0.02]),
        CameraModel(),
    )
    f = sigma_point_features(state, ctx.pose0, state[..., :3], 0.1, ctx)[0, 0]
    assert torch.allclose(f[-5:-3], torch.tensor([0.5, 0.0]), atol=1e-6)
    assert torch.allclose(f[-3:-1], torch.tensor([math.sin(0.3), math.cos(0.3)]), atol=1e-6)
    assert torch.isclose(f[-1], torch.tensor(0.2))


def test_dynamic_noise_scale_applies_to_the_samples_of_a_dynamic_phase():
    import pytest
    import torch

    from pushtoknow.common.errors import ShapeError
    from pushtoknow.models.context import PushContext, with_pad_track
    from pushtoknow.models.learned import ScaledObservationNoise

    class UnitNoise(torch.nn.Module):
        obs_dim = 5

        def forward(self, z, context):
            return torch.ones_like(z)

    # pad at rest, then accelerating (2 cm, 4 cm, ... steps), then steady
    x = torch.tensor([0.0, 0.0, 0.0, 0.02, 0.06, 0.10, 0.14, 0.18, 0.22])
    paths = torch.stack([x, torch.zeros_like(x)], -1)[None]
    ctx = PushContext(
        mask0=torch.zeros(1, 1, 4, 4),
        pose0=torch.zeros(1, 3),
        contact_xy=torch.zeros(1, 2),
        direction=torch.zeros(1),
        speed=torch.zeros(1),
        camera=None,  # type: ignore[arg-type]
    )
    noise = ScaledObservationNoise(UnitNoise(), 16.0, 2.0)
    z = torch.zeros(1, 5)
    scales = [float(noise(z, with_pad_track(ctx, paths, t, 0.1))[0, 0]) for t in range(1, 9)]
    dynamic = [bool(with_pad_track(ctx, paths, t, 0.1).pad_accelerating()) for t in range(1, 9)]
    assert any(dynamic) and not all(dynamic)
    assert scales == [2.0 if d else 16.0 for d in dynamic]
    assert not dynamic[-1]  # steady at the end
    assert float(ScaledObservationNoise(UnitNoise(), 16.0)(z, ctx)[0, 0]) == 16.0
    with pytest.raises(ShapeError, match="pad's track"):
        noise(z, ctx)
    with pytest.raises(ValueError, match="dynamic noise scale must be positive"):
        ScaledObservationNoise(UnitNoise(), 16.0, 0.0)
