"""Constraints: validity, projection for model inputs only, retained invalid sigma points."""

import pytest
import torch
from shapely.geometry import Point, Polygon

from pushtoknow.common.errors import ShapeError
from pushtoknow.common.params import PARAM_NAMES, denormalise_params, normalise_param
from pushtoknow.filters import (
    ComInFootprintConstraint,
    DualFilter,
    FilterConfig,
    JointFilter,
    default_object_constraints,
    vision_only_filter,
)
from pushtoknow.filters.constraints import (
    ParamPositivityConstraint,
    closest_point_on_polygon,
    point_in_polygon,
)
from pushtoknow.filters.interfaces import DynamicsModel, ObservationModel
from pushtoknow.models.analytic import ConstantObservationNoise

F64 = torch.float64
TRIANGLE = [[-0.04, -0.04], [0.08, -0.04], [-0.04, 0.08]]  # right triangle, centroid at 0
L_SHAPE = [[0, 0], [0.1, 0], [0.1, 0.03], [0.03, 0.03], [0.03, 0.1], [0, 0.1]]


class Footprint:
    """Minimal context carrying footprint polygons (B, V, 2)."""

    def __init__(self, polygon, batch):
        self.footprint = torch.tensor(polygon, dtype=F64).expand(batch, -1, -1)


@pytest.mark.parametrize("polygon", [TRIANGLE, L_SHAPE])
def test_point_in_polygon_agrees_with_shapely(polygon):
    gen = torch.Generator().manual_seed(0)
    pts = torch.rand(1, 500, 2, generator=gen, dtype=F64) * 0.2 - 0.05
    inside = point_in_polygon(pts, torch.tensor([polygon], dtype=F64))
    poly = Polygon(polygon)
    ref = [poly.contains(Point(*p)) for p in pts[0].tolist()]
    assert inside[0].tolist() == ref


def test_padded_polygon_and_closest_point():
    square = [[-1.0, -1.0], [1.0, -1.0], [1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0], [-1.0, 1.0]]
    poly = torch.tensor([square], dtype=F64)
    pts = torch.tensor([[[0.0, 0.0], [2.0, 0.5], [3.0, 3.0], [0.5, -0.9]]], dtype=F64)
    assert point_in_polygon(pts, poly)[0].tolist() == [True, False, False, True]
    closest = closest_point_on_polygon(pts, poly)[0]
    torch.testing.assert_close(closest[1:3], torch.tensor([[1.0, 0.5], [1.0, 1.0]], dtype=F64))


def test_positivity_bounds_are_the_si_floors():
    c = ParamPositivityConstraint(pose_dim=3)
    # m, μ, I_z are filtered in log space, so the floors lie far out (−6.9 for 1 g of mass)
    states = torch.full((1, 1, 8), -100.0, dtype=F64)
    proj = c.project(states, None)
    si = denormalise_params(proj[0, 0, 3:])
    for name in ("mass", "friction", "inertia"):
        assert si[PARAM_NAMES.index(name)].item() == pytest.approx(c.floors_si[name])
    assert c.is_valid(proj, None).all() and not c.is_valid(states, None).any()
    # c_x, c_y are not bounded by this constraint
    assert proj[0, 0, 5] == -100.0


@pytest.mark.parametrize("polygon", [TRIANGLE, L_SHAPE])
def test_com_projection_is_valid_and_leaves_valid_points(polygon):
    ctx = Footprint(polygon, 2)
    c = ComInFootprintConstraint()
    gen = torch.Generator().manual_seed(1)
    states = torch.randn(2, 300, 8, generator=gen, dtype=F64) * 3
    valid = c.is_valid(states, ctx)
    assert valid.any() and (~valid).any()
    proj = c.project(states, ctx)
    assert c.is_valid(proj, ctx).all()
    assert torch.equal(proj[valid], states[valid])
    assert torch.equal(proj[..., :5], states[..., :5]) and torch.equal(proj[..., 7], states[..., 7])


def test_missing_footprint_is_a_clear_error():
    with pytest.raises(ShapeError, match="footprint"):
        ComInFootprintConstraint().is_valid(torch.zeros(1, 2, 8), object())


class SpyDynamics(DynamicsModel):
    """Pose drifts by a parameter-dependent amount; asserts it only sees valid states."""

    def __init__(self, constraint):
        super().__init__()
        self.constraint = constraint
        self.calls = 0

    def forward(self, states, context):
        assert self.constraint.is_valid(states, context).all(), "dynamics got an invalid state"
        self.calls += 1
        delta = 0.001 * states[..., 3:6]
        return delta, torch.full_like(delta, 1e-8)


class SpyObservation(ObservationModel):
    """z = (pose, log of the SI mass, friction and inertia): NaN for invalid states."""

    def __init__(self, constraint):
        super().__init__()
        self.constraint = constraint
        self.obs_dim = 6
        self.angle_indices = (2,)
        self.calls = 0

    def forward(self, states, context):
        assert self.constraint.is_valid(states, context).all(), "observation got an invalid state"
        self.calls += 1
        si = denormalise_params(states[..., 3:])
        return torch.cat([states[..., :3], si[..., [0, 1, 4]].log()], -1)


def invalid_heavy_belief(batch):
    """Mean near the bounds: about half the sigma points violate some constraint."""
    mean = torch.zeros(batch, 8, dtype=F64)
    mean[:, 3] = normalise_param("mass", 1e-3)  # on the positivity floors (log space)
    mean[:, 4] = normalise_param("friction", 1e-2)
    mean[:, 5] = 2.0  # c_x = 0.04 m: near the triangle's edge
    cov = torch.diag(torch.tensor([1e-6, 1e-6, 1e-4, 0.1, 0.1, 1.0, 1.0, 0.1], dtype=F64))
    return mean, cov.expand(batch, 8, 8).clone()


@pytest.mark.parametrize("kind", ["dual", "joint", "vision_only"])
def test_models_never_see_invalid_states(kind):
    constraint = default_object_constraints()
    ctx = Footprint(TRIANGLE, 4)
    dyn, obs = SpyDynamics(constraint), SpyObservation(constraint)
    if kind == "vision_only":
        filt = vision_only_filter(
            dyn, ConstantObservationNoise([1e-6, 1e-6, 1e-4]), FilterConfig(), constraint
        )
        z = torch.zeros(4, 3, dtype=F64)
    else:
        cls = DualFilter if kind == "dual" else JointFilter
        noise = ConstantObservationNoise([1e-6, 1e-6, 1e-4, 0.1, 0.1, 0.1])
        filt = cls(dyn, obs, noise, FilterConfig(), constraint)
        z = torch.tensor([[0.0, 0.0, 0.0, -1.0, -2.0, -7.0]], dtype=F64).expand(4, 6)
    mean, cov = invalid_heavy_belief(4)
    gen = torch.Generator().manual_seed(2)
    points = mean.unsqueeze(1) + torch.randn(4, 100, 8, generator=gen, dtype=F64) @ cov.sqrt()
    assert (~constraint.is_valid(points, ctx)).float().mean() > 0.3
    for _ in range(3):
        mean, cov, _ = filt(mean, cov, z, ctx, generator=gen)
    assert torch.isfinite(mean).all() and torch.isfinite(cov).all()
    assert dyn.calls == 3 and (kind == "vision_only" or obs.calls >= 3)


def test_retained_invalid_points_preserve_the_sample_covariance():
    """Prediction with a zero-motion model: the predicted covariance equals the prior's exactly
    with constraints on (invalid points keep their values in the moments); clipping the points
    themselves, as a naive filter would, shrinks the parameter variances."""

    class Still(DynamicsModel):
        def forward(self, states, context):
            z = torch.zeros_like(states[..., :3])
            return z, z

    constraint = default_object_constraints()
    ctx = Footprint(TRIANGLE, 3)
    mean, cov = invalid_heavy_belief(3)
    obs = SpyObservation(constraint)
    with_c = JointFilter(
        Still(), obs, ConstantObservationNoise([1.0] * 6), FilterConfig(), constraint
    )
    without = JointFilter(Still(), obs, ConstantObservationNoise([1.0] * 6), FilterConfig())
    draws = with_c.draw_noise(3, torch.Generator().manual_seed(3), F64)
    m1, c1 = with_c.predict(mean, cov, ctx, draws)
    m2, c2 = without.predict(mean, cov, ctx, draws)
    torch.testing.assert_close(c1, c2)
    torch.testing.assert_close(c1, cov)  # moment-matched draws: exact
    torch.testing.assert_close(m1, mean)
    # the naive alternative: moments of the projected points
    pts = with_c.prepare_noise(torch.cat([draws.predict, draws.process], -1))[..., :8]
    chi = mean.unsqueeze(1) + pts @ torch.linalg.cholesky(cov).transpose(-1, -2)
    projected = constraint.project(chi, ctx)
    naive = torch.diagonal(torch.cov(projected[0].T), 0)
    assert (naive[3:6] < 0.8 * torch.diagonal(cov[0])[3:6]).all()
