"""Quasi-static pushing by a round frictionless pad: the ellipsoidal limit surface (Lynch,
Maekawa and Tanie, 1992), batched over sigma points and differentiable in the pose and the CoM.

A slider whose support pressure is centred at its CoM c resists a planar wrench (f, τ) about c
on the ellipsoid |f|²/f_max² + τ²/τ_max² = 1, f_max = μ m g, τ_max = μ m g · ℓ. A frictionless
pad touching the outline at point q with inward unit normal n pushes with f = f_n n, τ = f_n
(r × n), r = q − c. The slider's twist is normal to the ellipsoid, (v, ω) ∝ (n, (r × n)/ℓ²),
and the contact point keeps up with the pad along n. Writing ρ = (r × n)/ℓ, a touching pad
that advances by δ along n moves the CoM by δ n / (1 + ρ²) and turns the slider
by δ (r × n) / (ℓ² (1 + ρ²)); the pad force is f_n = μ m g / √(1 + ρ²). m and μ drop out
of the motion: quasi-static pushing reveals the CoM and ℓ, not the mass.

ℓ is the limit surface's moment arm; for a uniform pressure it is close to the footprint's
radius of gyration, so ℓ = κ · √(J/A) with J the polar second moment of the footprint about
its centroid, A its area and κ a learned scalar (`radius_of_gyration`). `pressure_moment_arm`
gives instead the arm of the support pressure that a given CoM implies.
"""

from __future__ import annotations

from dataclasses import dataclass

import torch

from pushtoknow.filters.tensor_shapes import expect_shape


@dataclass(frozen=True)
class PadContact:
    """The pad against the outline, per sigma point (B, S, ·), object frame (m).

    point: the outline's point nearest the pad's centre; normal: unit, from the pad into the
    object; penetration: how far the pad's rim reaches past the outline along the normal
    after the pad's move (m, negative: a gap)."""

    point: torch.Tensor
    normal: torch.Tensor
    penetration: torch.Tensor


@dataclass(frozen=True)
class LimitSurfacePush:
    """One quasi-static step per sigma point: twist (B, S, 3) the slider frame's displacement
    (Δx, Δy world m, Δθ rad); normal (B, S, 2) the contact normal (world, unit, pad → object);
    force_factor (B, S) = 1/√(1 + ρ²) (pad force / μ m g while pushing); touching (B, S) in
    (0, 1)."""

    twist: torch.Tensor
    normal: torch.Tensor
    force_factor: torch.Tensor
    touching: torch.Tensor


def radius_of_gyration(footprint: torch.Tensor) -> torch.Tensor:
    """√(J/A) (B,) of polygons footprint (B, V, 2) (m, counter-clockwise, centroid at the
    origin): J the polar second moment of area about the origin, exact for any simple
    polygon, convex or not."""
    a, b = footprint, footprint.roll(-1, dims=1)
    cross = a[..., 0] * b[..., 1] - b[..., 0] * a[..., 1]
    area = 0.5 * cross.sum(-1)
    quad = (a.square() + a * b + b.square()).sum(-1)
    polar = (cross * quad).sum(-1) / 12.0
    return (polar / area).clamp_min(1e-12).sqrt()


PRESSURE_GRID = 16  # points per side of the grid over the footprint's bounding box
PRESSURE_ITERATIONS = 32  # active-set passes of the lifted-off pressure (≤ 12 seen on novel shapes)
PRESSURE_RIDGE = 1e-10  # added to the 3 × 3 normal equations (solved in float64)
PRESSURE_CENTRE_TOLERANCE = 1e-4  # m: a pressure centred farther from the CoM cannot carry it
PRESSURE_ARM_FLOOR = 0.3  # ℓ ≥ this × the radius of gyration, and ℓ of a CoM none can carry


def pressure_moment_arm(footprint: torch.Tensor, com: torch.Tensor) -> torch.Tensor:
    """ℓ (B, S) = Σ w_i ‖p_i − c‖ (m): the limit surface's τ_max / f_max for the support
    pressure of a rigid slider on an elastic floor whose CoM is at com (B, S, 2) (object
    frame, m), over footprint (B, V, 2) (m, centroid at the origin).

    The pressure is the one closest to uniform with its centre at the CoM: linear in position,
    lifted off where it would be negative (w_i = max(0, a + b·p_i), a and b set by Σ w_i = 1
    and Σ w_i p_i = c; the least-squares problem's optimality conditions). p_i: the points of
    a `PRESSURE_GRID`² grid over the bounding box that lie inside the outline. A centred CoM
    gives ℓ ≈ 0.93 × the radius of gyration; a CoM 3 cm off-centre between the floor and
    1.2 × the centred arm on catalogue shapes (rectangles: 0.6–0.8 ×).

    Differentiable in c wherever the grid's points can carry the CoM. A CoM they cannot
    carry (outside their hull: beyond the outline, or within about half a grid cell of it)
    gets the floor, `PRESSURE_ARM_FLOOR` × the radius of gyration, which is also a lower
    bound everywhere: ℓ jumps there, with zero gradient beyond. Solved in float64 whatever
    the inputs' dtype (a float32 solve of a nearly singular carried set can fail)."""
    dtype = com.dtype
    footprint, com = footprint.double(), com.double()
    b, s = com.shape[:2]
    expect_shape(footprint, "footprint", [("B", b), ("V", None), ("2", 2)])
    lo, hi = footprint.amin(1), footprint.amax(1)
    u = torch.arange(PRESSURE_GRID, dtype=footprint.dtype, device=footprint.device) + 0.5
    u = u / PRESSURE_GRID
    gx, gy = torch.meshgrid(u, u, indexing="ij")
    unit = torch.stack([gx.reshape(-1), gy.reshape(-1)], -1)
    pts = lo[:, None] + unit[None] * (hi - lo)[:, None]  # (B, P, 2)
    inside = _inside(pts, footprint).to(footprint.dtype)  # (B, P)
    feat = torch.cat([torch.ones_like(pts[..., :1]), pts], -1)  # (B, P, 3)
    outer = (feat[..., :, None] * feat[..., None, :]).reshape(b, -1, 9)  # (B, P, 9)
    target = torch.cat([torch.ones_like(com[..., :1]), com], -1).unsqueeze(-1)  # (B, S, 3, 1)
    # a CoM outside the loaded points' hull (a sigma point off the outline) has no solution:
    # the ridge keeps the solve defined there, and the floor below gives its arm
    ridge = PRESSURE_RIDGE * torch.eye(3, dtype=footprint.dtype, device=footprint.device)

    def solve(active: torch.Tensor, rhs: torch.Tensor) -> torch.Tensor:
        return torch.linalg.solve((active @ outer).reshape(b, s, 3, 3) + ridge, rhs)

    active = inside[:, None].expand(b, s, -1)
    with torch.no_grad():  # find which points carry load; the final solve is differentiable
        for _ in range(PRESSURE_ITERATIONS):
            coef = solve(active, target.detach()).squeeze(-1)  # (B, S, 3)
            carries = inside[:, None] * ((coef @ feat.transpose(1, 2)) > 0)
            if torch.equal(carries, active):
                break
            active = carries
    coef = solve(active, target).squeeze(-1)
    load = torch.relu(coef @ feat.transpose(1, 2)) * active  # (B, S, P)
    total = load.sum(-1)
    gap = pts[:, None] - com[:, :, None]  # (B, S, P, 2)
    dist = (gap * gap).sum(-1).clamp_min(1e-12).sqrt()
    arm = (load * dist).sum(-1) / total.clamp_min(1e-12)
    centre = (load @ pts) / total.clamp_min(1e-12).unsqueeze(-1)  # (B, S, 2)
    carried = (total > 1e-9) & ((centre - com).norm(dim=-1) < PRESSURE_CENTRE_TOLERANCE)
    floor = PRESSURE_ARM_FLOOR * radius_of_gyration(footprint)[:, None]
    return torch.where(carried, arm, floor).maximum(floor).to(dtype)


def _inside(points: torch.Tensor, footprint: torch.Tensor) -> torch.Tensor:
    """(B, P) bool: points (B, P, 2) inside polygons footprint (B, V, 2) (even-odd rule)."""
    a = footprint[:, None]
    b = footprint.roll(-1, dims=1)[:, None]
    p = points[:, :, None]
    ay, by, py = a[..., 1], b[..., 1], p[..., 1]
    straddles = (ay > py) != (by > py)
    dy = torch.where(straddles, by - ay, torch.ones_like(ay))
    x_cross = a[..., 0] + (py - ay) * (b[..., 0] - a[..., 0]) / dy
    return ((straddles & (p[..., 0] < x_cross)).sum(-1) % 2) == 1


def _rotate(vec: torch.Tensor, angle: torch.Tensor, inverse: bool = False) -> torch.Tensor:
    """Rotate vectors (B, S, 2) by angle (B, S) (or by −angle when inverse)."""
    c, s = angle.cos(), angle.sin()
    if inverse:
        s = -s
    x, y = vec[..., 0], vec[..., 1]
    return torch.stack([c * x - s * y, s * x + c * y], dim=-1)


def pad_contact(
    pad: torch.Tensor, move: torch.Tensor, footprint: torch.Tensor, pad_radius: float
) -> PadContact:
    """Contact of a round pad of `pad_radius` (m) centred at pad (B, S, 2) that then moves by
    move (B, S, 2) with the outline footprint (B, V, 2), all in the object frame (m). The
    normal is taken where the pad starts, so a long move into the object keeps the face it
    entered by; a pad centre inside the outline pushes outward through the nearest edge."""
    expect_shape(footprint, "footprint", [("B", pad.shape[0]), ("V", None), ("2", 2)])
    a = footprint[:, None]  # (B, 1, V, 2)
    b = footprint.roll(-1, dims=1)[:, None]
    ab = b - a
    p = pad.unsqueeze(-2)  # (B, S, 1, 2)
    u = (((p - a) * ab).sum(-1) / ab.square().sum(-1).clamp_min(1e-18)).clamp(0.0, 1.0)
    q = a + u.unsqueeze(-1) * ab  # (B, S, V, 2)
    dist_all = (p - q).square().sum(-1)
    idx = dist_all.argmin(-1, keepdim=True)  # (B, S, 1)
    point = q.gather(-2, idx.unsqueeze(-1).expand(*idx.shape, 2)).squeeze(-2)
    sign = torch.where(_inside(pad, footprint), -1.0, 1.0).to(pad.dtype)
    offset = point - pad
    dist = offset.square().sum(-1).clamp_min(1e-14).sqrt()
    normal = sign.unsqueeze(-1) * offset / dist.unsqueeze(-1)
    penetration = pad_radius - sign * dist + (normal * move).sum(-1)
    return PadContact(point, normal, penetration)


def limit_surface_push(
    pose: torch.Tensor,
    com: torch.Tensor,
    pad_from: torch.Tensor,
    pad_to: torch.Tensor,
    footprint: torch.Tensor,
    pad_radius: float,
    moment_arm: torch.Tensor,
    reach: float,
    softness: float,
) -> LimitSurfacePush:
    """The quasi-static step of sliders at poses (B, S, 3) (x, y, θ of the footprint's frame,
    world) with CoMs com (B, S, 2) (object frame, m) while the pad moves from pad_from to
    pad_to (B, 2) (world, m); footprint (B, V, 2) (object frame, m); moment_arm ℓ (B,),
    (B, 1) or (B, S) (m).

    The contact point keeps up with the pad's advance along the normal (the pad's velocity
    form, robust to an outline that is a millimetre off), while the pad touches: weight
    sigmoid((penetration + reach) / softness) (m), so a pad within `reach` of the outline
    counts as touching."""
    b, s = pose.shape[:2]
    expect_shape(com, "com", [("B", b), ("S", s), ("2", 2)])
    expect_shape(pad_from, "pad_from", [("B", b), ("2", 2)])
    expect_shape(pad_to, "pad_to", [("B", b), ("2", 2)])
    th = pose[..., 2]
    start = _rotate(pad_from[:, None] - pose[..., :2], th, inverse=True)
    move = _rotate((pad_to - pad_from)[:, None].expand(b, s, 2), th, inverse=True)
    contact = pad_contact(start, move, footprint, pad_radius)
    n = contact.normal
    r = contact.point - com
    lever = r[..., 0] * n[..., 1] - r[..., 1] * n[..., 0]  # r × n (m)
    arm = moment_arm if moment_arm.dim() == 2 else moment_arm[:, None]
    rho_sq = (lever / arm).square()
    touching = torch.sigmoid((contact.penetration + reach) / softness)
    advance = touching * torch.relu((n * move).sum(-1)) / (1.0 + rho_sq)
    turn = advance * lever / arm.square()
    # the frame's origin is at −c from the CoM: it moves by δc + δθ ẑ × (−c)
    shift = advance.unsqueeze(-1) * n + turn.unsqueeze(-1) * torch.stack(
        [com[..., 1], -com[..., 0]], dim=-1
    )
    twist = torch.cat([_rotate(shift, th), turn.unsqueeze(-1)], dim=-1)
    return LimitSurfacePush(twist, _rotate(n, th), (1.0 + rho_sq).rsqrt(), touching)


SLIDE_SUBSTEPS = 64  # integration steps of a free slide (to rest)


def free_slide(
    pose: torch.Tensor,
    com: torch.Tensor,
    pad: torch.Tensor,
    direction: torch.Tensor,
    speed: torch.Tensor,
    friction_accel: torch.Tensor,
    inertia_ratio: torch.Tensor,
    footprint: torch.Tensor,
    pad_radius: float,
    moment_arm: torch.Tensor,
    reach: float,
    softness: float,
) -> torch.Tensor:
    """How a slider pushed at `speed` and then let go slides to rest: (B, S, 3) the displacement
    of its frame (Δx, Δy world m, Δθ rad) from the release to rest.

    pose (B, S, 3) and com (B, S, 2) (object frame) at the release; pad (B, 2) the pad's centre
    then and direction (B,) its heading (world); speed (B,) its speed (m/s); friction_accel
    (B, S) = μ g (m/s²); inertia_ratio (B, S) k = I_z / (m ℓ²); moment_arm ℓ (B,), (B, 1) or
    (B, S).

    At the release the slider moves as the pad pushed it (`limit_surface_push`: a pad that
    touches); then only the table's friction acts, through the same ellipsoidal limit surface:
    with u the CoM's speed and w = ℓ ω, S = √(u² + w²), du/dt = −μ g u / S and
    dw/dt = −(μ g / k) w / S, the CoM keeps its heading. A centred push (w = 0) slides
    v² / (2 μ g); I_z enters through k, in the turn."""
    eps = 1e-4  # s: a short pad advance gives the pushed twist per unit time
    heading = torch.stack([direction.cos(), direction.sin()], -1)
    pushed = limit_surface_push(
        pose,
        com,
        pad,
        pad + heading * (speed * eps)[:, None],
        footprint,
        pad_radius,
        moment_arm,
        reach,
        softness,
    )
    touching = pushed.touching
    rate = pushed.twist / (eps * touching.clamp_min(1e-6)).unsqueeze(-1)
    rate = rate * (touching > 0.5).to(rate.dtype).unsqueeze(-1)  # a pad off the outline: no push
    th = pose[..., 2]
    c_world = _rotate(com, th)
    omega = rate[..., 2]
    v_com = rate[..., :2] + omega.unsqueeze(-1) * torch.stack(
        [-c_world[..., 1], c_world[..., 0]], -1
    )
    arm = moment_arm if moment_arm.dim() == 2 else moment_arm[:, None]
    u0 = v_com.norm(dim=-1)
    w0 = arm * omega
    s0 = torch.sqrt(u0.square() + w0.square() + 1e-18)
    a = friction_accel.clamp_min(1e-6)
    k = inertia_ratio.clamp_min(1e-6)
    dt = s0 / (a * torch.minimum(torch.ones_like(k), 1.0 / k)) / SLIDE_SUBSTEPS  # to rest
    u, w = u0, w0
    travel = torch.zeros_like(u0)
    turn = torch.zeros_like(u0)
    for _ in range(SLIDE_SUBSTEPS):
        s = torch.sqrt(u.square() + w.square() + 1e-18)
        u_next = torch.relu(u - a * u / s * dt)
        w_next = w.sign() * torch.relu(w.abs() - a / k * w.abs() / s * dt)
        travel = travel + 0.5 * (u + u_next) * dt
        turn = turn + 0.5 * (w + w_next) / arm * dt
        u, w = u_next, w_next
    heading_com = v_com / u0.clamp_min(1e-12).unsqueeze(-1)
    moved = heading_com * travel.unsqueeze(-1) + _rotate(-com, th + turn) - _rotate(-com, th)
    return torch.cat([moved, turn.unsqueeze(-1)], dim=-1)
