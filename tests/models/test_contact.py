"""Quasi-static pushing through the ellipsoidal limit surface against closed forms."""

import math

import numpy as np
import pytest
import torch
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.optimize import minimize
from torch.autograd import gradcheck

from pushtoknow.common.errors import ShapeError
from pushtoknow.models.contact import (
    PRESSURE_ARM_FLOOR,
    PRESSURE_GRID,
    limit_surface_push,
    pad_contact,
    pressure_moment_arm,
    radius_of_gyration,
)
from pushtoknow.testbed.object_refs import load_object_spec

F64 = torch.float64
H = 0.04  # half side of the test square (m)
R_PAD = 0.005
HARD = (0.0, 1e-12)  # reach, softness: touching is a step at zero penetration


def square(half=H):
    return torch.tensor([[-half, -half], [half, -half], [half, half], [-half, half]], dtype=F64)


def push_square(pad_y=0.0, advance=0.002, com=(0.0, 0.0), pose=(0.0, 0.0, 0.0), arm=0.02, gap=0.0):
    """A pad touching the square's left edge (at height pad_y, object frame) from outside
    with `gap`, moving by `advance` along the object's +x; pose of the square (world)."""
    x, y, th = pose
    rot = torch.tensor([[math.cos(th), -math.sin(th)], [math.sin(th), math.cos(th)]], dtype=F64)
    start_obj = torch.tensor([-H - R_PAD - gap, pad_y], dtype=F64)
    start = rot @ start_obj + torch.tensor([x, y], dtype=F64)
    end = start + rot @ torch.tensor([advance, 0.0], dtype=F64)
    return limit_surface_push(
        torch.tensor([[list(pose)]], dtype=F64),
        torch.tensor([[list(com)]], dtype=F64),
        start[None],
        end[None],
        square()[None],
        R_PAD,
        torch.tensor([arm], dtype=F64),
        *HARD,
    )


def test_radius_of_gyration_of_a_square_a_disc_and_an_l_shape():
    assert radius_of_gyration(square()[None]).item() == pytest.approx(math.sqrt((2 * H) ** 2 / 6))
    k = torch.arange(720, dtype=F64) * 2 * math.pi / 720
    disc = 0.05 * torch.stack([k.cos(), k.sin()], -1)
    assert radius_of_gyration(disc[None]).item() == pytest.approx(0.05 / math.sqrt(2), rel=1e-4)
    # L: a 2×1 bar plus a 1×1 block on its left end (units of 1 cm); exact by parallel axes
    ell = torch.tensor([[0, 0], [2, 0], [2, 1], [1, 1], [1, 2], [0, 2]], dtype=F64) * 0.01
    blocks = [(2.0, (1.0, 0.5), (2.0, 1.0)), (1.0, (0.5, 1.5), (1.0, 1.0))]  # area, centre, size
    area = sum(a for a, _, _ in blocks)
    cx = sum(a * c[0] for a, c, _ in blocks) / area
    cy = sum(a * c[1] for a, c, _ in blocks) / area
    polar = sum(
        a * ((w * w + h * h) / 12 + (c[0] - cx) ** 2 + (c[1] - cy) ** 2) for a, c, (w, h) in blocks
    )
    centred = ell - torch.tensor([cx, cy], dtype=F64) * 0.01
    assert radius_of_gyration(centred[None]).item() == pytest.approx(
        math.sqrt(polar / area) * 0.01, rel=1e-9
    )


def test_a_push_through_the_com_translates_by_the_pads_advance():
    out = push_square(advance=0.003)
    assert torch.allclose(out.twist[0, 0], torch.tensor([0.003, 0.0, 0.0], dtype=F64))
    assert out.force_factor.item() == pytest.approx(1.0)
    assert torch.allclose(out.normal[0, 0], torch.tensor([1.0, 0.0], dtype=F64))


@pytest.mark.parametrize("pad_y", [0.02, -0.015])
def test_an_off_centre_push_follows_the_ellipsoidal_limit_surface(pad_y):
    """Closed form for the left edge pushed along +x at height y above a CoM at the centre:
    r × n = -y, ρ = -y / ℓ, the CoM moves δ/(1 + ρ²) along x and the square turns by
    -δ y / (ℓ² (1 + ρ²)) (clockwise when pushed above the CoM)."""
    arm, adv = 0.025, 0.002
    out = push_square(pad_y=pad_y, advance=adv, arm=arm)
    rho_sq = (pad_y / arm) ** 2
    expected = torch.tensor([adv / (1 + rho_sq), 0.0, -adv * pad_y / (arm**2 * (1 + rho_sq))])
    assert torch.allclose(out.twist[0, 0], expected.to(F64))
    assert out.force_factor.item() == pytest.approx(1 / math.sqrt(1 + rho_sq))


def test_the_frame_origin_moves_with_the_rotation_about_an_offset_com():
    """With the CoM at c, the footprint frame's origin moves by δc + δθ (c_y, -c_x)."""
    com, arm, adv = (0.01, -0.012), 0.025, 0.002
    out = push_square(pad_y=0.01, advance=adv, com=com, arm=arm)
    lever = (-H - com[0]) * 0.0 - (0.01 - com[1]) * 1.0  # r × n with n = +x
    rho_sq = (lever / arm) ** 2
    turn = adv * lever / (arm**2 * (1 + rho_sq))
    expected = [adv / (1 + rho_sq) + turn * com[1], -turn * com[0], turn]
    assert torch.allclose(out.twist[0, 0], torch.tensor(expected, dtype=F64))


def test_a_pad_short_of_the_outline_does_not_move_the_object():
    out = push_square(advance=0.002, gap=0.003)
    assert out.touching.item() == 0.0
    assert torch.equal(out.twist, torch.zeros_like(out.twist))


def test_a_touching_pad_moves_the_object_by_its_advance_whatever_the_overlap():
    """The velocity form: an outline seen 2 mm too large (the pad appears inside it) gives
    the same step as an exact one."""
    exact = push_square(advance=0.002)
    overlapping = push_square(advance=0.002, gap=-0.002)
    assert torch.allclose(exact.twist, overlapping.twist)


def test_a_pad_moving_away_does_not_pull():
    out = push_square(advance=-0.0005, gap=-0.001)  # still overlapping after the move
    assert out.touching.item() == 1.0
    assert torch.equal(out.twist, torch.zeros_like(out.twist))


def test_a_pad_centre_inside_the_outline_pushes_out_through_the_nearest_edge():
    contact = pad_contact(
        torch.tensor([[[-H + 0.003, 0.0]]], dtype=F64),
        torch.zeros(1, 1, 2, dtype=F64),
        square()[None],
        R_PAD,
    )
    assert torch.allclose(contact.normal[0, 0], torch.tensor([1.0, 0.0], dtype=F64))
    assert contact.penetration.item() == pytest.approx(R_PAD + 0.003)


@given(
    x=st.floats(-0.2, 0.2),
    y=st.floats(-0.2, 0.2),
    th=st.floats(-3.0, 3.0),
    pad_y=st.floats(-0.035, 0.035),
    cx=st.floats(-0.02, 0.02),
    cy=st.floats(-0.02, 0.02),
)
@settings(max_examples=40, deadline=None)
def test_the_step_is_the_same_in_any_placement_of_the_scene(x, y, th, pad_y, cx, cy):
    """Moving and turning slider and pad together rotates the displacement and leaves the
    turn unchanged (the model has no preferred frame)."""
    here = push_square(pad_y=pad_y, com=(cx, cy)).twist[0, 0]
    there = push_square(pad_y=pad_y, com=(cx, cy), pose=(x, y, th)).twist[0, 0]
    c, s = math.cos(th), math.sin(th)
    rotated = torch.stack([c * here[0] - s * here[1], s * here[0] + c * here[1], here[2]])
    assert torch.allclose(there, rotated, atol=1e-12)


def test_gradients_in_pose_and_com_are_exact():
    start = torch.tensor([[-H - R_PAD, 0.01]], dtype=F64)
    end = start + torch.tensor([[0.002, 0.0005]], dtype=F64)
    arm = torch.tensor([0.025], dtype=F64)

    def step(pose, com):
        return limit_surface_push(
            pose, com, start, end, square()[None], R_PAD, arm, 0.001, 0.0005
        ).twist

    pose = torch.tensor([[[0.001, -0.002, 0.03]]], dtype=F64, requires_grad=True)
    com = torch.tensor([[[0.004, -0.006]]], dtype=F64, requires_grad=True)
    assert gradcheck(step, (pose, com), eps=1e-7, atol=1e-6)


def test_mismatched_shapes_are_refused():
    with pytest.raises(ShapeError, match="com"):
        limit_surface_push(
            torch.zeros(1, 2, 3, dtype=F64),
            torch.zeros(1, 3, 2, dtype=F64),
            torch.zeros(1, 2, dtype=F64),
            torch.zeros(1, 2, dtype=F64),
            square()[None],
            R_PAD,
            torch.tensor([0.02], dtype=F64),
            *HARD,
        )


def _grid_inside_square(half=H):
    """The points `pressure_moment_arm` loads on a square: the midpoints of its grid."""
    u = (torch.arange(PRESSURE_GRID, dtype=F64) + 0.5) / PRESSURE_GRID * 2 * half - half
    gx, gy = torch.meshgrid(u, u, indexing="ij")
    return torch.stack([gx.reshape(-1), gy.reshape(-1)], -1)


def test_pressure_arm_of_a_centred_square_and_disc_is_the_mean_distance():
    side = 2 * H
    exact_square = side * (math.sqrt(2) + math.log(1 + math.sqrt(2))) / 6
    got = pressure_moment_arm(square()[None], torch.zeros(1, 1, 2, dtype=F64)).item()
    assert got == pytest.approx(exact_square, rel=2e-3)
    k = torch.arange(360, dtype=F64) * 2 * math.pi / 360
    disc = 0.05 * torch.stack([k.cos(), k.sin()], -1)
    got = pressure_moment_arm(disc[None], torch.zeros(1, 1, 2, dtype=F64)).item()
    assert got == pytest.approx(2 * 0.05 / 3, rel=2e-2)  # a 16-point grid over a disc


def _closest_to_uniform_loads(pts: np.ndarray, com) -> np.ndarray:
    """Reference: shares w ≥ 0 minimising Σ (n w_i − 1)² with Σ w_i = 1 and Σ w_i p_i = com
    (the testbed's support-load problem), through its convex dual: w_i = max(0, λ·a_i),
    a_i = (1, p_i / H), with λ minimising Σ ½ max(0, λ·a_i)² − λ·b, by BFGS."""
    a = np.hstack([np.ones((len(pts), 1)), pts / H])
    b = np.array([1.0, com[0] / H, com[1] / H])

    def dual(lam):
        w = np.maximum(0.0, a @ lam)
        return 0.5 * float(w @ w) - float(lam @ b), a.T @ w - b

    res = minimize(
        dual,
        np.array([1.0 / len(pts), 0.0, 0.0]),
        jac=True,
        method="BFGS",
        options={"gtol": 1e-13, "maxiter": 10_000},
    )
    w = np.maximum(0.0, a @ res.x)
    assert np.allclose(a.T @ w, b, atol=1e-9), res.message
    return w


@pytest.mark.parametrize("com", [(0.005, 0.0), (0.012, -0.004), (0.03, 0.02), (-0.025, 0.03)])
def test_pressure_arm_is_that_of_the_closest_to_uniform_support_loads(com):
    """Against an independent solver of the same problem on the same points, lifted off where
    the linear pressure would be negative (the last two CoMs)."""
    pts = _grid_inside_square().numpy()
    w = _closest_to_uniform_loads(pts, com)
    expected = float((w * np.linalg.norm(pts - np.asarray(com), axis=1)).sum())
    got = pressure_moment_arm(square()[None], torch.tensor([[com]], dtype=F64)).item()
    assert got == pytest.approx(expected, rel=1e-6)


def test_an_off_centre_com_shortens_a_squares_pressure_arm():
    coms = torch.tensor([[[0.0, 0.0], [0.01, 0.0], [0.02, 0.0], [0.03, 0.0]]], dtype=F64)
    arms = pressure_moment_arm(square()[None], coms)[0]
    assert bool((arms[1:] < arms[:-1]).all())
    assert arms[-1].item() < 0.8 * arms[0].item()


def test_a_com_at_the_edge_or_outside_gets_the_floor_arm():
    floor = PRESSURE_ARM_FLOOR * radius_of_gyration(square()[None]).item()
    coms = torch.tensor([[[-0.034, 0.034], [0.039, 0.0], [0.2, -0.1]]], dtype=F64)
    arms = pressure_moment_arm(square()[None], coms)[0]
    assert arms.tolist() == pytest.approx([floor] * 3, rel=1e-12)


def test_pressure_arm_in_float32_survives_coms_no_pressure_can_carry():
    """Sigma points of a float32 filter may put the CoM far outside the outline, where the
    carried set of points is nearly singular (a float32 solve failed on this triangle): the
    arm stays finite, in float32, and never below the floor."""
    tri = load_object_spec("catalogue:225").footprint.vertices
    fp = torch.tensor(np.asarray(tri), dtype=torch.float32)[None]
    g = torch.linspace(-0.08, 0.08, 80)
    coms = torch.stack(torch.meshgrid(g, g, indexing="ij"), -1).reshape(1, -1, 2)
    arms = pressure_moment_arm(fp, coms)
    assert arms.dtype == torch.float32 and bool(torch.isfinite(arms).all())
    floor = PRESSURE_ARM_FLOOR * radius_of_gyration(fp.double()).item()
    assert arms.min().item() == pytest.approx(floor, rel=1e-6)


def test_pressure_arm_gradient_in_the_com_is_exact():
    fp = square()[None]
    com = torch.tensor([[[0.006, -0.011], [0.031, 0.02]]], dtype=F64, requires_grad=True)
    assert gradcheck(lambda c: pressure_moment_arm(fp, c), (com,), eps=1e-7, atol=1e-6)


@settings(max_examples=30, deadline=None)
@given(st.floats(-0.06, 0.06), st.floats(-0.06, 0.06), st.floats(0.3, 1.0), st.floats(0.0, 3.2))
def test_pressure_arm_is_finite_and_bounded_for_any_com(cx, cy, aspect, th):
    """Sigma points may put the CoM anywhere, even outside the outline: ℓ stays positive and
    within the farthest point of the footprint from the CoM."""
    c, s = math.cos(th), math.sin(th)
    fp = square() * torch.tensor([1.0, aspect], dtype=F64)
    fp = fp @ torch.tensor([[c, s], [-s, c]], dtype=F64)
    com = torch.tensor([[[cx, cy]]], dtype=F64)
    arm = pressure_moment_arm(fp[None], com).item()
    farthest = (fp - com[0]).norm(dim=-1).max().item()
    assert math.isfinite(arm)
    assert 0.0 < arm <= farthest + 1e-9
