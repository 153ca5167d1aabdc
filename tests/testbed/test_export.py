"""Exporting an identified object: MJCF loads in MuJoCo with the identified parameters and rests
on its floor, URDF and its mesh carry the same body, bad inputs raise one-line errors."""

import math
import os
import xml.etree.ElementTree as ET

import mujoco
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from shapely.geometry import Polygon

from pushtoknow.common.errors import ExportError
from pushtoknow.common.params import GRAVITY
from pushtoknow.testbed.export import ObjectModel, prism_mesh, to_mjcf, to_obj, write_export
from pushtoknow.testbed.objects import NOVEL_SHAPES, ObjectSpec

SQUARE = [[-0.045, -0.045], [0.045, -0.045], [0.045, 0.045], [-0.045, 0.045]]
L_SHAPE = NOVEL_SHAPES["l_shape"]["vertices"]  # non-convex, about its centroid
MEAN = [0.5, 0.45, 0.01, -0.005, 0.8e-3]  # m, μ, c_x, c_y, I_z (SI)


def box(**kw) -> ObjectModel:
    return ObjectModel.from_estimate(kw.pop("mean", MEAN), kw.pop("outline", SQUARE), **kw)


def l_object() -> ObjectModel:  # its CoM in the notch: inside the hull, outside the outline
    return ObjectModel.from_estimate([0.6, 0.55, 0.02, 0.02, 1.1e-3], L_SHAPE, 0.02, "ell")


def load_mjcf(model: ObjectModel, tmp_path) -> mujoco.MjModel:
    (path,) = write_export(model, "mjcf", tmp_path / f"{model.name}.xml")
    return mujoco.MjModel.from_xml_path(str(path))


def full_inertia(mj: mujoco.MjModel, body: str) -> np.ndarray:
    """The body's inertia tensor (3, 3) about its CoM in body axes (MuJoCo stores principal
    moments and the rotation to them)."""
    b = mj.body(body)
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, b.iquat)
    rot = rot.reshape(3, 3)
    return rot @ np.diag(b.inertia) @ rot.T


def object_geoms(mj: mujoco.MjModel, body: str) -> np.ndarray:
    return np.flatnonzero(mj.geom_bodyid == mj.body(body).id)


@pytest.mark.parametrize("make", [box, l_object], ids=["square", "L"])
def test_mjcf_body_has_the_identified_parameters(make, tmp_path):
    model = make()
    mj = load_mjcf(model, tmp_path)
    b = mj.body(model.name)
    assert b.mass[0] == model.mass
    np.testing.assert_array_equal(b.ipos, [*model.com, model.height / 2])
    tensor = full_inertia(mj, model.name)
    assert tensor[2, 2] == pytest.approx(model.inertia_z, rel=1e-9)
    np.testing.assert_allclose(tensor, model.inertia_tensor, rtol=0, atol=1e-12)
    geoms = object_geoms(mj, model.name)
    assert len(geoms) == (1 if make is box else len(L_SHAPE) - 2)  # convex pieces
    np.testing.assert_array_equal(mj.geom_friction[geoms, 0], model.friction)
    assert (mj.geom_priority[geoms] > mj.geom_priority[mj.geom("floor").id]).all()


@pytest.mark.parametrize("make", [box, l_object], ids=["square", "L"])
def test_object_rests_on_the_floor_with_contact_friction_mu(make, tmp_path):
    model = make()
    mj = load_mjcf(model, tmp_path)
    data = mujoco.MjData(mj)
    for _ in range(round(1.0 / mj.opt.timestep)):
        mujoco.mj_step(mj, data)
    pos, quat = data.qpos[:3], data.qpos[3:7]
    assert np.all(np.isfinite(data.qpos))
    assert abs(pos[2]) < 1e-3  # neither fell through nor lifted off
    assert np.hypot(*pos[:2]) < 1e-4  # did not wander
    assert abs(quat[0]) > 1 - 1e-6  # did not tip
    assert np.abs(data.qvel).max() < 1e-3  # at rest
    assert data.ncon >= 3
    frictions = [data.contact[i].friction[0] for i in range(data.ncon)]
    np.testing.assert_array_equal(frictions, model.friction)


def test_a_slide_stops_where_coulomb_friction_stops_it(tmp_path):
    """A body sliding at v stops after v² / (2 μ g): the object–floor friction is μ."""
    model = box(mean=[0.5, 0.5, 0.0, 0.0, 0.7e-3])
    mj = load_mjcf(model, tmp_path)
    data = mujoco.MjData(mj)
    for _ in range(200):
        mujoco.mj_step(mj, data)
    x0, v0 = data.qpos[0], 0.3
    data.qvel[0] = v0
    for _ in range(round(0.2 / mj.opt.timestep)):
        mujoco.mj_step(mj, data)
    assert abs(data.qvel[0]) < 1e-4
    assert data.qpos[0] - x0 == pytest.approx(v0**2 / (2 * model.friction * GRAVITY), rel=0.05)


def test_inertia_of_a_uniform_box_is_the_textbook_one():
    m, a, b, h = 0.5, 0.09, 0.06, 0.02
    rect = [[-a / 2, -b / 2], [a / 2, -b / 2], [a / 2, b / 2], [-a / 2, b / 2]]
    model = ObjectModel.from_estimate([m, 0.5, 0, 0, m * (a * a + b * b) / 12], rect, h)
    expected = np.diag(
        [m * (b * b + h * h) / 12, m * (a * a + h * h) / 12, m * (a * a + b * b) / 12]
    )
    np.testing.assert_allclose(model.inertia_tensor, expected, rtol=1e-12, atol=1e-18)
    # a larger identified I_z scales the in-plane moments, not the thickness's
    big = ObjectModel.from_estimate([m, 0.5, 0, 0, 2 * m * (a * a + b * b) / 12], rect, h)
    assert big.inertia_tensor[0, 0] == pytest.approx(m * (2 * b * b + h * h) / 12)


def test_an_asymmetric_outline_has_a_product_of_inertia():
    t = l_object().inertia_tensor
    assert t[0, 1] > 0  # the L's arms lie along (+x, −y) and (−x, +y): ∫xy dm < 0
    assert np.all(np.linalg.eigvalsh(t) > 0)
    assert t[0, 0] + t[1, 1] >= t[2, 2]  # a physical tensor


def read_obj(text: str) -> tuple[np.ndarray, np.ndarray]:
    verts = [list(map(float, ln.split()[1:])) for ln in text.splitlines() if ln.startswith("v ")]
    faces = [list(map(int, ln.split()[1:])) for ln in text.splitlines() if ln.startswith("f ")]
    return np.array(verts), np.array(faces) - 1


def signed_volume(verts: np.ndarray, faces: np.ndarray) -> float:
    a, b, c = verts[faces[:, 0]], verts[faces[:, 1]], verts[faces[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6)


def assert_closed_outward_mesh(model: ObjectModel, text: str) -> None:
    verts, faces = read_obj(text)
    n = len(model.vertices)
    assert verts.shape == (2 * n, 3)
    assert faces.shape == (4 * n - 4, 3)
    # each edge is used once in each direction: closed and consistently oriented
    edges = [(f[i], f[(i + 1) % 3]) for f in faces.tolist() for i in range(3)]
    assert len(set(edges)) == len(edges)
    assert all((b, a) in set(edges) for a, b in edges)
    # positive: the normals point outwards
    assert signed_volume(verts, faces) == pytest.approx(model.area * model.height, rel=1e-9)


def test_urdf_and_its_mesh_carry_the_identified_body(tmp_path):
    model = l_object()
    mesh, urdf = write_export(model, "urdf", tmp_path / "ell.urdf")
    assert mesh == tmp_path / "ell.obj"
    assert sorted(os.listdir(tmp_path)) == ["ell.obj", "ell.urdf"]  # no temporary files left
    robot = ET.parse(urdf).getroot()
    assert robot.tag == "robot"
    (link,) = robot.findall("link")
    inertial = link.find("inertial")
    xyz = [float(x) for x in inertial.find("origin").get("xyz").split()]
    assert xyz == [*model.com, model.height / 2]
    assert float(inertial.find("mass").get("value")) == model.mass
    t = model.inertia_tensor
    got = {k: float(v) for k, v in inertial.find("inertia").attrib.items()}
    assert got == {
        "ixx": t[0, 0],
        "ixy": t[0, 1],
        "ixz": t[0, 2],
        "iyy": t[1, 1],
        "iyz": t[1, 2],
        "izz": model.inertia_z,
    }
    for tag in ("visual", "collision"):
        assert link.find(f"{tag}/geometry/mesh").get("filename") == "ell.obj"
    assert float(link.find("contact/lateral_friction").get("value")) == model.friction
    gazebo = robot.find("gazebo")
    assert gazebo.get("reference") == link.get("name")
    assert float(gazebo.find("mu1").text) == float(gazebo.find("mu2").text) == model.friction
    assert_closed_outward_mesh(model, mesh.read_text())


@settings(max_examples=60, deadline=None)
@given(
    n=st.integers(3, 12),
    jitter=st.lists(st.floats(0.0, 0.8), min_size=12, max_size=12),
    radii=st.lists(st.floats(0.02, 0.1), min_size=12, max_size=12),
    height=st.floats(0.005, 0.15),
)
def test_mesh_volume_is_area_times_height(n, jitter, radii, height):
    """Any star-shaped outline (convex or not): the extruded mesh is closed, faces outwards
    and encloses area × height."""
    angles = 2 * np.pi * (np.arange(n) + np.array(jitter[:n])) / n
    outline = np.array(radii[:n])[:, None] * np.stack([np.cos(angles), np.sin(angles)], 1)
    c = Polygon(outline).centroid
    model = ObjectModel.from_estimate([0.5, 0.5, c.x, c.y, 1e-3], outline, height)
    assert_closed_outward_mesh(model, to_obj(model))


def test_outline_is_cleaned_and_oriented():
    closed_cw = [*SQUARE[::-1], SQUARE[-1]]  # clockwise, closed, with a repeated vertex
    with_midpoints = [SQUARE[0], [0.0, -0.045], SQUARE[1], SQUARE[1], *SQUARE[2:]]
    for outline in (closed_cw, with_midpoints):
        model = box(outline=outline)
        assert len(model.vertices) == 4
        assert signed_area(model.vertices) > 0
        assert model.area == pytest.approx(0.09**2)
    verts, faces = prism_mesh(box())
    assert verts.shape == (8, 3) and faces.shape == (12, 3)


def signed_area(v: np.ndarray) -> float:
    x, y = v[:, 0], v[:, 1]
    return float(0.5 * np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def test_from_spec_keeps_the_testbed_object():
    d = {"name": "b", "shape": "rect1", "mass": 0.5, "friction": 0.4, "com": [0.0, 0.01]}
    spec = ObjectSpec.from_dict({**d, "inertia": 0.6e-3, "height": 0.02})
    model = ObjectModel.from_spec(spec)
    assert (model.name, model.mass, model.friction) == ("b", 0.5, 0.4)
    assert (model.inertia_z, model.height) == (0.6e-3, 0.02)
    np.testing.assert_array_equal(model.com, [0.0, 0.01])
    np.testing.assert_array_equal(model.vertices, spec.footprint.vertices)


def test_model_is_immutable():
    model = box()
    with pytest.raises(ValueError):
        model.vertices[0, 0] = 1.0
    with pytest.raises(AttributeError):
        model.mass = 2.0  # type: ignore[misc]


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"mean": [-0.5, 0.45, 0, 0, 1e-3]}, "mass"),
        ({"mean": [math.nan, 0.45, 0, 0, 1e-3]}, "mass"),
        ({"mean": [0.5, 0.0, 0, 0, 1e-3]}, "friction"),
        ({"mean": [0.5, 0.45, 0, 0, -1e-3]}, "inertia_z"),
        ({"mean": [0.5, 0.45, 0.2, 0.0, 1e-3]}, "com"),
        ({"mean": [0.5, 0.45, 0.0, 0.0]}, "mean"),
        ({"height": 0.0}, "height"),
        ({"outline": [[0, 0], [0.1, 0]]}, "vertices"),
        ({"outline": [[0, 0], [0.05, 0], [0.1, 0]]}, "vertices"),  # collinear: a segment
        ({"outline": [[0, 0], [0.1, 0.1], [0.1, 0], [0, 0.1]]}, "vertices"),  # a bow tie
        ({"outline": [[0, 0], [0.1], [0, 0.1]]}, "vertices"),
        ({"mean": "heavy"}, "mean"),
    ],
)
def test_bad_input_raises_a_one_line_error_naming_the_field(kw, field):
    with pytest.raises(ExportError) as e:
        box(**kw)
    assert e.value.field == field
    assert "\n" not in str(e.value)
    assert str(e.value).startswith(f"cannot export: {field}=")


def test_l_com_in_the_notch_is_accepted_but_not_beyond_the_hull():
    l_object()  # (0.02, 0.02): outside the L, inside its convex hull
    with pytest.raises(ExportError, match="com="):
        ObjectModel.from_estimate([0.6, 0.55, 0.05, 0.05, 1e-3], L_SHAPE, 0.02)


def test_write_export_refuses_a_missing_folder_and_an_unknown_kind(tmp_path):
    with pytest.raises(ExportError) as e:
        write_export(box(), "mjcf", tmp_path / "nope" / "box.xml")
    assert e.value.field == "path" and "\n" not in str(e.value) and "does not exist" in str(e.value)
    with pytest.raises(ExportError) as e:
        write_export(box(), "sdf", tmp_path / "box.sdf")  # type: ignore[arg-type]
    assert e.value.field == "kind"
    with pytest.raises(ExportError):
        write_export(box(), "urdf", tmp_path / "box.obj")  # its mesh would overwrite it
    assert os.listdir(tmp_path) == []


def test_write_export_replaces_an_existing_file(tmp_path):
    path = tmp_path / "box.xml"
    path.write_text("old")
    assert write_export(box(), "mjcf", path) == [path]
    assert path.read_text() == to_mjcf(box())
    assert os.listdir(tmp_path) == ["box.xml"]
