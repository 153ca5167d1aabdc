"""MJCF scene builder: table, one extruded object on a grid of point supports, the finger pad,
and the overhead camera."""

from __future__ import annotations

import numpy as np
from shapely.geometry import Point, Polygon, box

from pushtoknow.testbed.config import SimConfig
from pushtoknow.testbed.objects import ObjectSpec
from pushtoknow.testbed.shapes import Footprint

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


def support_points(footprint: Footprint, spacing: float, margin: float) -> np.ndarray:
    """Grid of support points (N, 2) inside the footprint, symmetric about the centroid."""
    poly = footprint.polygon.buffer(-margin)
    minx, miny, maxx, maxy = footprint.polygon.bounds
    nx = int(np.ceil(max(abs(minx), abs(maxx)) / spacing))
    ny = int(np.ceil(max(abs(miny), abs(maxy)) / spacing))
    xs = np.arange(-nx, nx + 1) * spacing
    ys = np.arange(-ny, ny + 1) * spacing
    pts = np.array([(x, y) for x in xs for y in ys if poly.contains(Point(x, y))])
    if len(pts) < 3:  # tiny objects: fall back to a triangle of supports
        pts = 0.5 * footprint.vertices[np.linspace(0, len(footprint.vertices) - 1, 3).astype(int)]
    return pts


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
    supports = support_points(spec.footprint, sup.spacing, sup.edge_margin)
    support_geoms = [
        f'<geom name="support{i}" type="sphere" size="{sup.radius}" pos="{x:.6f} {y:.6f} '
        f'{sup.radius}" contype="{TABLE_BITS}" conaffinity="{TABLE_BITS}" condim="3" '
        f'friction="{p.friction} 0 0" mass="0" rgba="0 0 0 0" group="3"/>'
        for i, (x, y) in enumerate(supports)
    ]
    # Off-axis moments of inertia: thin-plate relation plus thickness; they satisfy the
    # triangle inequality for any positive I_z and do not affect planar motion.
    ixx = p.inertia / 2 + p.mass * h * h / 12
    pad_condim = 1 if pad.friction == 0 else 3
    fov = cam.fovy_deg
    size = max(cam.width, cam.height)
    return f"""
<mujoco model="pushtoknow">
  <compiler angle="radian" inertiafromgeom="false"/>
  <option timestep="{ph.timestep}" cone="{ph.cone}" integrator="implicitfast"/>
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
      <freejoint name="object_free"/>
      <inertial pos="{p.com_x} {p.com_y} {h / 2}" mass="{p.mass}"
                diaginertia="{ixx} {ixx} {p.inertia}"/>
      {"".join(prism_geoms)}
      {"".join(support_geoms)}
    </body>
    <body name="pusher" pos="0 0 {pad.z}">
      <joint name="pusher_x" type="slide" axis="1 0 0"/>
      <joint name="pusher_y" type="slide" axis="0 1 0"/>
      <inertial pos="0 0 0" mass="{pad.mass}" diaginertia="1 1 1"/>
      <geom name="pad" type="cylinder" size="{pad.radius} {pad.half_height}"
            contype="{PAD_BITS}" conaffinity="{PAD_BITS}" condim="{pad_condim}"
            friction="{pad.friction} 0 0" priority="1" rgba="{PAD_RGBA}"/>
    </body>
  </worldbody>
</mujoco>
"""
