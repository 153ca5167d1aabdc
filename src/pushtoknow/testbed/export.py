"""Export an identified object for the simulators users run: MuJoCo MJCF, or URDF with a mesh.

An `ObjectModel` is the outline (object frame, m) extruded to a height, with the identified mass,
friction, CoM and yaw inertia (SI, docs/DESIGN.md §2). Build one from an estimate's mean (5,)
with `ObjectModel.from_estimate`, or from a testbed spec with `ObjectModel.from_spec`, then
`write_export(model, "mjcf" | "urdf", path)`.

The exported body's frame is the object frame: the outline and the CoM are given in it, its
z = 0 is the bottom face. The full inertia tensor about the CoM (`ObjectModel.inertia_tensor`)
has the identified I_zz = I_z; pushes on a table never reveal the tilting moments, so I_xx,
I_yy and I_xy come from a uniform-density extrusion of the outline with its in-plane second
moments scaled to the identified I_z (docs/DESIGN.md §3, "Export").
"""

from __future__ import annotations

import contextlib
import math
import os
import tempfile
import xml.etree.ElementTree as ET
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Literal, cast

import numpy as np
from shapely.geometry import Point, Polygon
from shapely.validation import explain_validity

from pushtoknow.common.errors import ExportError
from pushtoknow.common.params import PARAM_NAMES
from pushtoknow.testbed.objects import DEFAULT_HEIGHT, ObjectSpec
from pushtoknow.testbed.scene import OBJECT_RGBA
from pushtoknow.testbed.shapes import Footprint
from pushtoknow.testbed.sim_config import PhysicsConfig

ExportKind = Literal["mjcf", "urdf"]
EXPORT_KINDS: tuple[str, ...] = ("mjcf", "urdf")
COLLINEAR_SINE = 1e-9  # a vertex whose edges turn by less (sine) is dropped: it changes nothing
MIN_PIECE_AREA = 1e-9  # m²: a collision piece smaller than this (a sliver) is left out of MJCF
FLOOR_FRICTION = PhysicsConfig().table_friction  # the testbed's table: MuJoCo takes the max


@dataclass(frozen=True, eq=False)
class ObjectModel:
    """An identified object, SI, object frame. vertices: (V, 2) simple outline (m; stored
    counter-clockwise, without repeated or collinear vertices); height (m); mass (kg); com (2,)
    (m); inertia_z: yaw inertia about the CoM (kg·m²); friction: object–floor Coulomb μ.

    Raises ExportError naming the field and value of the first invalid one."""

    name: str
    vertices: np.ndarray
    height: float
    mass: float
    com: np.ndarray
    inertia_z: float
    friction: float

    def __post_init__(self):
        for field, value in (
            ("mass", self.mass),
            ("inertia_z", self.inertia_z),
            ("friction", self.friction),
            ("height", self.height),
        ):
            object.__setattr__(self, field, _positive(field, value))
        vertices = _clean_outline(self.vertices)
        try:
            com = np.array(self.com, dtype=np.float64)
        except (TypeError, ValueError):
            com = np.full(3, np.nan)
        if com.shape != (2,) or not np.all(np.isfinite(com)):
            raise ExportError("com", self.com, "must be [c_x, c_y], finite, in metres")
        if not Polygon(vertices).convex_hull.covers(Point(*com)):
            raise ExportError(
                "com",
                com.tolist(),
                "outside the outline's convex hull, where no mass distribution over the "
                "outline has its centre of mass",
            )
        vertices.setflags(write=False)
        com.setflags(write=False)
        object.__setattr__(self, "vertices", vertices)
        object.__setattr__(self, "com", com)
        object.__setattr__(self, "name", str(self.name))

    @classmethod
    def from_estimate(
        cls,
        mean: Sequence[float] | np.ndarray,
        outline: Sequence[Sequence[float]] | np.ndarray,
        height: float = DEFAULT_HEIGHT,
        name: str = "object",
    ) -> ObjectModel:
        """The model of an estimate: mean (5,) SI in PARAM_NAMES order (m, μ, c_x, c_y, I_z),
        e.g. `PushEstimate.mean` or `Identification.mean`; outline (V, 2) in the frame of the
        estimate's CoM (m); height (m)."""
        try:
            phi = np.asarray(mean, dtype=np.float64).reshape(-1)
        except (TypeError, ValueError):
            phi = np.zeros(0)
        if phi.shape != (len(PARAM_NAMES),):
            raise ExportError("mean", mean, f"must hold 5 values {PARAM_NAMES} (SI)")
        m, mu, cx, cy, iz = (float(x) for x in phi)
        vertices = cast(np.ndarray, outline)  # converted and checked by __post_init__
        return cls(name, vertices, height, m, np.array([cx, cy]), iz, mu)

    @classmethod
    def from_spec(cls, spec: ObjectSpec) -> ObjectModel:
        """The model of a testbed object (its true parameters and footprint)."""
        return cls.from_estimate(
            spec.params.as_array(), spec.footprint.vertices, spec.height, spec.name
        )

    @property
    def area(self) -> float:
        """Outline area (m²)."""
        return float(Polygon(self.vertices).area)

    @property
    def inertia_tensor(self) -> np.ndarray:
        """Inertia tensor (3, 3) about the CoM, body axes (kg·m²): I_zz = inertia_z; the tilting
        moments of a uniform extrusion of the outline whose in-plane second moments are scaled
        to inertia_z (about the CoM at half the height)."""
        s = _plate_second_moments(self.vertices)
        j = s * (self.inertia_z / np.trace(s))  # kg·m²: [[∫x² dm, ∫xy dm], [∫xy dm, ∫y² dm]]
        zz = self.mass * self.height**2 / 12.0  # ∫z² dm of a uniform extrusion
        return np.array(
            [
                [j[1, 1] + zz, -j[0, 1], 0.0],
                [-j[0, 1], j[0, 0] + zz, 0.0],
                [0.0, 0.0, self.inertia_z],
            ]
        )

    @property
    def com_3d(self) -> np.ndarray:
        """CoM (3,) in the body frame (m): (c_x, c_y, height / 2)."""
        return np.array([self.com[0], self.com[1], self.height / 2])


def _positive(field: str, value: object) -> float:
    """value as a positive finite float, else ExportError naming the field."""
    try:
        x = float(value)  # type: ignore[arg-type]
    except (TypeError, ValueError):
        x = math.nan
    if isinstance(value, bool) or not math.isfinite(x):
        raise ExportError(field, value, "must be a finite number")
    if x <= 0:
        raise ExportError(field, value, "must be positive")
    return x


def _clean_outline(vertices) -> np.ndarray:
    """(V, 2) float64 counter-clockwise outline without a closing vertex, repeated vertices or
    collinear ones (none changes the shape); ExportError unless a simple polygon."""
    try:
        v = np.array(vertices, dtype=np.float64)
    except (TypeError, ValueError):
        raise ExportError("vertices", vertices, "must be (V, 2) [x, y] pairs in metres") from None
    if v.ndim != 2 or v.shape[1] != 2:
        raise ExportError("vertices", f"array of shape {v.shape}", "must be (V, 2) in metres")
    if not np.all(np.isfinite(v)):
        raise ExportError("vertices", _summary(v), "must be finite")
    given = v
    while len(v) >= 3:
        v = v[np.any(v != np.roll(v, 1, axis=0), axis=1)]  # repeated (and closing) vertices
        a, c = np.roll(v, 1, axis=0), np.roll(v, -1, axis=0)
        e1, e2 = v - a, c - v
        cross = np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
        straight = cross <= COLLINEAR_SINE * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
        if not straight.any():
            break
        v = v[~straight]
    if len(v) < 3:
        raise ExportError(
            "vertices", _summary(given), "an outline needs 3 vertices, not repeated or collinear"
        )
    poly = Polygon(v)
    if not poly.is_valid:
        raise ExportError(
            "vertices", _summary(given), f"not a simple polygon ({explain_validity(poly)})"
        )
    x, y = v[:, 0], v[:, 1]
    signed = np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y)
    return v if signed > 0 else v[::-1].copy()


def _summary(v: np.ndarray) -> object:
    return v.tolist() if v.size <= 16 else f"{len(v)} vertices"


def _plate_second_moments(v: np.ndarray) -> np.ndarray:
    """Second moments (2, 2) per unit area about the area centroid (m²) of a CCW polygon (V, 2):
    [[⟨x²⟩, ⟨xy⟩], [⟨xy⟩, ⟨y²⟩]] of a uniform plate."""
    x, y = v[:, 0], v[:, 1]
    x1, y1 = np.roll(x, -1), np.roll(y, -1)
    cr = x * y1 - x1 * y
    a = cr.sum() / 2
    cx, cy = ((x + x1) * cr).sum() / (6 * a), ((y + y1) * cr).sum() / (6 * a)
    xx = ((x * x + x * x1 + x1 * x1) * cr).sum() / (12 * a) - cx * cx
    yy = ((y * y + y * y1 + y1 * y1) * cr).sum() / (12 * a) - cy * cy
    xy = ((x * y1 + 2 * x * y + 2 * x1 * y1 + x1 * y) * cr).sum() / (24 * a) - cx * cy
    return np.array([[xx, xy], [xy, yy]])


def _convex_pieces(model: ObjectModel) -> list[np.ndarray]:
    """The outline's convex pieces (each (k, 2), CCW): the testbed's decomposition (the outline
    itself if convex, else ear-clipped triangles)."""
    return Footprint(np.array(model.vertices)).convex_pieces()  # writable: earcut needs it


def prism_mesh(model: ObjectModel) -> tuple[np.ndarray, np.ndarray]:
    """The outline extruded to the height as a closed triangle mesh, object frame (m): vertices
    (2V, 3), the outline at z = 0 then at z = height; triangles (4V − 4, 3) of vertex indices,
    counter-clockwise seen from outside (outward normals)."""
    v = model.vertices
    n = len(v)
    index = {(float(x), float(y)): i for i, (x, y) in enumerate(v)}
    cap = np.array(
        [
            [index[tuple(p[0])], index[tuple(p[k])], index[tuple(p[k + 1])]]
            for p in (piece.tolist() for piece in _convex_pieces(model))
            for k in range(1, len(p) - 1)
        ],
        dtype=np.int64,
    )
    i = np.arange(n)
    j = (i + 1) % n
    sides = np.concatenate([np.stack([i, j, j + n], 1), np.stack([i, j + n, i + n], 1)])
    faces = np.concatenate([cap[:, ::-1], cap + n, sides])
    verts = np.concatenate(
        [np.column_stack([v, np.zeros(n)]), np.column_stack([v, np.full(n, model.height)])]
    )
    return verts, faces


def _num(x: float) -> str:
    """Shortest text that reads back as the same float."""
    return repr(float(x))


def _nums(xs) -> str:
    return " ".join(_num(x) for x in np.ravel(xs))


def _header(model: ObjectModel) -> str:
    return (
        f" pushtoknow export of {model.name!r}: mass {_num(model.mass)} kg, friction "
        f"{_num(model.friction)}, CoM {_nums(model.com)} m (object frame), I_z "
        f"{_num(model.inertia_z)} kg m2 about the CoM; outline extruded to "
        f"{_num(model.height)} m. Tilting moments (I_xx, I_yy, I_xy) are those of a uniform "
        "extrusion scaled to I_z: pushes do not identify them. "
    )


def to_mjcf(model: ObjectModel) -> str:
    """A standalone MuJoCo MJCF document: a floor plane and the object as a free body resting on
    it, with its mass, CoM, inertia tensor and friction."""
    ph = PhysicsConfig()
    name = model.name
    root = ET.Element("mujoco", model=name)
    root.append(ET.Comment(_header(model)))
    ET.SubElement(root, "compiler", angle="radian", inertiafromgeom="false")
    # The testbed's contact settings: elliptic cones and a high impratio make friction stiff
    # Coulomb friction (no creep under sub-threshold forces).
    ET.SubElement(root, "option", cone=ph.cone, impratio=_num(ph.impratio))
    asset = ET.SubElement(root, "asset")
    world = ET.SubElement(root, "worldbody")
    ET.SubElement(world, "light", name="top", pos="0 0 2", dir="0 0 -1", directional="true")
    world.append(
        ET.Comment(
            " MuJoCo gives a contact the larger friction of its two geoms, unless one geom has "
            "the higher priority, whose friction is then used. Like the testbed's table, this "
            "floor is frictionless and the object's geoms have priority 1: its contacts with "
            "this floor, or with any default-priority floor, have friction mu. "
        )
    )
    ET.SubElement(
        world,
        "geom",
        name="floor",
        type="plane",
        size="0 0 0.05",
        friction=f"{_num(FLOOR_FRICTION)} 0 0",
        rgba="0.75 0.75 0.72 1",
    )
    body = ET.SubElement(world, "body", name=name, pos="0 0 0")
    ET.SubElement(body, "freejoint", name=f"{name}_free")
    t = model.inertia_tensor
    ET.SubElement(
        body,
        "inertial",
        pos=_nums(model.com_3d),
        mass=_num(model.mass),
        fullinertia=_nums([t[0, 0], t[1, 1], t[2, 2], t[0, 1], t[0, 2], t[1, 2]]),
    )
    body.append(
        ET.Comment(
            " MuJoCo collides a mesh as its convex hull, so the outline is the testbed's convex "
            "pieces (itself if convex, else ear-clipped triangles), each extruded to a prism. "
        )
    )
    for i, piece in enumerate(_convex_pieces(model)):
        if Polygon(piece).area < MIN_PIECE_AREA:
            continue
        mesh = f"{name}_piece{i}"
        prism = [(x, y, z) for z in (0.0, model.height) for x, y in piece]
        ET.SubElement(asset, "mesh", name=mesh, vertex=_nums(prism))
        ET.SubElement(
            body,
            "geom",
            name=mesh,
            type="mesh",
            mesh=mesh,
            friction=f"{_num(model.friction)} 0 0",
            condim="3",
            priority="1",
            rgba=OBJECT_RGBA,
        )
    ET.indent(root)
    return ET.tostring(root, encoding="unicode") + "\n"


def to_urdf(model: ObjectModel, mesh_path: str | os.PathLike) -> str:
    """A URDF robot of one link: its inertial (origin at the CoM, mass, full inertia tensor) and
    `mesh_path` (written as given; `write_export` uses a name beside the URDF) as visual and
    collision geometry. URDF has no standard friction: μ goes into `<gazebo>` (mu1, mu2) and
    PyBullet's `<contact>` (lateral_friction)."""
    name = model.name
    robot = ET.Element("robot", name=name)
    robot.append(ET.Comment(_header(model)))
    link = ET.SubElement(robot, "link", name=name)
    inertial = ET.SubElement(link, "inertial")
    ET.SubElement(inertial, "origin", xyz=_nums(model.com_3d), rpy="0 0 0")
    ET.SubElement(inertial, "mass", value=_num(model.mass))
    t = model.inertia_tensor
    ET.SubElement(
        inertial,
        "inertia",
        ixx=_num(t[0, 0]),
        ixy=_num(t[0, 1]),
        ixz=_num(t[0, 2]),
        iyy=_num(t[1, 1]),
        iyz=_num(t[1, 2]),
        izz=_num(t[2, 2]),
    )
    for tag in ("visual", "collision"):
        el = ET.SubElement(link, tag)
        ET.SubElement(el, "origin", xyz="0 0 0", rpy="0 0 0")
        geometry = ET.SubElement(el, "geometry")
        ET.SubElement(geometry, "mesh", filename=os.fspath(mesh_path))
    link.append(
        ET.Comment(
            " Friction mu (object-floor Coulomb coefficient) for PyBullet, which multiplies "
            "the two bodies' lateral frictions (its plane's is 1). Simulators that collide a "
            "mesh as its convex hull (PyBullet, MuJoCo) fill a non-convex outline's notches. "
        )
    )
    contact = ET.SubElement(link, "contact")
    ET.SubElement(contact, "lateral_friction", value=_num(model.friction))
    robot.append(
        ET.Comment(
            " Friction mu for Gazebo, which takes the smaller of the two surfaces' mu: "
            "give the floor a larger one. "
        )
    )
    gazebo = ET.SubElement(robot, "gazebo", reference=name)
    ET.SubElement(gazebo, "mu1").text = _num(model.friction)
    ET.SubElement(gazebo, "mu2").text = _num(model.friction)
    ET.indent(robot)
    return '<?xml version="1.0"?>\n' + ET.tostring(robot, encoding="unicode") + "\n"


def to_obj(model: ObjectModel) -> str:
    """The extruded outline (`prism_mesh`) as a Wavefront OBJ (m, object frame)."""
    verts, faces = prism_mesh(model)
    lines = [
        f"# pushtoknow export of {model.name!r}: the outline extruded to {_num(model.height)} m,"
        " object frame, metres",
        f"o {model.name}",
    ]
    lines += [f"v {_nums(p)}" for p in verts]
    lines += [f"f {a + 1} {b + 1} {c + 1}" for a, b, c in faces]
    return "\n".join(lines) + "\n"


def _write_atomic(path: Path, text: str) -> None:
    """Write text to path through a temporary file in the same folder and os.replace."""
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        with contextlib.suppress(FileNotFoundError):
            os.unlink(tmp)
        raise


def write_export(model: ObjectModel, kind: ExportKind, path: str | os.PathLike) -> list[Path]:
    """Write `model` as MJCF (one file at path) or URDF (path, and its OBJ mesh beside it with
    the suffix .obj, referenced by file name), each atomically. Returns the files written, the
    mesh first. ExportError if kind is unknown or path's folder does not exist."""
    path = Path(path)
    if kind not in EXPORT_KINDS:
        raise ExportError("kind", kind, f"must be one of {', '.join(EXPORT_KINDS)}")
    if not path.parent.is_dir():
        raise ExportError("path", str(path), f"its folder {path.parent} does not exist")
    if path.is_dir():
        raise ExportError("path", str(path), "is a folder, not a file name")
    if kind == "mjcf":
        files = [(path, to_mjcf(model))]
    else:
        mesh = path.with_suffix(".obj")
        if mesh == path:
            raise ExportError("path", str(path), "the URDF's mesh is written beside it as .obj")
        files = [(mesh, to_obj(model)), (path, to_urdf(model, mesh.name))]
    for file, text in files:
        _write_atomic(file, text)
    return [file for file, _ in files]
