"""Physical constraints on sigma points, and the projection used for network inputs only.

docs/DESIGN.md §6 step 1 (retain and reintroduce): a sigma point that violates a constraint is
never fed
to a model as it is; the model sees `project(point)`. The filter keeps the point's original value
in every moment, so the spread of the belief is preserved.

State layout: s = (ψ, φ̃), ψ the pose (pose_dim values), φ̃ the normalised parameters
(`pushtoknow.common.params`, order PARAM_NAMES = mass, friction, com_x, com_y, inertia).
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence

import torch

from pushtoknow.common.errors import ShapeError
from pushtoknow.common.params import PARAM_NAMES, linear_param_affine, normalise_param


class StateConstraint(ABC):
    """A set of valid states; `project` maps every state into it (a no-op on valid ones)."""

    @abstractmethod
    def is_valid(self, states: torch.Tensor, context: object) -> torch.Tensor:
        """states (B, C, D) → (B, C) bool."""

    @abstractmethod
    def project(self, states: torch.Tensor, context: object) -> torch.Tensor:
        """states (B, C, D) → (B, C, D), every row valid; valid rows unchanged."""


class BoxConstraint(StateConstraint):
    """lower ≤ s_k ≤ upper, component-wise on chosen state indices; projection = clamp.

    lower/upper: dicts state index → bound in state coordinates (normalised for parameters).
    """

    def __init__(
        self, lower: dict[int, float] | None = None, upper: dict[int, float] | None = None
    ):
        self.lower = dict(lower or {})
        self.upper = dict(upper or {})

    def _bounds(self, states: torch.Tensor) -> tuple[torch.Tensor, torch.Tensor]:
        d = states.shape[-1]
        inf = float("inf")
        lo = [self.lower.get(i, -inf) for i in range(d)]
        hi = [self.upper.get(i, inf) for i in range(d)]
        for i in (*self.lower, *self.upper):
            if not 0 <= i < d:
                raise ShapeError(f"constraint index {i} outside state dimension D={d}")
        return states.new_tensor(lo), states.new_tensor(hi)

    def is_valid(self, states: torch.Tensor, context: object) -> torch.Tensor:
        lo, hi = self._bounds(states)
        return ((states >= lo) & (states <= hi)).all(-1)

    def project(self, states: torch.Tensor, context: object) -> torch.Tensor:
        lo, hi = self._bounds(states)
        return torch.maximum(torch.minimum(states, hi), lo)  # identity (and gradient 1) inside


class ParamPositivityConstraint(BoxConstraint):
    """m > 0, μ > 0, I_z > 0 (SI), as lower bounds on the normalised parameters.

    A strict inequality has no closest point, so each bound is a small positive SI floor
    (defaults: 1 g, μ 0.01, 1e-6 kg·m²), mapped to normalised units (`common.params`; with
    m, μ and I_z filtered in log space every finite state satisfies them already).
    pose_dim: number of pose components before the parameters in the state.
    """

    def __init__(
        self,
        pose_dim: int = 3,
        floors_si: dict[str, float] | None = None,
        param_names: Sequence[str] = PARAM_NAMES,
    ):
        floors = floors_si if floors_si is not None else DEFAULT_POSITIVE_FLOORS_SI
        lower = {
            pose_dim + list(param_names).index(name): normalise_param(name, floor)
            for name, floor in floors.items()
        }
        super().__init__(lower=lower)
        self.floors_si = dict(floors)


DEFAULT_POSITIVE_FLOORS_SI: dict[str, float] = {"mass": 1e-3, "friction": 1e-2, "inertia": 1e-6}


def point_in_polygon(points: torch.Tensor, polygon: torch.Tensor) -> torch.Tensor:
    """Even-odd (ray casting) test. points (B, C, 2), polygon (B, V, 2) → (B, C) bool.

    Polygons with fewer vertices may be padded by repeating a vertex (zero-length edges never
    count as crossings). Points exactly on the boundary may go either way.
    """
    px, py = points[..., 0].unsqueeze(-1), points[..., 1].unsqueeze(-1)  # (B, C, 1)
    a = polygon.unsqueeze(1)  # (B, 1, V, 2)
    b = torch.roll(polygon, shifts=-1, dims=1).unsqueeze(1)
    ax, ay, bx, by = a[..., 0], a[..., 1], b[..., 0], b[..., 1]
    straddles = (ay > py) != (by > py)
    dy = torch.where(straddles, by - ay, torch.ones_like(by))
    x_cross = ax + (py - ay) * (bx - ax) / dy
    crossings = (straddles & (px < x_cross)).sum(-1)
    return crossings % 2 == 1


def _closest_on_edges(
    points: torch.Tensor, polygon: torch.Tensor
) -> tuple[torch.Tensor, torch.Tensor, torch.Tensor]:
    """Closest boundary point (..., 2), its edge index (...) and edge parameter t ∈ [0, 1] (...)
    for points (B, C, 2) and polygons (B, V, 2); edge k runs from vertex k to vertex k + 1."""
    a = polygon.unsqueeze(1)  # (B, 1, V, 2)
    b = torch.roll(polygon, shifts=-1, dims=1).unsqueeze(1)
    p = points.unsqueeze(-2)  # (B, C, 1, 2)
    edge = b - a
    len2 = (edge * edge).sum(-1)
    t = ((p - a) * edge).sum(-1) / torch.where(len2 > 0, len2, torch.ones_like(len2))
    t = t.clamp(0.0, 1.0)
    foot = a + t.unsqueeze(-1) * edge  # (B, C, V, 2)
    dist2 = ((foot - p) ** 2).sum(-1)
    best = dist2.argmin(-1, keepdim=True)  # (B, C, 1)
    closest = torch.gather(foot, -2, best.unsqueeze(-1).expand(*best.shape, 2)).squeeze(-2)
    return closest, best.squeeze(-1), torch.gather(t, -1, best).squeeze(-1)


def closest_point_on_polygon(points: torch.Tensor, polygon: torch.Tensor) -> torch.Tensor:
    """Closest point on the polygon boundary. points (B, C, 2), polygon (B, V, 2) → (B, C, 2)."""
    return _closest_on_edges(points, polygon)[0]


def _inward_edge_normals(polygon: torch.Tensor) -> torch.Tensor:
    """Unit inward normals (B, V, 2) of the edges of polygons (B, V, 2), any orientation;
    zero for zero-length edges."""
    edge = torch.roll(polygon, shifts=-1, dims=1) - polygon
    x, y = polygon[..., 0], polygon[..., 1]
    area2 = (x * torch.roll(y, -1, 1) - torch.roll(x, -1, 1) * y).sum(-1)  # 2 × signed area
    sign = torch.where(area2 >= 0, 1.0, -1.0).to(polygon.dtype).view(-1, 1, 1)
    normal = sign * torch.stack([-edge[..., 1], edge[..., 0]], dim=-1)  # left normal if CCW
    return normal / normal.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(polygon.dtype).tiny)


def project_into_polygon(
    points: torch.Tensor, polygon: torch.Tensor, margin: float
) -> torch.Tensor:
    """Move points (B, C, 2) into polygons (B, V, 2): closest boundary point q, then `margin`
    inwards along the inward normal of q's edge (at a vertex, the mean of both edges' normals).
    Points already inside are returned unchanged. Inside whenever margin is below the local
    feature size of the polygon (convex or not); otherwise the vertex mean is used."""
    inside = point_in_polygon(points, polygon)
    q, edge_idx, t = _closest_on_edges(points, polygon)
    normals = _inward_edge_normals(polygon)  # (B, V, 2)
    v = polygon.shape[1]

    def normal_of(idx: torch.Tensor) -> torch.Tensor:
        return torch.gather(normals, 1, (idx % v).unsqueeze(-1).expand(*idx.shape, 2))

    n_edge = normal_of(edge_idx)
    at_start = (t <= 0).unsqueeze(-1)
    at_end = (t >= 1).unsqueeze(-1)
    n = torch.where(at_start, n_edge + normal_of(edge_idx - 1), n_edge)
    n = torch.where(at_end, n_edge + normal_of(edge_idx + 1), n)
    n = n / n.norm(dim=-1, keepdim=True).clamp_min(torch.finfo(points.dtype).tiny)
    moved = q + margin * n
    centre = polygon.mean(dim=1, keepdim=True).expand_as(moved)
    moved = torch.where(point_in_polygon(moved, polygon).unsqueeze(-1), moved, centre)
    return torch.where(inside.unsqueeze(-1), points, moved)


class ComInFootprintConstraint(StateConstraint):
    """The centre of mass (c_x, c_y) lies inside the object's footprint polygon.

    The polygon comes from the context: ``getattr(context, footprint_attr)`` of shape (B, V, 2),
    metres, object frame (origin at the footprint centroid), vertices in order. The CoM state
    components are normalised; they are mapped to metres with the catalogue ranges.

    Projection of an outside point (`project_into_polygon`): its closest boundary point,
    moved `margin_m` (default 1 mm) inwards along the boundary's inward normal. Inside for
    convex and non-convex footprints whose features are larger than the margin; otherwise
    the vertex mean is used.
    """

    def __init__(
        self,
        com_indices: tuple[int, int] = (5, 6),
        footprint_attr: str = "footprint",
        margin_m: float = 1e-3,
        com_names: tuple[str, str] = ("com_x", "com_y"),
    ):
        self.com_indices = com_indices
        self.footprint_attr = footprint_attr
        self.margin_m = margin_m
        affine = [linear_param_affine(n) for n in com_names]
        self._offset = tuple(a[0] for a in affine)
        self._scale = tuple(a[1] for a in affine)

    def _footprint(self, states: torch.Tensor, context: object) -> torch.Tensor:
        poly = getattr(context, self.footprint_attr, None)
        if poly is None:
            raise ShapeError(
                f"ComInFootprintConstraint needs context.{self.footprint_attr} of shape "
                f"(B={states.shape[0]}, V, 2); the context has none"
            )
        if poly.ndim != 3 or poly.shape[0] != states.shape[0] or poly.shape[-1] != 2:
            raise ShapeError(
                f"context.{self.footprint_attr}: expected shape (B={states.shape[0]}, V, 2), "
                f"got {tuple(poly.shape)}"
            )
        return poly.to(states.dtype)

    def _com_metres(self, states: torch.Tensor) -> torch.Tensor:
        off = states.new_tensor(self._offset)
        scale = states.new_tensor(self._scale)
        return off + scale * states[..., list(self.com_indices)]

    def is_valid(self, states: torch.Tensor, context: object) -> torch.Tensor:
        return point_in_polygon(self._com_metres(states), self._footprint(states, context))

    def project(self, states: torch.Tensor, context: object) -> torch.Tensor:
        poly = self._footprint(states, context)
        com = self._com_metres(states)
        inside = point_in_polygon(com, poly)
        if bool(inside.all()):
            return states
        # project only the outside points: gather them with their object's polygon
        b_idx, c_idx = torch.nonzero(~inside, as_tuple=True)
        bad_poly = poly[b_idx]  # (N, V, 2)
        bad_com = com[b_idx, c_idx].unsqueeze(1)  # (N, 1, 2)
        moved = project_into_polygon(bad_com, bad_poly, self.margin_m)
        off = states.new_tensor(self._offset)
        scale = states.new_tensor(self._scale)
        idx = list(self.com_indices)
        new_rows = states[b_idx, c_idx].clone()
        new_rows[:, idx] = (moved.squeeze(1) - off) / scale
        out = states.clone()
        out[b_idx, c_idx] = new_rows
        return out


class CompositeConstraint(StateConstraint):
    """All of several constraints. Projections are applied in order, so the constraints should
    act on disjoint state components (then the result satisfies all of them)."""

    def __init__(self, constraints: Sequence[StateConstraint]):
        self.constraints = tuple(constraints)

    def is_valid(self, states: torch.Tensor, context: object) -> torch.Tensor:
        valid = torch.ones(states.shape[:-1], dtype=torch.bool, device=states.device)
        for c in self.constraints:
            valid = valid & c.is_valid(states, context)
        return valid

    def project(self, states: torch.Tensor, context: object) -> torch.Tensor:
        for c in self.constraints:
            states = c.project(states, context)
        return states


def default_object_constraints(pose_dim: int = 3, with_footprint: bool = True) -> StateConstraint:
    """m, μ, I_z > 0 and (optionally) CoM inside the footprint, for s = (ψ, φ̃) ∈ R^(pose_dim+5)."""
    parts: list[StateConstraint] = [ParamPositivityConstraint(pose_dim)]
    if with_footprint:
        cx = pose_dim + PARAM_NAMES.index("com_x")
        cy = pose_dim + PARAM_NAMES.index("com_y")
        parts.append(ComInFootprintConstraint(com_indices=(cx, cy)))
    return CompositeConstraint(parts)
