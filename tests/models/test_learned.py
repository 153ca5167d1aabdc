def test_pad_features_are_in_the_object_frame():
    """The pad 5 cm ahead along the object's +x axis reads (0.5, 0) in units of L = 0.1 m,
    whatever the object's world orientation."""
    import math

    import torch

    from pushtoknow.common.camera import CameraModel
    from pushtoknow.models.learned import PushContext, sigma_point_features

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
