"""MJCF scene builder: table, one extruded object on a grid of point supports, the finger pad,
and the overhead camera."""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import shapely
from shapely.geometry import Polygon, box

from pushtoknow.common.params import GRAVITY
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.shapes import Footprint
from pushtoknow.testbed.sim_config import SimConfig

# Collision bits: supports ↔ table (1), object prism ↔ pad (2). The prism never touches the
# table and the pad never touches the supports or the table.
TABLE_BITS = 1
PAD_BITS = 2
OBJECT_RGBA = "0.85 0.35 0.15 1"
PAD_RGBA = "0.2 0.4 0.9 1"
TABLE_RGBA = "0.75 0.75 0.72 1"
MARKER_RGBA = "0.15 0.1 0.1 1"
MARKER_THICKNESS = 0.001  # m: a decal on the top face; vision sees it, depth barely does
PRISM_LIFT = 0.0005  # m: the prism floats just above the table; the supports carry the load
PRESSURE_LENGTH = 0.05  # m: scales positions in the support-load problem (conditioning only)
LOAD_SPRING_REST = -1000.0  # m: a spring this far below loads a support with a constant force
SUPPORT_MASS_SHARE = 0.01  # at most this share of the mass sits in the supports (see build_mjcf)


def support_points(footprint: Footprint, spacing: float, margin: float, com=None) -> np.ndarray:
    """Support points (N, 2), object frame: a grid at `spacing` inside the footprint shrunk by
    `margin`, plus points every `spacing` along that shrunk outline. Their convex hull is the
    footprint less `margin`, except that the ring may cut a sharp corner; if `com` (2,) lies
    outside the hull, the shrunk outline's vertices are added too, so any CoM inside the
    footprint less `margin` can be carried with positive loads."""
    pts, hull, corners = _support_grid(
        footprint.polygon.wkb, len(footprint.vertices), spacing, margin
    )
    if com is not None and not shapely.contains_xy(hull, float(com[0]), float(com[1])):
        pts = np.vstack([pts, corners])
    return pts.copy()


@lru_cache(maxsize=64)
def _support_grid(
    outline_wkb: bytes, n_vertices: int, spacing: float, margin: float
) -> tuple[np.ndarray, Polygon, np.ndarray]:
    """`support_points`' grid and ring (N, 2) of the footprint polygon (its WKB, V vertices),
    their convex hull (grown by 1e-9 m) and the shrunk outline's vertices (K, 2)."""
    outline = shapely.from_wkb(outline_wkb)
    poly = outline.buffer(-margin)
    if poly.is_empty or poly.area <= 0:
        poly = outline.buffer(-0.25 * outline.length / n_vertices)
    minx, miny, maxx, maxy = outline.bounds
    nx = int(np.ceil(max(abs(minx), abs(maxx)) / spacing))
    ny = int(np.ceil(max(abs(miny), abs(maxy)) / spacing))
    xs, ys = np.meshgrid(np.arange(-nx, nx + 1) * spacing, np.arange(-ny, ny + 1) * spacing)
    xs, ys = xs.T.ravel(), ys.T.ravel()  # x-major, as the grid is listed
    inside = shapely.contains_xy(poly.buffer(-0.5 * spacing), xs, ys)
    grid = np.column_stack([xs[inside], ys[inside]])
    if poly.geom_type != "Polygon":  # a thin neck split the shrunk footprint: keep the largest
        poly = max(poly.geoms, key=lambda g: g.area)
    ring = poly.exterior
    n_ring = max(3, int(np.ceil(ring.length / spacing)))
    edge = shapely.get_coordinates(ring.interpolate(np.arange(n_ring) / n_ring, normalized=True))
    pts = np.vstack([grid, edge]).astype(np.float64).reshape(-1, 2)
    hull = shapely.multipoints(pts).convex_hull.buffer(1e-9)
    shapely.prepare(hull)
    pts.setflags(write=False)
    corners = np.asarray(ring.coords[:-1], dtype=np.float64)
    return pts, hull, corners


def support_loads(points: np.ndarray, com) -> np.ndarray:
    """Share of the weight (N,) each support point carries: ≥ 0, summing to 1, centred on the
    CoM (Σ w_i p_i = com, the moment balance of a body at rest).

    The shares closest to uniform that satisfy those conditions: a pressure linear in position
    (a rigid body on an elastic foundation), with the points it would make negative lifted off.
    """
    from scipy.optimize import lsq_linear

    pts = np.asarray(points, dtype=np.float64)
    n = len(pts)
    a = np.vstack([np.ones(n), pts.T / PRESSURE_LENGTH])
    b = np.array([1.0, *np.asarray(com, dtype=np.float64) / PRESSURE_LENGTH])
    # weight of the equality rows: 1e4 balances the moment to ~1e-8 m; a CoM far off-centre
    # (nearly all the weight on a few points) can need a stiffer one
    for k in (1e4, 1e6, 1e8):
        lhs = np.vstack([np.eye(n) * n, k * a])
        rhs = np.concatenate([np.ones(n), k * b])
        w = lsq_linear(lhs, rhs, bounds=(0.0, np.inf), method="bvls", tol=1e-14).x
        w = np.clip(w, 0.0, None)
        w /= w.sum()
        err = float(np.linalg.norm(w @ pts - np.asarray(com)))
        if err <= 1e-5:
            break
    if err > 1e-5:
        raise ValueError(
            f"the supports cannot carry a CoM at {list(com)} (m): it lies outside their hull"
        )
    return w


def marker_pieces(footprint: Footprint) -> list[np.ndarray]:
    """Convex pieces (each (V, 2), object frame) of the orientation marker: the footprint's
    half with x ≥ 0. It breaks every symmetry, so the object frame's θ is visible."""
    minx, miny, maxx, maxy = footprint.polygon.bounds
    half = box(0.0, miny - 1.0, maxx + 1.0, maxy + 1.0)
    pieces = []
    for piece in footprint.convex_pieces():
        cut = Polygon(piece).intersection(half)
        if cut.geom_type == "Polygon" and cut.area > 1e-8:
            pieces.append(np.asarray(cut.exterior.coords)[:-1])
    return pieces


@dataclass(frozen=True)
class MassLayout:
    """How an object's mass is split between its body and its supports (see `build_mjcf`).

    points (N, 2): support positions (m, object frame), those carrying load; loads (N,): their
    shares of the weight; support_masses (N,) kg; stiffness (N,) N/m of their load springs;
    body_mass (kg), body_inertia (kg·m², about the vertical through the CoM) and body_ixx (the
    thin-plate off-axis moment) of the object body itself."""

    points: np.ndarray
    loads: np.ndarray
    support_masses: np.ndarray
    stiffness: np.ndarray
    body_mass: float
    body_inertia: float
    body_ixx: float


def mass_layout(spec: ObjectSpec, config: SimConfig) -> MassLayout:
    """The supports and mass split of `spec` under `config` (`build_mjcf`'s, which the
    simulator can also write into a compiled scene of the same outline)."""
    # Supports: each point is a small body on a vertical slide joint under the planar object,
    # pressed on the table by a constant load w_i·m·g (its own weight plus a joint spring with
    # a rest length 1 km below, constant to 1e-6). The loads are fixed shares centred on the
    # CoM, so the friction of each point is exactly μ·w_i·m·g while it slides and the object
    # neither tilts nor bounces: the planar motion depends on the pressure distribution alone.
    p, sup = spec.params, config.support
    supports = support_points(spec.footprint, sup.spacing, sup.edge_margin, (p.com_x, p.com_y))
    loads = support_loads(supports, (p.com_x, p.com_y))
    keep = loads > 1e-9
    supports, loads = supports[keep], loads[keep]
    com = np.array([p.com_x, p.com_y])
    spread = float(loads @ np.sum((supports - com) ** 2, axis=1))  # m², Σ w_i ‖p_i − c‖²
    share = min(SUPPORT_MASS_SHARE, 0.5 * p.inertia / max(p.mass * spread, 1e-12))
    masses = share * loads * p.mass
    stiffness = (loads * p.mass * GRAVITY - masses * GRAVITY) / -LOAD_SPRING_REST
    # The object body carries the rest of the mass, placed so that the whole assembly has the
    # object's mass, CoM and I_z (the supports' mass is centred on the CoM by construction).
    body_mass = (1.0 - share) * p.mass
    body_inertia = p.inertia - share * p.mass * spread
    # Off-axis moments of inertia do not affect planar motion (no tilt); thin-plate values.
    ixx = body_inertia / 2 + body_mass * spec.height * spec.height / 12
    return MassLayout(supports, loads, masses, stiffness, body_mass, body_inertia, ixx)


def build_mjcf(spec: ObjectSpec, config: SimConfig) -> str:
    """MJCF XML string for one object on the table."""
    ph, pad, sup, cam = config.physics, config.pad, config.support, config.camera
    p = spec.params
    h = spec.height
    meshes, prism_geoms = [], []
    for i, piece in enumerate(spec.footprint.convex_pieces()):
        verts = " ".join(f"{x:.6f} {y:.6f} {z:.6f}" for z in (PRISM_LIFT, h) for x, y in piece)
        meshes.append(f'<mesh name="piece{i}" vertex="{verts}"/>')
        prism_geoms.append(
            f'<geom name="obj_piece{i}" type="mesh" mesh="piece{i}" contype="{PAD_BITS}" '
            f'conaffinity="{PAD_BITS}" rgba="{OBJECT_RGBA}" mass="0" group="1"/>'
        )
    if config.orientation_marker:
        for i, piece in enumerate(marker_pieces(spec.footprint)):
            verts = " ".join(
                f"{x:.6f} {y:.6f} {z:.6f}" for z in (h, h + MARKER_THICKNESS) for x, y in piece
            )
            meshes.append(f'<mesh name="marker{i}" vertex="{verts}"/>')
            prism_geoms.append(
                f'<geom name="obj_marker{i}" type="mesh" mesh="marker{i}" contype="0" '
                f'conaffinity="0" rgba="{MARKER_RGBA}" mass="0" group="1"/>'
            )
    layout = mass_layout(spec, config)
    support_bodies = []
    for i, ((x, y), m_i, k_i) in enumerate(
        zip(layout.points, layout.support_masses, layout.stiffness)
    ):
        support_bodies.append(
            f'<body name="support{i}" pos="{x:.6f} {y:.6f} 0">'
            f'<joint name="support{i}_z" type="slide" axis="0 0 1" stiffness="{k_i:.9g}" '
            f'springref="{LOAD_SPRING_REST}"/>'
            f'<inertial pos="0 0 {sup.radius}" mass="{m_i:.9g}" diaginertia="1e-9 1e-9 1e-9"/>'
            f'<geom name="support{i}" type="sphere" size="{sup.radius}" pos="0 0 {sup.radius}" '
            f'contype="{TABLE_BITS}" conaffinity="{TABLE_BITS}" condim="3" '
            f'friction="{p.friction} 0 0" mass="0" rgba="0 0 0 0" group="3"/></body>'
        )
    body_mass, body_inertia, ixx = layout.body_mass, layout.body_inertia, layout.body_ixx
    pad_condim = 1 if pad.friction == 0 else 3
    fov = cam.fovy_deg
    size = max(cam.width, cam.height) * cam.outline_scale
    return f"""
<mujoco model="pushtoknow">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="{ph.timestep}" cone="{ph.cone}" impratio="{ph.impratio}"
          solver="{ph.solver}" integrator="implicitfast"/>
  <visual>
    <global offwidth="{size}" offheight="{size}"/>
    <quality shadowsize="0" offsamples="0"/>
    <map znear="0.01" zfar="50"/>
    <headlight ambient="0.5 0.5 0.5" diffuse="0.5 0.5 0.5" specular="0 0 0"/>
  </visual>
  <asset>
    {"".join(meshes)}
  </asset>
  <worldbody>
    <geom name="table" type="plane" size="1 1 0.01" contype="{TABLE_BITS}"
          conaffinity="{TABLE_BITS}" friction="{ph.table_friction} 0 0" rgba="{TABLE_RGBA}"/>
    <camera name="overhead" pos="0 0 {cam.distance}" fovy="{fov}"/>
    <body name="object" pos="0 0 0">
      <joint name="object_x" type="slide" axis="1 0 0"/>
      <joint name="object_y" type="slide" axis="0 1 0"/>
      <joint name="object_yaw" type="hinge" axis="0 0 1"/>
      <inertial pos="{p.com_x} {p.com_y} {h / 2}" mass="{body_mass}"
                diaginertia="{ixx} {ixx} {body_inertia}"/>
      {"".join(prism_geoms)}
      {"".join(support_bodies)}
    </body>
    <body name="pusher" pos="0 0 {pad.z}">
      <joint name="pusher_x" type="slide" axis="1 0 0"/>
      <joint name="pusher_y" type="slide" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="{pad.mass}" diaginertia="1 1 1"/>
      <geom name="pad" type="cylinder" size="{pad.radius} {pad.half_height}"
            contype="{PAD_BITS}" conaffinity="{PAD_BITS}" condim="{pad_condim}"
            friction="{pad.friction} 0 0" priority="1" solref="{pad.contact_timeconst} 1"
            rgba="{PAD_RGBA}"/>
    </body>
  </worldbody>
</mujoco>
"""
