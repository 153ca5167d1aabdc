"""Physics-structured models: how m, μ and I_z enter force and motion, the pad's kinematics."""

import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from tiny_models import prior, square_context, tiny_config
from torch.autograd import gradcheck

from pushtoknow.common.errors import ShapeError
from pushtoknow.common.params import GRAVITY, normalise_params
from pushtoknow.filters import DualFilter
from pushtoknow.models import build_filter, build_learned_models
from pushtoknow.models.context import pad_windows, with_pad_track
from pushtoknow.models.learned import LearnedModelsConfig

F64 = torch.float64
DT = 0.1


QUASI_STATIC = ["network", "limit-surface"]
# quasi-static motion and the limit surface's moment arm
MOTION = [("network", "gyration"), ("limit-surface", "gyration"), ("limit-surface", "pressure")]


def physics_config(
    quasi_static: str = "network", dynamic_motion_params: bool = True, moment_arm="gyration"
):
    """tiny_config with the physics structure and hidden layers wide enough that no random
    initialisation leaves a head constant (dead ReLUs)."""
    cfg = tiny_config()
    return cfg.model_copy(
        update={
            "structure": "physics",
            "quasi_static": quasi_static,
            "dynamic_motion_params": dynamic_motion_params,
            "moment_arm": moment_arm,
            "process": cfg.process.model_copy(update={"hidden_dims": (32, 32)}),
            "tac": cfg.tac.model_copy(update={"hidden_dims": (32, 32, 32)}),
        }
    )


def physics_models(
    seed: int = 0,
    quasi_static: str = "network",
    dynamic_motion_params: bool = True,
    moment_arm: str = "gyration",
):
    torch.manual_seed(seed)
    models = build_learned_models(physics_config(quasi_static, dynamic_motion_params, moment_arm))
    for m in models.modules().modules():
        if isinstance(m, torch.nn.Linear):  # tiny nets: make every output depend on its inputs
            torch.nn.init.normal_(m.weight, std=0.8)
    return models.modules().to(F64), models


def context_with_path(path: torch.Tensor, t: int):
    """square_context with pad path (T, 2) along +x, step ending at sample t."""
    base = square_context(1, F64)
    return with_pad_track(base, path[None], t, DT)


def states_with(mass, friction, inertia, com=(0.005, -0.003), pose=(0.001, 0.0, 0.02)):
    phi = torch.tensor([[mass, friction, com[0], com[1], inertia]], dtype=F64)
    return torch.cat([torch.tensor([pose], dtype=F64), normalise_params(phi)], -1).unsqueeze(1)


PAD_START = -0.0505  # m: the pad's rim 0.5 mm short of square_context's left edge


def steady_path(speed=0.02, n=10):
    return torch.stack(
        [torch.arange(n, dtype=F64) * speed * DT + PAD_START, torch.zeros(n, dtype=F64)], -1
    )


def accelerating_path(accel=1.0, n=10):
    t = torch.arange(n, dtype=F64) * DT
    return torch.stack([0.5 * accel * t**2 + PAD_START, torch.zeros(n, dtype=F64)], -1)


@given(
    v=st.floats(-0.5, 0.5),
    a=st.floats(-3.0, 3.0),
    x0=st.floats(-1.0, 1.0),
    t=st.integers(0, 7),
)
@settings(max_examples=40, deadline=None)
def test_pad_window_differences_are_exact_on_quadratic_paths(v, a, x0, t):
    """Centred differences of a quadratic path give its acceleration exactly, also at the ends
    where the window is extended at constant velocity (there the acceleration reads 0 beyond
    the path)."""
    time = torch.arange(8, dtype=F64) * DT
    path = torch.stack([x0 + v * time + 0.5 * a * time**2, 0.5 * x0 + 0 * time], -1)[None]
    ctx = with_pad_track(square_context(1, F64), path, t, DT)
    velocity, accel, _ = ctx.pad_kinematics()
    assert torch.allclose(ctx.contact_xy, path[:, t])
    if 1 <= t <= 6:
        assert accel[0, 0].item() == pytest.approx(a, abs=1e-6)
    if t >= 1:
        expected_v = v + a * (time[t] - 0.5 * DT)
        assert velocity[0, 0].item() == pytest.approx(float(expected_v), abs=1e-6)
    assert accel[0, 1].abs().item() < 1e-9


def test_pad_windows_reject_samples_outside_the_path():
    with pytest.raises(IndexError, match="outside the path of 5 samples"):
        pad_windows(torch.zeros(2, 5, 2), torch.tensor([1, 5]))


@pytest.mark.parametrize("quasi_static", QUASI_STATIC)
def test_physics_models_need_the_pad_track(quasi_static):
    _, models = physics_models(quasi_static=quasi_static)
    with pytest.raises(ShapeError, match="with_pad_track"):
        models.dynamics(states_with(0.5, 0.5, 1e-3), square_context(1, F64))


@given(k=st.floats(0.3, 3.0))
@settings(max_examples=15, deadline=None)
@pytest.mark.parametrize("quasi_static", QUASI_STATIC)
def test_quasi_static_force_depends_on_mass_and_friction_only_through_their_product(
    k, quasi_static
):
    """At constant pad speed, F(m k, μ / k) = F(m, μ) whatever the networks learned; with I_z
    changed too, nothing moves either."""
    _, models = physics_models(quasi_static=quasi_static)
    ctx = context_with_path(steady_path(), 4)
    f1, _ = models.observation.tactile(states_with(0.5, 0.5, 1e-3), ctx)
    f2, _ = models.observation.tactile(states_with(0.5 * k, 0.5 / k, 1e-3 * k**2), ctx)
    assert f1.abs().max() > 1e-3
    assert torch.allclose(f1, f2, rtol=1e-9, atol=1e-12)


@pytest.mark.parametrize("quasi_static", QUASI_STATIC)
def test_accelerating_pad_adds_a_force_proportional_to_mass(quasi_static):
    """With the pad accelerating, F = m (μ g G + J a): doubling m at fixed μ·m and I_z/m
    changes the force by exactly m J a, so F(2m, μ/2) - F(m, μ) = m J a is linear in a."""
    _, models = physics_models(quasi_static=quasi_static)
    ctx = context_with_path(accelerating_path(1.0), 3)
    f1, _ = models.observation.tactile(states_with(0.4, 0.6, 0.8e-3), ctx)
    f2, _ = models.observation.tactile(states_with(0.8, 0.3, 1.6e-3), ctx)
    f3, _ = models.observation.tactile(states_with(1.6, 0.15, 3.2e-3), ctx)
    inertial = f2 - f1
    assert inertial.abs().max() > 1e-3  # mass is separable from μ when the pad accelerates
    assert torch.allclose(f3 - f2, 2 * inertial, rtol=1e-8, atol=1e-10)


@pytest.mark.parametrize(("quasi_static", "moment_arm"), MOTION)
def test_quasi_static_motion_never_depends_on_mass_friction_or_inertia(quasi_static, moment_arm):
    _, models = physics_models(quasi_static=quasi_static, moment_arm=moment_arm)
    ctx = context_with_path(steady_path(), 4)
    d1, q1 = models.dynamics(states_with(0.3, 0.4, 0.6e-3), ctx)
    d2, q2 = models.dynamics(states_with(1.1, 0.7, 1.4e-3), ctx)
    assert torch.equal(d1, d2) and torch.equal(q1, q2)
    d3, _ = models.dynamics(states_with(0.3, 0.4, 0.6e-3, com=(-0.01, 0.01)), ctx)
    assert not torch.allclose(d1, d3)  # the CoM does enter quasi-static motion


@pytest.mark.parametrize("quasi_static", QUASI_STATIC)
def test_dynamic_motion_sees_friction_and_inertia_per_mass_but_not_mass(quasi_static):
    _, models = physics_models(quasi_static=quasi_static)
    ctx = context_with_path(accelerating_path(2.0), 3)
    d1, _ = models.dynamics(states_with(0.4, 0.5, 1e-3), ctx)
    d2, _ = models.dynamics(states_with(0.8, 0.5, 2e-3), ctx)  # same μ, same I_z / m
    d3, _ = models.dynamics(states_with(0.4, 0.3, 1e-3), ctx)
    assert torch.allclose(d1, d2, rtol=1e-9, atol=1e-12)
    assert not torch.allclose(d1, d3)


@pytest.mark.parametrize("quasi_static", QUASI_STATIC)
def test_kinematic_dynamic_motion_never_depends_on_mass_friction_or_inertia(quasi_static):
    """dynamic_motion_params False: while the pad accelerates the motion network still
    switches on (the motion differs from a steady push's) but sees no parameter but the CoM."""
    _, models = physics_models(quasi_static=quasi_static, dynamic_motion_params=False)
    ctx = context_with_path(accelerating_path(2.0), 3)
    d1, q1 = models.dynamics(states_with(0.4, 0.5, 1e-3), ctx)
    d2, q2 = models.dynamics(states_with(1.1, 0.3, 0.6e-3), ctx)
    assert torch.equal(d1, d2) and torch.equal(q1, q2)
    d3, _ = models.dynamics(states_with(0.4, 0.5, 1e-3, com=(-0.01, 0.01)), ctx)
    assert not torch.allclose(d1, d3)
    steady, _ = models.dynamics(states_with(0.4, 0.5, 1e-3), context_with_path(steady_path(), 3))
    assert not torch.allclose(d1, steady)


def test_kinematic_dynamic_motion_needs_the_physics_structure():
    with pytest.raises(ValueError, match="dynamic_motion_params: false needs structure: physics"):
        LearnedModelsConfig.model_validate(
            {**tiny_config().model_dump(), "dynamic_motion_params": False}
        )


@pytest.mark.parametrize(("quasi_static", "moment_arm"), MOTION)
def test_physics_filter_runs_and_has_exact_gradients(quasi_static, moment_arm):
    """A dual filter on the physics models: a step is finite, and the gradient of the
    updated belief with respect to the observation matches finite differences."""
    torch.manual_seed(1)
    config = physics_config(quasi_static, moment_arm=moment_arm)
    filt = build_filter("dual", models_config=config).to(F64)
    assert isinstance(filt, DualFilter)
    mean, cov = prior(1, F64)
    mean[0, 3:] = 0.1
    ctx = context_with_path(accelerating_path(1.0), 3)
    noise = filt.draw_noise(1, torch.Generator().manual_seed(0), F64, num_sigma_points=12)

    def updated(z):
        m, c, _ = filt(mean, cov, z, ctx, noise)
        return m[:, 3:]

    z = torch.tensor([[0.002, 0.0, 0.01, 1.0 * GRAVITY * 0.25, 0.1]], dtype=F64, requires_grad=True)
    assert torch.isfinite(updated(z)).all()
    assert gradcheck(updated, (z,), eps=1e-6, atol=1e-5)


def test_physics_structure_refuses_vision_only_models():
    cfg = tiny_config().model_copy(update={"structure": "physics"})
    with pytest.raises(ValueError, match="physics-structured models need tactile"):
        build_learned_models(cfg, vision_only=True)


def _silence(mlp: torch.nn.Module) -> None:
    """Zero a network's last linear layer, so it outputs exactly 0."""
    last = [m for m in mlp.modules() if isinstance(m, torch.nn.Linear)][-1]
    torch.nn.init.zeros_(last.weight)
    torch.nn.init.zeros_(last.bias)


@pytest.mark.parametrize("moment_arm", ["gyration", "pressure"])
def test_limit_surface_motion_is_the_pads_quasi_static_step_plus_the_network(moment_arm):
    """With the networks silenced, Δψ is the limit surface's step of the pad from sample t-1
    to t, for the footprint in the context, the sigma point's CoM and ℓ = κ √(J/A) or
    κ × the pressure's mean distance from the CoM."""
    from pushtoknow.models.contact import (
        limit_surface_push,
        pressure_moment_arm,
        radius_of_gyration,
    )

    _, models = physics_models(quasi_static="limit-surface", moment_arm=moment_arm)
    _silence(models.dynamics.process_net.quasi_static)
    _silence(models.dynamics.process_net.dynamic)
    ctx = context_with_path(steady_path(), 4)
    states = states_with(0.5, 0.5, 1e-3, com=(0.01, -0.02))
    delta, _ = models.dynamics(states, ctx)
    com = torch.tensor([[[0.01, -0.02]]], dtype=F64)
    if moment_arm == "gyration":
        base = radius_of_gyration(ctx.footprint)
    else:
        base = pressure_moment_arm(ctx.footprint, com)[:, 0]
        assert base.item() < 0.9 * radius_of_gyration(ctx.footprint).item()  # off-centre CoM
    arm = models.dynamics.limit_surface.log_ratio.exp() * base
    expected = limit_surface_push(
        states[..., :3],
        com,
        ctx.pad_window[:, 1],
        ctx.pad_window[:, 2],
        ctx.footprint,
        0.005,
        arm,
        0.001,
        0.0005,
    ).twist
    assert expected[..., 2].abs().item() > 1e-4  # the off-centre CoM turns the square
    assert torch.allclose(delta, expected, rtol=1e-9, atol=1e-12)


def test_a_pressure_moment_arm_needs_the_limit_surface():
    with pytest.raises(ValueError, match="moment_arm: pressure needs quasi_static: limit-surface"):
        LearnedModelsConfig.model_validate(
            {**physics_config().model_dump(), "moment_arm": "pressure"}
        )
    assert "pressure-arm" in physics_config("limit-surface", moment_arm="pressure").label
