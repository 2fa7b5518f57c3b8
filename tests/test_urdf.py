"""URDF import: tolsynth.load_urdf and model files whose chain is a URDF.

References, none of them tolsynth's CasADi graph:
* the real URDFs that example-robot-data ships inside its wheel (UR5 of ur_description, Franka
  Panda of panda_description; no download at run time);
* a plain-NumPy chain written here from yourdfpy's own 4x4 origin matrices and a Rodrigues
  rotation about each joint axis (FK), and from the file's xyz/rpy numbers read here with
  ElementTree (central finite differences of the sensitivities);
* UR's published D-H table (models/ur5.toml, and the same table as a NumPy D-H chain here).
"""

from __future__ import annotations

import math
import sys
import xml.etree.ElementTree as ET
from pathlib import Path

import numpy as np
import pytest

import tolsynth
from tolsynth.errors import MissingDependencyError, ModelFileError, UnsupportedJointError

yourdfpy = pytest.importorskip("yourdfpy")


def _robots_dir() -> Path:
    from importlib.metadata import PackageNotFoundError, distribution

    try:
        root = Path(str(distribution("example-robot-data").locate_file("cmeel.prefix/share/example-robot-data/robots")))
    except PackageNotFoundError:
        pytest.skip("example-robot-data (test extra) is not installed")
    return root


UR5 = ("ur_description/urdf/ur5_robot.urdf", "base_link", "tool0")
PANDA = ("panda_description/urdf/panda.urdf", "panda_link0", "panda_hand")


def _file(rel: str) -> Path:
    path = _robots_dir() / rel
    if not path.is_file():
        pytest.skip(f"{rel} not in example-robot-data")
    return path


# ---------------------------------------------------------------------------------------------
# the independent chain
# ---------------------------------------------------------------------------------------------
def _rodrigues(axis, angle):
    a = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -a[2], a[1]], [a[2], 0, -a[0]], [-a[1], a[0], 0]])
    return np.eye(3) + math.sin(angle) * K + (1 - math.cos(angle)) * K @ K


def _numpy_chain(path, base, tip):
    """(fk(q) -> 4x4 in mm, movable joint names): yourdfpy's origin matrices, our own motion."""
    robot = yourdfpy.URDF.load(
        str(path),
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    ).robot
    by_child = {j.child: j for j in robot.joints}
    chain, link = [], tip
    while link != base:
        chain.append(by_child[link])
        link = by_child[link].parent
    chain = chain[::-1]
    movable = [j.name for j in chain if j.type != "fixed"]

    def fk(q):
        T = np.eye(4)
        i = 0
        for j in chain:
            O = np.array(j.origin, float)
            O[:3, 3] *= 1000.0
            T = T @ O
            if j.type == "fixed":
                continue
            M = np.eye(4)
            if j.type == "prismatic":
                M[:3, 3] = np.asarray(j.axis) / np.linalg.norm(j.axis) * q[i]
            else:
                M[:3, :3] = _rodrigues(j.axis, q[i])
            T = T @ M
            i += 1
        return T

    return fk, movable


def _random_q(m, n, seed):
    rng = np.random.default_rng(seed)
    lo = np.array([j.lower for j in m.spec.joints])
    hi = np.array([j.upper for j in m.spec.joints])
    return lo + (hi - lo) * rng.uniform(0.001, 0.999, (n, len(lo)))


@pytest.mark.parametrize("robot", [UR5, PANDA], ids=["ur5", "panda"])
def test_fk_matches_an_independent_numpy_chain(robot):
    rel, base, tip = robot
    m = tolsynth.load_urdf(_file(rel), base, tip)
    fk, movable = _numpy_chain(_file(rel), base, tip)
    assert m.joint_names == tuple(movable)
    worst = 0.0
    for q in _random_q(m, 50, 1):
        T, ref = m.fk(q), fk(q)
        scale = np.linalg.norm(ref[:3, 3])
        worst = max(worst, np.abs(T[:3, 3] - ref[:3, 3]).max() / scale, np.abs(T[:3, :3] - ref[:3, :3]).max())
    assert worst <= 1e-9, worst


def test_joint_limits_come_from_the_file():
    m = tolsynth.load_urdf(_file(PANDA[0]), *PANDA[1:])
    limits = {
        j.get("name"): (float(j.find("limit").get("lower")), float(j.find("limit").get("upper")))
        for j in ET.parse(_file(PANDA[0])).getroot().findall("joint")
        if j.get("type") == "revolute"
    }
    for j in m.spec.joints:
        assert (j.lower, j.upper) == limits[j.name]
    # Franka's published limits for joint 4: -3.0718 .. -0.0698 rad
    assert m.spec.joints[3].lower == pytest.approx(-3.0718) and m.spec.joints[3].upper == pytest.approx(-0.0698)


def _file_origins(path):
    out = {}
    for j in ET.parse(path).getroot().findall("joint"):
        o = j.find("origin")
        xyz = [float(t) for t in (o.get("xyz", "0 0 0") if o is not None else "0 0 0").split()]
        rpy = [float(t) for t in (o.get("rpy", "0 0 0") if o is not None else "0 0 0").split()]
        out[j.get("name")] = (xyz, rpy)
    return out


def _param_chain(path, base, tip):
    """FK from the file's own xyz/rpy numbers (ElementTree), with those numbers perturbable:
    fk(q, {"joint.field": delta in mm or rad})."""
    origins = _file_origins(path)
    robot = yourdfpy.URDF.load(
        str(path),
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    ).robot
    by_child = {j.child: j for j in robot.joints}
    chain, link = [], tip
    while link != base:
        chain.append(by_child[link])
        link = by_child[link].parent
    chain = chain[::-1]

    def rot(axis, a):
        c, s = math.cos(a), math.sin(a)
        return {
            "x": np.array([[1, 0, 0], [0, c, -s], [0, s, c]]),
            "y": np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]]),
            "z": np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]]),
        }[axis]

    def fk(q, d):
        T = np.eye(4)
        i = 0
        for j in chain:
            xyz, rpy = origins[j.name]
            x, y, z = (1000 * v + d.get(f"{j.name}.{f}", 0.0) for v, f in zip(xyz, "xyz"))
            r, p, w = (v + d.get(f"{j.name}.{f}", 0.0) for v, f in zip(rpy, ("roll", "pitch", "yaw")))
            O = np.eye(4)
            O[:3, :3] = rot("z", w) @ rot("y", p) @ rot("x", r)
            O[:3, 3] = (x, y, z)
            T = T @ O
            if j.type != "fixed":
                M = np.eye(4)
                M[:3, :3] = _rodrigues(j.axis, q[i])
                T = T @ M
                i += 1
        return T

    return fk


@pytest.mark.parametrize("robot", [UR5, PANDA], ids=["ur5", "panda"])
def test_sensitivities_match_central_differences(robot):
    rel, base, tip = robot
    m = tolsynth.load_urdf(_file(rel), base, tip)  # xyz (mm) and rpy (mrad)
    fk = _param_chain(_file(rel), base, tip)
    h = 1e-4  # mm or mrad
    worst = 0.0
    for q in _random_q(m, 3, 2):
        S = m.sensitivity(q)
        R0 = fk(q, {})[:3, :3]
        for i, par in enumerate(m.parameters):
            step = h * par.scale
            Tp, Tm = fk(q, {par.name: step}), fk(q, {par.name: -step})
            dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ R0.T
            ref = np.concatenate([dp, [W[2, 1], W[0, 2], W[1, 0]]])
            worst = max(worst, np.abs(S[:, i] - ref).max() / max(1.0, np.abs(ref).max()))
    assert worst < 1e-7, worst


def test_axis_tilts_match_central_differences():
    """A tilt of joint j's axis by e about a direction u perpendicular to it: the NumPy chain
    rotates the axis itself (Rodrigues about R(u, e) axis)."""
    rel, base, tip = UR5
    m = tolsynth.load_urdf(_file(rel), base, tip, errors=["elbow_joint.axis"])
    assert m.error_parameters == ("elbow_joint.tilt1", "elbow_joint.tilt2")
    robot = yourdfpy.URDF.load(
        str(_file(rel)),
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    ).robot
    elbow = next(j for j in robot.joints if j.name == "elbow_joint")
    axis = np.asarray(elbow.axis, float)  # (0, 1, 0): tolsynth's A = Rz(90 deg) . Ry(90 deg)
    fk, _ = _numpy_chain(_file(rel), base, tip)
    q = _random_q(m, 1, 5)[0]
    S = m.sensitivity(q)
    # tilt1 is a rotation of the axis about A's x column, tilt2 about (Rx(tilt1) A)'s y column
    A = np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]) @ np.array([[0.0, 0, 1], [0, 1, 0], [-1, 0, 0]])
    assert np.allclose(A[:, 2], axis, atol=1e-15)
    h = 1e-6
    for col, u in ((0, A[:, 0]), (1, A[:, 1])):
        # perturb the chain copy held by _numpy_chain: rebuild it with the tilted axis
        Tp, Tm = (
            _tilted_fk(rel, base, tip, "elbow_joint", _rodrigues(u, h) @ axis, q),
            _tilted_fk(rel, base, tip, "elbow_joint", _rodrigues(u, -h) @ axis, q),
        )
        R0 = fk(q)[:3, :3]
        dp = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h) * 1e-3  # per mrad
        W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) * 1e-3 @ R0.T
        ref = np.concatenate([dp, [W[2, 1], W[0, 2], W[1, 0]]])
        assert np.abs(S[:, col] - ref).max() <= 1e-6 * max(1.0, np.abs(ref).max())


def _tilted_fk(rel, base, tip, joint, new_axis, q):
    robot = yourdfpy.URDF.load(
        str(_file(rel)),
        build_scene_graph=False,
        load_meshes=False,
        build_collision_scene_graph=False,
        load_collision_meshes=False,
    ).robot
    by_child = {j.child: j for j in robot.joints}
    chain, link = [], tip
    while link != base:
        chain.append(by_child[link])
        link = by_child[link].parent
    T, i = np.eye(4), 0
    for j in chain[::-1]:
        O = np.array(j.origin, float)
        O[:3, 3] *= 1000.0
        T = T @ O
        if j.type != "fixed":
            M = np.eye(4)
            M[:3, :3] = _rodrigues(new_axis if j.name == joint else j.axis, q[i])
            T = T @ M
            i += 1
    return T


# ---------------------------------------------------------------------------------------------
# fixed joints, prismatic joints, selection, errors: small URDFs written here
# ---------------------------------------------------------------------------------------------
def _urdf(tmp_path, joints: str, name="toy") -> Path:
    links = sorted(set(__import__("re").findall(r'link="([^"]+)"', joints)))
    text = f'<robot name="{name}">' + "".join(f'<link name="{n}"/>' for n in links) + joints + "</robot>"
    path = tmp_path / f"{name}.urdf"
    path.write_text(text)
    return path


TOY = """
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
  <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="f1" type="fixed"><parent link="l1"/><child link="l1b"/><origin xyz="0.3 0 0" rpy="0 0 0"/></joint>
<joint name="f2" type="fixed"><parent link="l1b"/><child link="l1c"/><origin xyz="0.1 0 0" rpy="0 0 1.5707963267948966"/></joint>
<joint name="j2" type="prismatic"><parent link="l1c"/><child link="l2"/>
  <origin xyz="0 0 0" rpy="0 0 0"/><axis xyz="1 0 0"/><limit lower="0" upper="0.2" effort="1" velocity="1"/></joint>
<joint name="f3" type="fixed"><parent link="l2"/><child link="tip"/><origin xyz="0 0 -0.05" rpy="0 0 0"/></joint>
"""


def test_fixed_joints_are_folded_and_prismatic_joints_slide(tmp_path):
    """Closed form: hand = (0,0,500) + Rz(q1) [(400, 0, 0) + Rz(90 deg) (q2, 0, 0)] + (0,0,-50)."""
    m = tolsynth.load_urdf(_urdf(tmp_path, TOY), "base", "tip")
    assert m.joint_names == ("j1", "j2")
    assert [(j.lower, j.upper) for j in m.spec.joints] == [(-3.0, 3.0), (0.0, 200.0)]  # prismatic in mm
    # f1 and f2 are folded into j2's origin, f3 is the tool; their numbers are error parameters
    assert [op for op, _ in m.spec.links[1].origin][:6] == ["Tx", "Ty", "Tz", "Rz", "Ry", "Rx"]
    assert len(m.spec.links[1].origin) == 18 and len(m.spec.tool) == 6
    assert {"f1.x", "f2.yaw", "f3.z"} <= set(m.error_parameters)
    for q1, q2 in ((0.3, 50.0), (-2.0, 199.0)):
        c, s = math.cos(q1), math.sin(q1)
        local = np.array([400.0, q2, 0.0])  # Rz(90 deg) turns the slide onto +y
        expect = np.array([c * local[0] - s * local[1], s * local[0] + c * local[1], 450.0])
        assert np.allclose(m.fk([q1, q2])[:3, 3], expect, rtol=0, atol=1e-9)
    # d hand / d f1.x = Rz(q1) x, per mm
    S = m.sensitivity([0.3, 50.0])
    assert np.allclose(S[:3, m.error_parameters.index("f1.x")], [math.cos(0.3), math.sin(0.3), 0], atol=1e-12)
    assert np.allclose(S[:3, m.error_parameters.index("f3.z")], [0, 0, 1], atol=1e-12)


def test_error_selection_by_pattern(tmp_path):
    path = _urdf(tmp_path, TOY)
    m = tolsynth.load_urdf(path, "base", "tip", errors=["*.xyz", "j1.rpy"])
    assert m.error_parameters == (
        "j1.x",
        "j1.y",
        "j1.z",
        "j1.roll",
        "j1.pitch",
        "j1.yaw",
        "f1.x",
        "f1.y",
        "f1.z",
        "f2.x",
        "f2.y",
        "f2.z",
        "j2.x",
        "j2.y",
        "j2.z",
        "f3.x",
        "f3.y",
        "f3.z",
    )
    units = dict(zip(m.error_parameters, m.units))
    assert units["j1.x"] == "mm" and units["j1.yaw"] == "mrad"
    assert dict(zip(m.error_parameters, m.k))["j1.yaw"] == 1.5
    m2 = tolsynth.load_urdf(
        path,
        "base",
        "tip",
        errors="all",
        k={"length": 2.0, "j1.yaw": 3.0},
        bounds={"angle": (0.01, 10.0)},
        tolerance_units={"length": "um"},
    )
    assert "j2.tilt2" in m2.error_parameters and "j1.tilt1" in m2.error_parameters
    p = {q.name: q for q in m2.parameters}
    assert p["f1.x"].unit == "um" and p["f1.x"].k == 2.0 and p["j1.yaw"].k == 3.0 and p["j1.roll"].k == 1.5
    assert (p["j1.roll"].lower, p["j1.roll"].upper) == (0.01, 10.0)
    # a micrometre column is a thousandth of the millimetre one
    S, S2 = m.sensitivity([0.3, 50.0]), m2.sensitivity([0.3, 50.0])
    assert np.allclose(S2[:, m2.error_parameters.index("f1.x")], 1e-3 * S[:, m.error_parameters.index("f1.x")])


def test_default_bounds_follow_the_tolerance_units(tmp_path):
    """The default bounds, 0.001-5 mm and 0.001-50 mrad, are physical: in um they read 1-5000 um,
    in arcsec 0.001 mrad = 0.206265 arcsec to 50 mrad = 10313.24 arcsec (1 rad = 180 * 3600 / pi
    arcsec); bounds given stay as given."""
    m = tolsynth.load_urdf(
        _urdf(tmp_path, TOY),
        "base",
        "tip",
        tolerance_units={"length": "um", "angle": "arcsec"},
        bounds={"j1.z": (2, 9)},
    )
    arcsec = 180 * 3600 / math.pi * 1e-3  # one mrad in arcsec
    for p in m.parameters:
        want = (
            (2.0, 9.0) if p.name == "j1.z" else (1.0, 5000.0) if p.kind == "length" else (0.001 * arcsec, 50 * arcsec)
        )
        assert (p.lower, p.upper) == (pytest.approx(want[0], rel=1e-12), pytest.approx(want[1], rel=1e-12)), p.name


def test_bad_input_is_a_typed_error_naming_the_field(tmp_path):
    path = _urdf(tmp_path, TOY)
    with pytest.raises(ModelFileError, match=r"base_link: no link 'bse' .*did you mean `base`"):
        tolsynth.load_urdf(path, "bse", "tip")
    with pytest.raises(ModelFileError, match=r"tip_link: link 'base' does not descend|tip_link: is the base link"):
        tolsynth.load_urdf(path, "tip", "base")
    with pytest.raises(ModelFileError, match=r"errors\[1\]: 'j9\.rpy' selects no error parameter"):
        tolsynth.load_urdf(path, "base", "tip", errors=["*.xyz", "j9.rpy"])
    with pytest.raises(ModelFileError, match=r"bounds\[j1.x\]"):
        tolsynth.load_urdf(path, "base", "tip", bounds={"length": (5.0, 1.0)})
    with pytest.raises(ModelFileError, match=r"k\[j1.x\]"):
        tolsynth.load_urdf(path, "base", "tip", k={"length": -1.0})
    with pytest.raises(ModelFileError, match=r"k\[lenght\].*did you mean `length`"):
        tolsynth.load_urdf(path, "base", "tip", k={"lenght": 1.0})
    with pytest.raises(ModelFileError, match=r"tolerance_units\[j1.x\]: unit 'mrad' is not a unit of length"):
        tolsynth.load_urdf(path, "base", "tip", tolerance_units={"length": "mrad"})
    with pytest.raises(ModelFileError, match=r"configurations.home: expected 2 joint values"):
        tolsynth.load_urdf(path, "base", "tip", configurations={"home": [0.0]})
    with pytest.raises(ModelFileError, match=r"tip_link: the chain 'base' -> 'l1' has no movable|no link"):
        tolsynth.load_urdf(_urdf(tmp_path, TOY.replace('type="revolute"', 'type="fixed"'), "fixed"), "base", "l1")


@pytest.mark.parametrize("kind", ["floating", "planar"])
def test_unsupported_joint_types_name_the_joint(tmp_path, kind):
    path = _urdf(tmp_path, TOY.replace('name="j2" type="prismatic"', f'name="j2" type="{kind}"'), kind)
    with pytest.raises(UnsupportedJointError, match=rf"joint 'j2': type '{kind}' is not supported") as info:
        tolsynth.load_urdf(path, "base", "tip")
    assert info.value.joint == "j2" and info.value.joint_type == kind
    # the part of the tree before it is fine
    assert tolsynth.load_urdf(path, "base", "l1").joint_names == ("j1",)


def test_missing_yourdfpy_names_the_install_command(tmp_path, monkeypatch):
    monkeypatch.setitem(sys.modules, "yourdfpy", None)
    with pytest.raises(MissingDependencyError, match=r'pip install "tolsynth\[urdf\]"'):
        tolsynth.load_urdf(_urdf(tmp_path, TOY), "base", "tip")


# ---------------------------------------------------------------------------------------------
# a model file pointing at a URDF
# ---------------------------------------------------------------------------------------------
def _model_text(urdf_name="ur5_robot.urdf", extra=""):
    return f'''
[model]
name = "ur5_urdf"
source = "ur5_robot.urdf of ur_description, as shipped by example-robot-data 6.0.0"
assumptions = ["hand point = origin of tool0"]
[units]
length = "mm"
angle = "deg"
[chain]
urdf = "{urdf_name}"
base_link = "base_link"
tip_link = "tool0"
errors = ["*.xyz", "*.rpy"]
k = {{ length = 1.0, angle = 1.5 }}
bounds = {{ length = [0.001, 5.0], angle = [0.001, 50.0] }}
tolerance_units = {{ length = "mm", angle = "mrad" }}
[configurations.bent]
note = "elbow at 90 deg"
shoulder_pan_joint = 0.0
shoulder_lift_joint = -90.0
elbow_joint = 90.0
wrist_1_joint = 0.0
wrist_2_joint = 90.0
wrist_3_joint = 0.0
{extra}'''


def test_model_file_with_a_urdf_chain(tmp_path):
    (tmp_path / "ur5_robot.urdf").write_bytes(_file(UR5[0]).read_bytes())
    (tmp_path / "ur5_urdf.toml").write_text(_model_text())
    m = tolsynth.load_model(tmp_path / "ur5_urdf.toml")
    ref = tolsynth.load_urdf(_file(UR5[0]), *UR5[1:])
    q = np.radians([0.0, -90.0, 90.0, 0.0, 90.0, 0.0])
    assert np.allclose(m.configurations["bent"], q)
    assert np.allclose(m.fk("bent"), ref.fk(q), rtol=0, atol=1e-12)
    assert m.error_parameters == ref.error_parameters and len(m.error_parameters) == 42


@pytest.mark.parametrize(
    "extra, field",
    [
        ("[symbols]\na = 1.0\n", "symbols: not allowed with chain.urdf"),
        ("[[error_parameter]]\nname = 'x'\n", "error_parameter: unknown key (did you mean `error_parameters`"),
        ('[tolerance_sets.t]\n"elbow_joint.zz" = 0.1\n', "tolerance_sets.t.elbow_joint.zz: unknown error parameter"),
    ],
)
def test_model_file_with_a_urdf_chain_rejects_bad_input(tmp_path, extra, field):
    (tmp_path / "ur5_robot.urdf").write_bytes(_file(UR5[0]).read_bytes())
    (tmp_path / "m.toml").write_text(_model_text(extra=extra))
    with pytest.raises(ModelFileError) as info:
        tolsynth.load_model(tmp_path / "m.toml")
    assert field in str(info.value)
    (tmp_path / "m.toml").write_text(_model_text("nowhere.urdf"))
    with pytest.raises(ModelFileError, match="chain.urdf: no URDF file at"):
        tolsynth.load_model(tmp_path / "m.toml")
    (tmp_path / "m.toml").write_text(_model_text().replace('tip_link = "tool0"', 'tip_link = "tool"'))
    with pytest.raises(ModelFileError, match="chain.tip_link: no link 'tool'.*did you mean `tool0`"):
        tolsynth.load_model(tmp_path / "m.toml")


# ---------------------------------------------------------------------------------------------
# the UR5 from its URDF against the UR5 from UR's D-H table
# ---------------------------------------------------------------------------------------------
#: UR's published CB3 UR5 table (mm, deg), the one models/ur5.toml cites
UR5_DH = dict(d=[89.159, 0, 0, 109.15, 94.65, 82.3], a=[0, -425.0, -392.25, 0, 0, 0], alpha=[90, 0, 0, 90, -90, 0])


def _dh_numpy(q):
    T = np.eye(4)
    for i in range(6):
        ct, st = math.cos(q[i]), math.sin(q[i])
        al = math.radians(UR5_DH["alpha"][i])
        ca, sa = math.cos(al), math.sin(al)
        T = T @ np.array(
            [
                [ct, -st * ca, st * sa, UR5_DH["a"][i] * ct],
                [st, ct * ca, -ct * sa, UR5_DH["a"][i] * st],
                [0, sa, ca, UR5_DH["d"][i]],
                [0, 0, 0, 1],
            ]
        )
    return T


#: the URDF's base_link is UR's D-H base frame turned 180 deg about z (ur_description's "base"
#: link, a fixed child of base_link, is the D-H base frame)
RZ180 = np.diag([-1.0, -1.0, 1.0])


def test_ur5_urdf_and_dh_table_describe_the_same_arm():
    """Hand pose of base_link -> tool0 = Rz(180 deg) x the D-H chain's frame 6, at 50 random q;
    both the pose and the orientation.  The URDF writes pi/2 as 1.57079632679 (5e-12 rad short),
    so the two agree to ~1e-11 relative, not to the last bit."""
    m = tolsynth.load_urdf(_file(UR5[0]), *UR5[1:])
    worst = 0.0
    for q in _random_q(m, 50, 3):
        T, D = m.fk(q), _dh_numpy(q)
        worst = max(
            worst,
            np.abs(T[:3, 3] - RZ180 @ D[:3, 3]).max() / np.linalg.norm(D[:3, 3]),
            np.abs(T[:3, :3] - RZ180 @ D[:3, :3]).max(),
        )
    assert worst < 1e-10, worst
    if "ur5" in tolsynth.bundled_models():  # the bundled file is the same table
        d = tolsynth.load_model("ur5")
        q = _random_q(m, 1, 4)[0]
        assert np.allclose(d.fk(q), _dh_numpy(q), rtol=0, atol=1e-9)


#: D-H error parameter -> the URDF origin number with the same effect (up to sign) at every pose
#: (found by comparing the columns at random poses; asserted below)
DH_TO_URDF = {
    "a1": "shoulder_lift_joint.x",
    "d1": "shoulder_pan_joint.z",
    "o1": "shoulder_pan_joint.yaw",
    "a2": "elbow_joint.z",
    "d2": "shoulder_lift_joint.y",
    "o2": "shoulder_lift_joint.pitch",
    "a3": "wrist_1_joint.z",
    "d3": "elbow_joint.y",
    "o3": "elbow_joint.pitch",
    "a4": "wrist_2_joint.x",
    "d4": "wrist_1_joint.y",
    "alpha4": "wrist_2_joint.roll",
    "o4": "wrist_1_joint.pitch",
    "a5": "wrist_3_joint.x",
    "d5": "wrist_2_joint.z",
    "alpha5": "wrist_3_joint.roll",
    "o5": "wrist_2_joint.yaw",
    "a6": "wrist_3_link-tool0_fixed_joint.x",
    "d6": "wrist_3_joint.y",
    "alpha6": "wrist_3_link-tool0_fixed_joint.roll",
    "o6": "wrist_3_joint.pitch",
}


def _dh_mechanism(errors):
    links = [
        {"d": UR5_DH["d"][i], "a": UR5_DH["a"][i], "alpha": UR5_DH["alpha"][i], "limits": (-360, 360)} for i in range(6)
    ]
    # the table's twists and limits are degrees (as the UR data sheet gives them): said, not guessed
    return tolsynth.Mechanism.from_dh(links, name="ur5_dh", errors=errors, angle_unit="deg")


def test_ur5_same_optimum_from_urdf_and_dh_where_the_error_parameters_are_the_same():
    """Where the two describe the same kinematics *and the same errors*, the optimum is the same.

    The D-H table has 4 error parameters per link (a, d, alpha, theta offset: 24), the URDF 6 per
    joint origin (xyz, rpy: 42 on base_link -> tool0, 7 origins).  21 of the 24 D-H errors act on
    the hand exactly like one URDF origin number (same sensitivity column up to sign and the
    180 deg base turn, at every pose; same unit mm/mrad, k 1/1.5 and bounds): the mapping
    DH_TO_URDF.  With those 21 on each side the tolerance problem is the same, and so is its
    optimum (to 1e-6 relative; measured ~1e-9).

    alpha1, alpha2, alpha3 have no single counterpart: alpha1 turns about D-H x1, which at the
    shoulder_lift origin (rpy = 0, pi/2, 0: gimbal lock) is the one rotation roll and yaw cannot
    give (both turn about the same axis there; only an axis tilt reaches it, see the next test);
    alpha2/alpha3 turn about axes through the elbow/wrist that the URDF's origin numbers reach
    only as a combination (a rotation plus a translation).  With all
    their parameters the two problems differ (24 D-H vs 42 URDF numbers, different cost and
    different directions), so their optima differ: the URDF's 42 cost more (asserted), which is
    the answer to a different question, not a disagreement.
    """
    m = tolsynth.load_urdf(_file(UR5[0]), *UR5[1:], errors=list(DH_TO_URDF.values()))
    d = _dh_mechanism(list(DH_TO_URDF))
    assert set(d.error_parameters) == set(DH_TO_URDF)
    cols = [m.error_parameters.index(DH_TO_URDF[n]) for n in d.error_parameters]
    B = np.kron(np.eye(2), RZ180)
    poses = _random_q(m, 4, 7)
    for q in poses:
        Su, Sd = m.sensitivity(q)[:, cols], B @ d.sensitivity(q)
        sign = np.sign(np.sum(Su * Sd, axis=0))
        assert np.abs(Su * sign - Sd).max() < 1e-8
    assert np.allclose(m.k[cols], d.k) and m.units[0] == "mm"
    ru = tolsynth.synthesize(m, R=0.5, p=0.99, poses=list(poses), probability="gaussian")
    rd = tolsynth.synthesize(d, R=0.5, p=0.99, poses=list(poses), probability="gaussian")
    assert ru.success and rd.success
    assert ru.cost == pytest.approx(rd.cost, rel=1e-6)
    tu, td = ru.tolerances, rd.tolerances
    for n in d.error_parameters:
        assert tu[DH_TO_URDF[n]] == pytest.approx(td[n], rel=1e-5, abs=1e-7)
    # the full sets: different problems (see the docstring)
    full_u = tolsynth.synthesize(
        tolsynth.load_urdf(_file(UR5[0]), *UR5[1:]), R=0.5, p=0.99, poses=list(poses), probability="gaussian"
    )
    full_d = tolsynth.synthesize(_dh_mechanism("all"), R=0.5, p=0.99, poses=list(poses), probability="gaussian")
    assert full_u.success and full_d.success and full_u.cost > full_d.cost


def test_ur5_dh_errors_are_fixed_combinations_of_urdf_origin_errors():
    """Every D-H error column is a linear combination of the URDF's columns with the SAME
    coefficients at every pose (least squares over 6 poses stacked): the D-H errors are a
    subspace of the URDF's, except one.  With xyz + rpy (42) alpha1 is missing (residual ~1e-3):
    the shoulder_lift origin has pitch = 90 deg, where roll and yaw turn about the same axis
    (gimbal lock), so the origin's rpy give two rotations, not three.  With the axis tilts too
    ("all", 54) every D-H error is in the span (residual ~1e-15)."""
    d = _dh_mechanism("all")
    B = np.kron(np.eye(2), RZ180)
    poses = _random_q(tolsynth.load_urdf(_file(UR5[0]), *UR5[1:]), 6, 9)  # inside the URDF limits
    D = np.vstack([B @ d.sensitivity(q) for q in poses])
    for errors in (["*.xyz", "*.rpy"], "all"):
        m = tolsynth.load_urdf(_file(UR5[0]), *UR5[1:], errors=errors)
        U = np.vstack([m.sensitivity(q) for q in poses])
        M, *_ = np.linalg.lstsq(U, D, rcond=None)
        residual = dict(zip(d.error_parameters, np.abs(U @ M - D).max(axis=0)))
        if errors == "all":
            assert max(residual.values()) < 1e-10, residual
        else:
            assert residual["alpha1"] > 1e-4
            assert max(v for n, v in residual.items() if n != "alpha1") < 1e-10, residual


def test_readme_block_says_true_things():
    """The docs' "From a URDF" block (docs/robots.md): 42 parameters, and its hand point is the D-H
    chain of UR's table (NumPy, above) turned 180 deg about z."""
    import re

    readme = (Path(__file__).resolve().parent.parent / "docs" / "robots.md").read_text()
    (block,) = [b for b in re.findall(r"```python\n(.*?)```", readme, flags=re.S) if "load_urdf" in b]
    _robots_dir()
    namespace: dict = {}
    exec(compile(block, "docs/robots.md", "exec"), namespace)
    m = namespace["ur5u"]
    assert len(m.error_parameters) == 42
    hand = RZ180 @ _dh_numpy([0, 0, 0, -math.pi / 2, 0, 0])[:3, 3]
    assert np.allclose(m.fk("stretched")[:3, 3], hand, rtol=0, atol=1e-8)
    assert np.allclose(hand, [911.9, 191.45, 89.159], atol=1e-9)


def test_readme_model_file_block_loads(tmp_path):
    """The docs' model file pointing at a URDF (docs/robots.md) loads, and its 'worst' pose is the D-H table's
    hand at (q4 = -90 deg) turned 180 deg about z."""
    import re

    readme = (Path(__file__).resolve().parent.parent / "docs" / "robots.md").read_text()
    (block,) = [b for b in re.findall(r"```toml\n(.*?)```", readme, flags=re.S) if "urdf =" in b]
    (tmp_path / "ur5_robot.urdf").write_bytes(_file(UR5[0]).read_bytes())
    (tmp_path / "my_ur5.toml").write_text(block)
    m = tolsynth.load_model(tmp_path / "my_ur5.toml")
    assert len(m.error_parameters) == 42
    assert np.allclose(m.fk("worst")[:3, 3], RZ180 @ _dh_numpy([0, 0, 0, -math.pi / 2, 0, 0])[:3, 3], atol=1e-8)


def test_cli_solves_a_model_file_with_a_urdf_chain(tmp_path, capsys):
    """The commands take such a model file like any other; dotted parameter names work in --k."""
    from tolsynth.cli import main

    (tmp_path / "ur5_robot.urdf").write_bytes(_file(UR5[0]).read_bytes())
    (tmp_path / "m.toml").write_text(_model_text())
    rc = main(
        [
            "solve",
            "--model",
            str(tmp_path / "m.toml"),
            "--R",
            "0.5",
            "--p",
            "0.99",
            "--pose",
            "bent",
            "--k",
            "elbow_joint.z=2",
        ]
    )
    out = capsys.readouterr().out
    assert rc == 0 and "elbow_joint.z = " in out and "wrist_3_link-tool0_fixed_joint.yaw" in out


# ---------------------------------------------------------------------------------------------
# bad input: every defect a typed error naming its field, before any use
# ---------------------------------------------------------------------------------------------
TWO = """
<joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
  <origin xyz="0 0 0.5" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
<joint name="j2" type="revolute"><parent link="l1"/><child link="tip"/>
  <origin xyz="0.3 0 0" rpy="0 0 0"/><axis xyz="0 0 1"/><limit lower="-3" upper="3" effort="1" velocity="1"/></joint>
"""


@pytest.mark.parametrize(
    "joints, extra_links, fragment",
    [
        (
            TWO.replace('<axis xyz="0 0 1"/>', '<axis xyz="1 0"/>', 1),
            "",
            r"joint 'j1': axis xyz='1 0': expected three finite numbers",
        ),
        (TWO.replace('<axis xyz="0 0 1"/>', '<axis xyz="1e308 1e308 0"/>', 1), "", r"joint 'j1': axis xyz="),
        (
            TWO.replace('<axis xyz="0 0 1"/>', '<axis xyz="0 0 0"/>', 1),
            "",
            r"joint 'j1': axis \[0.0, 0.0, 0.0\] has no direction",
        ),
        (TWO.replace('xyz="0.3 0 0"', 'xyz="1e308 0 0"'), "", r"joint 'j2': origin xyz='1e308 0 0'"),
        (TWO.replace('xyz="0.3 0 0"', 'xyz="nan 0 0"'), "", r"joint 'j2': origin xyz"),
        (
            TWO + '<joint name="j3" type="fixed"><parent link="tip"/><child link="l1"/></joint>',
            "",
            r"link 'l1' is also the child of joint 'j1': a closed loop",
        ),
        (TWO, '<link name="l1"/>', r"link 'l1': declared twice"),
        (
            TWO + '<joint name="j2" type="fixed"><parent link="tip"/><child link="t2"/></joint>',
            "",
            r"joint 'j2': declared twice",
        ),
    ],
    ids=[
        "axis-2-numbers",
        "axis-overflow",
        "axis-zero",
        "xyz-1e308",
        "xyz-nan",
        "closed-loop",
        "duplicate-link",
        "duplicate-joint",
    ],
)
def test_malformed_urdf_is_a_typed_error(tmp_path, joints, extra_links, fragment):
    import re

    links = sorted(set(re.findall(r'link="([^"]+)"', joints)))
    path = tmp_path / "bad.urdf"
    path.write_text(
        '<robot name="bad">' + "".join(f'<link name="{n}"/>' for n in links) + extra_links + joints + "</robot>"
    )
    with pytest.raises(ModelFileError, match=fragment):
        tolsynth.load_urdf(path, "base", "tip")


@pytest.mark.parametrize(
    "kw, field",
    [
        (dict(errors=5), "errors"),
        (dict(errors=[5]), "errors"),
        (dict(configurations="abc"), "configurations"),
        (dict(configurations={"a": "x"}), "configurations[a]"),
        (dict(tolerance_sets="x"), "tolerance_sets"),
        (dict(tolerance_sets={"s": 3}), "tolerance_sets[s]"),
        (dict(assumptions=5), "assumptions"),
        (dict(name=5), "name"),
    ],
)
def test_bad_load_urdf_arguments_are_typed_errors(tmp_path, kw, field):
    from tolsynth.errors import InputError

    with pytest.raises(InputError) as info:
        tolsynth.load_urdf(_urdf(tmp_path, TWO, "two"), "base", "tip", **kw)
    assert info.value.field == field and "allowed" in str(info.value)
    with pytest.raises(InputError) as info:
        tolsynth.load_urdf(5, "base", "tip")
    assert info.value.field == "path"


def test_configurations_outside_the_limits_fail_at_load(tmp_path):
    """A pose outside its joint's limits is an error naming the configuration when the robot is
    built (not at its first use); the same pose in degrees, with the unit stated, loads and is
    the pose of the same joint values in radians."""
    path = _urdf(tmp_path, TWO, "two")
    with pytest.raises(ModelFileError, match=r"configurations\.a\.j1: 190 deg is outside the joint limits"):
        tolsynth.load_urdf(path, "base", "tip", configurations={"a": [190.0, 0.0]}, angle_unit="deg")
    with pytest.raises(ModelFileError, match=r"configurations\.b\.j2"):
        tolsynth.load_urdf(path, "base", "tip", configurations={"b": [0.0, 3.5]})
    m = tolsynth.load_urdf(path, "base", "tip", configurations={"a": [90.0, -45.0]}, angle_unit="deg")
    assert m.configurations["a"] == pytest.approx([math.pi / 2, -math.pi / 4], rel=1e-15)


def test_angles_are_radians_unless_the_unit_is_given(tmp_path):
    """One rule (docs/units.md): numbers in rad unless angle_unit says otherwise; a value beyond
    2 pi without a stated unit reads like degrees and is refused instead of being taken as radians."""
    from tolsynth.errors import InputError

    path = _urdf(tmp_path, TWO, "two")
    with pytest.raises(InputError) as info:
        tolsynth.load_urdf(path, "base", "tip", configurations={"a": [90.0, 0.0]})
    assert info.value.field == "angle_unit" and "angle_unit='deg'" in str(info.value)
    m = tolsynth.load_urdf(path, "base", "tip", configurations={"a": [1.0, 0.5]})
    assert m.configurations["a"] == pytest.approx([1.0, 0.5], rel=0, abs=0)
