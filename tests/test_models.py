"""Robot descriptions (models/robots/*.toml) and the generated URDFs (urdf/*.urdf).

Every expected value here comes from outside the generator: the EBA paper's Tables 1-2 typed in by
hand, D-H products written out as matrices in this file, and plain Pinocchio / coal.
"""
from __future__ import annotations

import math
import tomllib

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.model.description import available_models, dh_capsules, load_description, models_dir, urdf_dir
from optplan.model.robot import RobotModel
from optplan.model.urdf_writer import build_all, urdf_string, write_urdf

DEG = math.pi / 180.0

# --------------------------------------------------------------------------- the EBA paper, by hand
# Table 1 (theta offset [deg], alpha [deg], a [m], d [m]); read as modified D-H:
# row i = (theta_off_i, alpha_{i-1}, a_{i-1}, d_i) (shared/spec/conventions.md).
EBA_DH = np.array([[0, 0, 0, 0.225],
                   [0, 90, 0, 0.240],
                   [-90, -90, 0, 0.240],
                   [0, 0, 0.56, 0.200],
                   [90, 0, 0.5, 0.195],
                   [0, 90, 0, 0.180],
                   [0, -90, 0, 0.476]], float)
# Table 2
EBA_BASE_MASS = 510.0
EBA_BASE_INERTIA = np.array([[625.0, -4.95, 6.58], [-4.95, 452.5, -2.39], [6.58, -2.39, 450.0]])
EBA_MASSES = [6.34, 6.34, 7.93, 5.67, 2.80, 2.70, 10.01]
EBA_COMS = np.array([[0, -0.07, -0.05], [0, 0.07, -0.05], [0.23, 0, -0.03], [0.24, 0, 0],
                     [0, -0.03, -0.03], [-0.03, 0.02, 0], [0, -0.01, -0.20]], float)
#                        Ixx   Ixy  Ixz   Iyy   Iyz   Izz
EBA_INERTIAS = np.array([[0.09, 0, 0, 0.05, 0.02, 0.07],
                         [0.09, 0, 0, 0.05, 0.02, 0.07],
                         [0.08, 0, 0.12, 0.57, 0, 0.53],
                         [0.03, 0, 0.05, 0.33, 0, 0.31],
                         [0.01, 0, 0, 0.01, 0, 0.01],
                         [0.01, 0, 0, 0.01, 0, 0.01],
                         [0.15, 0, 0, 0.20, 0.01, 0.10]], float)
EBA_TOTAL_MASS = 593.58
# Table 1 note: arm A at (0.3, 0.51, 0.83) m, "RPY" (90, 26, 0) deg read as Rz(90) Ry(26) Rx(0).
EBA_MOUNT_A = (np.array([0.3, 0.51, 0.83]), (90.0, 26.0, 0.0))

# tcbirrt_dual_arm: the documented reading of the TCBiRRT paper's table (see the TOML header): standard
# D-H, rows (theta_off, alpha_i, a_i, d_i) [deg, deg, m, m]; mounts at (0, ±1, 2) m, no rotation.
TCB_DH = np.array([[0, 90, 0, 0],
                   [0, 90, 0, 0.24],
                   [0, 0, 1.08, -0.17],
                   [0, 0, 1.08, -0.18],
                   [0, 90, 0, -0.17],
                   [0, 90, 0, -0.24],
                   [0, 0, 0, -0.1]], float)
TCB_MOUNTS = {"a": np.array([0.0, 1.0, 2.0]), "b": np.array([0.0, -1.0, 2.0])}


# --------------------------------------------------------------------------- independent D-H
def Rx(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[1, 0, 0], [0, c, -s], [0, s, c]])


def Ry(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, 0, s], [0, 1, 0], [-s, 0, c]])


def Rz(a):
    c, s = math.cos(a), math.sin(a)
    return np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])


def H(R=None, p=None):
    T = np.eye(4)
    if R is not None:
        T[:3, :3] = R
    if p is not None:
        T[:3, 3] = p
    return T


def dh_modified(alpha_prev, a_prev, theta, d):
    """Craig: Rx(alpha_{i-1}) Tx(a_{i-1}) Rz(theta_i) Tz(d_i), written out."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha_prev), math.sin(alpha_prev)
    return np.array([[ct, -st, 0, a_prev],
                     [st * ca, ct * ca, -sa, -sa * d],
                     [st * sa, ct * sa, ca, ca * d],
                     [0, 0, 0, 1]])


def dh_standard(theta, d, a, alpha):
    """Distal: Rz(theta_i) Tz(d_i) Tx(a_i) Rx(alpha_i), written out."""
    ct, st, ca, sa = math.cos(theta), math.sin(theta), math.cos(alpha), math.sin(alpha)
    return np.array([[ct, -st * ca, st * sa, a * ct],
                     [st, ct * ca, -ct * sa, a * st],
                     [0, sa, ca, d],
                     [0, 0, 0, 1]])


def dh_chain(rows_deg, q, convention, T0=None):
    """World transforms of D-H frames 1..n (rows [theta_off deg, alpha deg, a, d])."""
    out, T = [], (np.eye(4) if T0 is None else T0.copy())
    for (off, alpha, a, d), qi in zip(rows_deg, q):
        th = qi + off * DEG
        if convention == "modified":
            T = T @ dh_modified(alpha * DEG, a, th, d)
        else:
            T = T @ dh_standard(th, d, a, alpha * DEG)
        out.append(T.copy())
    return out


def se3_h(M: pin.SE3) -> np.ndarray:
    return np.asarray(M.homogeneous)


def plain_model(name: str, free_flyer: bool):
    path = str(urdf_dir() / f"{name}.urdf")
    if free_flyer:
        return pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer())
    return pin.buildModelFromUrdf(path)


# --------------------------------------------------------------------------- files
def test_shipped_models_are_listed():
    assert {"eba_ffsr", "tcbirrt_dual_arm"} <= set(available_models())


@pytest.mark.parametrize("name", available_models())
def test_committed_urdf_is_up_to_date(name):
    path = urdf_dir() / f"{name}.urdf"
    assert path.exists(), f"{path} is missing: run `optplan models build`"
    expected = urdf_string(load_description(name))
    assert path.read_text() == expected, (
        f"urdf/{name}.urdf is out of date with models/robots/{name}.toml: run `optplan models build` "
        "and commit the regenerated URDF")


def test_every_committed_urdf_has_a_description():
    stems = sorted(p.stem for p in urdf_dir().glob("*.urdf"))
    assert stems == available_models(), "stale URDF without a TOML in models/robots (or vice versa)"


def test_build_all_and_write_urdf_write_the_generated_text(tmp_path):
    paths = build_all(tmp_path / "a")
    assert sorted(p.name for p in paths) == sorted(f"{n}.urdf" for n in available_models())
    for p in paths:
        assert p.read_text() == urdf_string(load_description(p.stem))
    p = write_urdf(load_description("eba_ffsr"), tmp_path / "b")
    assert p == tmp_path / "b" / "eba_ffsr.urdf"
    assert p.read_text() == (urdf_dir() / "eba_ffsr.urdf").read_text()


def test_urdf_string_is_deterministic():
    d = load_description("eba_ffsr")
    assert urdf_string(d) == urdf_string(load_description("eba_ffsr"))


# --------------------------------------------------------------------------- plain Pinocchio
@pytest.mark.parametrize("name,free_flyer,nq,nv", [
    ("eba_ffsr", False, 14, 14),
    ("eba_ffsr", True, 21, 20),
    ("tcbirrt_dual_arm", False, 14, 14),
])
def test_urdf_loads_in_plain_pinocchio(name, free_flyer, nq, nv):
    m = plain_model(name, free_flyer)
    assert (m.nq, m.nv) == (nq, nv)
    names = list(m.names)
    for p in ("a", "b"):
        for i in range(1, 8):
            assert f"{p}_joint{i}" in names
        assert m.existFrame(f"{p}_ee")
    geom = pin.buildGeomFromUrdf(m, str(urdf_dir() / f"{name}.urdf"), pin.COLLISION)
    assert len(geom.geometryObjects) > 0


def test_robot_model_matches_plain_pinocchio(eba, tcb):
    for robot, ff in ((eba, True), (tcb, False)):
        m = plain_model(robot.name, ff)
        assert (robot.nq, robot.nv) == (m.nq, m.nv)
        assert robot.nj == 14
        assert robot.is_floating == ff
        q = robot.random_configuration(np.random.default_rng(3))
        d1, d2 = robot.model.createData(), m.createData()
        pin.framesForwardKinematics(robot.model, d1, q)
        pin.framesForwardKinematics(m, d2, q)
        for f in ("a_ee", "b_ee", "a_link4"):
            assert np.allclose(se3_h(d1.oMf[robot.model.getFrameId(f)]), se3_h(d2.oMf[m.getFrameId(f)]),
                               atol=1e-14)


# --------------------------------------------------------------------------- the EBA paper Table 2
def test_eba_masses_match_table_2():
    m = plain_model("eba_ffsr", True)
    assert m.inertias[1].mass == pytest.approx(EBA_BASE_MASS, abs=1e-12)
    for p in ("a", "b"):
        for i, mass in enumerate(EBA_MASSES, start=1):
            assert m.inertias[m.getJointId(f"{p}_joint{i}")].mass == pytest.approx(mass, abs=1e-12), (p, i)
    assert pin.computeTotalMass(m) == pytest.approx(EBA_TOTAL_MASS, abs=1e-9)
    assert load_description("eba_ffsr").total_mass == pytest.approx(EBA_TOTAL_MASS, abs=1e-9)


def test_eba_base_inertia_matches_table_2():
    m = plain_model("eba_ffsr", True)
    base = m.inertias[1]
    np.testing.assert_allclose(base.inertia, EBA_BASE_INERTIA, atol=1e-12)
    np.testing.assert_allclose(base.lever, 0.0, atol=1e-15)


@pytest.mark.parametrize("prefix", ["a", "b"])
def test_eba_link_coms_and_inertias_in_dh_frames_match_table_2(prefix):
    # modified D-H: URDF link i frame = D-H frame i, so the inertia is stored in D-H axes
    m = plain_model("eba_ffsr", True)
    for i in range(1, 8):
        I = m.inertias[m.getJointId(f"{prefix}_joint{i}")]
        np.testing.assert_allclose(I.lever, EBA_COMS[i - 1], atol=1e-12, err_msg=f"{prefix} body {i}")
        xx, xy, xz, yy, yz, zz = EBA_INERTIAS[i - 1]
        np.testing.assert_allclose(I.inertia, [[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]], atol=1e-12,
                                   err_msg=f"{prefix} body {i}")


def test_eba_link_frames_are_modified_dh_frames_of_table_1(rng):
    """URDF link i of arm A = mount · Π Rx(α_{i-1}) Tx(a_{i-1}) Rz(θ_i + off_i) Tz(d_i)."""
    m = plain_model("eba_ffsr", False)
    d = m.createData()
    pos, zyx = EBA_MOUNT_A
    T0 = H(Rz(zyx[0] * DEG) @ Ry(zyx[1] * DEG) @ Rx(zyx[2] * DEG), pos)
    ia = np.array([m.idx_qs[m.getJointId(f"a_joint{i}")] for i in range(1, 8)])
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, m.nq)
        pin.framesForwardKinematics(m, d, q)
        frames = dh_chain(EBA_DH, q[ia], "modified", T0)
        for i, T in enumerate(frames, start=1):
            np.testing.assert_allclose(se3_h(d.oMf[m.getFrameId(f"a_link{i}")]), T, atol=1e-10,
                                       err_msg=f"a_link{i}")
        np.testing.assert_allclose(se3_h(d.oMf[m.getFrameId("a_ee")]), frames[-1], atol=1e-10)


def test_eba_arm_b_is_arm_a_turned_180_deg_about_base_x(rng):
    m = plain_model("eba_ffsr", False)
    d = m.createData()
    ia = np.array([m.idx_qs[m.getJointId(f"a_joint{i}")] for i in range(1, 8)])
    ib = np.array([m.idx_qs[m.getJointId(f"b_joint{i}")] for i in range(1, 8)])
    flip = pin.SE3(Rx(math.pi), np.zeros(3))
    for _ in range(20):
        q = np.zeros(m.nq)
        q[ia] = q[ib] = rng.uniform(-np.pi, np.pi, 7)
        pin.framesForwardKinematics(m, d, q)
        for f in ["mount"] + [f"link{i}" for i in range(1, 8)] + ["ee"]:
            Ma, Mb = d.oMf[m.getFrameId(f"a_{f}")], d.oMf[m.getFrameId(f"b_{f}")]
            np.testing.assert_allclose(se3_h(Mb), se3_h(flip * Ma), atol=1e-10, err_msg=f)
    # mount B as printed in Table 1: (0.3, -0.51, -0.83) m, (-90, -26, -180) deg
    pin.framesForwardKinematics(m, d, np.zeros(m.nq))
    Mb = d.oMf[m.getFrameId("b_mount")]
    # (the URDF stores 12 significant digits, so agreement is ~1e-11, not 1e-16)
    np.testing.assert_allclose(Mb.translation, [0.3, -0.51, -0.83], atol=1e-10)
    np.testing.assert_allclose(Mb.rotation, Rz(-90 * DEG) @ Ry(-26 * DEG) @ Rx(-180 * DEG), atol=1e-10)


def test_tcb_frames_are_standard_dh_frames(rng):
    """Standard convention: D-H frame i = link_i · Tz(d_i) Tx(a_i) Rx(α_i); EE = D-H frame 7;
    link CoMs are given in D-H frame i."""
    desc_toml = tomllib.loads((models_dir() / "robots" / "tcbirrt_dual_arm.toml").read_text())
    coms = np.array(desc_toml["arm_types"]["ssrms7"]["coms"])
    m = plain_model("tcbirrt_dual_arm", False)
    d = m.createData()
    for _ in range(20):
        q = rng.uniform(-np.pi, np.pi, m.nq)
        pin.framesForwardKinematics(m, d, q)
        for p, mount in TCB_MOUNTS.items():
            jids = [m.getJointId(f"{p}_joint{i}") for i in range(1, 8)]
            qa = q[[m.idx_qs[j] for j in jids]]
            frames = dh_chain(TCB_DH, qa, "standard", H(None, mount))
            np.testing.assert_allclose(se3_h(d.oMf[m.getFrameId(f"{p}_ee")]), frames[-1], atol=1e-10)
            prev = [H(None, mount)] + frames[:-1]
            for i in range(1, 8):
                link = prev[i - 1] @ H(Rz(qa[i - 1] + TCB_DH[i - 1, 0] * DEG))
                np.testing.assert_allclose(se3_h(d.oMf[m.getFrameId(f"{p}_link{i}")]), link, atol=1e-10)
                com_world = d.oMi[jids[i - 1]].act(m.inertias[jids[i - 1]].lever)
                np.testing.assert_allclose(com_world, (frames[i - 1] @ np.r_[coms[i - 1], 1])[:3], atol=1e-10)


# --------------------------------------------------------------------------- user-defined arm
_USER_TOML = """
name = "{name}"
base_type = "fixed"
angle_unit = "{unit}"

[base]
link = "body"
mass = 3.0
inertia = [1.0, 0.0, 0.0, 1.0, 0.0, 1.0]

[arm_types.arm3]
dh_convention = "{conv}"
dh = {dh}
masses = [1.0, 2.0, 3.0]
coms = {coms}
inertias = [[0.02, 0.001, 0.002, 0.02, 0.003, 0.03], [0.02, 0.0, 0.0, 0.02, 0.0, 0.01],
            [0.03, 0.0, 0.004, 0.02, 0.0, 0.02]]
lower = [{lo}, {lo}, {lo}]
upper = [{hi}, {hi}, {hi}]
velocity = [1.0, 1.0, 1.0]
capsules = {caps}
tool = {{ xyz = {tool_xyz}, rpy = {tool_rpy} }}

[[arms]]
name = "left"
type = "arm3"
prefix = "l"
mount_xyz = {mount_xyz}
mount_{mount_kind} = {mount_angles}
"""


def _fmt(x):
    return repr(np.asarray(x, float).tolist())


def _user_robot(tmp_path, *, name, conv, dh_deg, coms, caps, tool_xyz=(0, 0, 0), tool_rpy_deg=(0, 0, 0),
                mount_xyz=(0, 0, 0), mount_kind="rpy", mount_deg=(0, 0, 0), unit="deg"):
    """Write a one-arm TOML (angles given here in degrees, written in ``unit``), generate its URDF
    and load it."""
    k = 1.0 if unit == "deg" else DEG
    dh = np.array(dh_deg, float)
    dh[:, :2] *= k
    cap_txt = "[" + ", ".join(f"{{ link = {c['link']}, a = {_fmt(c['a'])}, b = {_fmt(c['b'])}, radius = {c['r']} }}"
                              for c in caps) + "]"
    text = _USER_TOML.format(
        name=name, unit=unit, conv=conv, dh=_fmt(dh), coms=_fmt(coms), caps=cap_txt,
        lo=-170 * k, hi=170 * k, tool_xyz=_fmt(tool_xyz), tool_rpy=_fmt(np.asarray(tool_rpy_deg) * k),
        mount_xyz=_fmt(mount_xyz), mount_kind=mount_kind, mount_angles=_fmt(np.asarray(mount_deg) * k))
    toml_path = tmp_path / f"{name}.toml"
    toml_path.write_text(text)
    desc = load_description(toml_path)
    urdf = write_urdf(desc, tmp_path)
    from optplan.model.description import arm_metadata
    robot = RobotModel.from_urdf(urdf, arm_metadata(desc), floating=False, name=name)
    return robot


@pytest.mark.parametrize("conv", ["standard", "modified"])
@pytest.mark.parametrize("unit", ["deg", "rad"])
def test_user_planar_arm_matches_closed_form(tmp_path, rng, conv, unit):
    """3-link planar arm, link lengths 0.5, 0.4, 0.3, written in either convention: the EE is at
    Σ l_k (cos, sin)(θ_1 + … + θ_k), heading θ_1 + θ_2 + θ_3."""
    L = [0.5, 0.4, 0.3]
    if conv == "standard":
        dh = [[0, 0, L[0], 0], [0, 0, L[1], 0], [0, 0, L[2], 0]]
        tool = (0, 0, 0)
    else:  # row i holds a_{i-1}: the last length becomes the tool
        dh = [[0, 0, 0, 0], [0, 0, L[0], 0], [0, 0, L[1], 0]]
        tool = (L[2], 0, 0)
    robot = _user_robot(tmp_path, name=f"planar_{conv}_{unit}", conv=conv, dh_deg=dh, coms=np.zeros((3, 3)),
                        caps=[], tool_xyz=tool, unit=unit)
    assert robot.nq == 3 and list(robot.arms) == ["left"]
    d = robot.model.createData()
    fid = robot.model.getFrameId("l_ee")
    for _ in range(10):
        q = rng.uniform(-2.5, 2.5, 3)
        pin.framesForwardKinematics(robot.model, d, q)
        c = np.cumsum(q)
        p = [sum(L[k] * math.cos(c[k]) for k in range(3)), sum(L[k] * math.sin(c[k]) for k in range(3)), 0.0]
        np.testing.assert_allclose(d.oMf[fid].translation, p, atol=1e-10)
        np.testing.assert_allclose(d.oMf[fid].rotation, Rz(c[-1]), atol=1e-10)


SPATIAL_DH = [[10.0, 0.0, 0.1, 0.3], [-30.0, 90.0, 0.2, 0.05], [45.0, -60.0, 0.35, -0.1]]
SPATIAL_INERTIAS = np.array([[0.02, 0.001, 0.002, 0.02, 0.003, 0.03], [0.02, 0.0, 0.0, 0.02, 0.0, 0.01],
                             [0.03, 0.0, 0.004, 0.02, 0.0, 0.02]])  # as in _USER_TOML
SPATIAL_COMS = np.array([[0.01, -0.02, 0.03], [0.1, 0.02, -0.01], [-0.05, 0.04, 0.12]])
SPATIAL_CAPS = [{"link": 1, "a": [0.0, 0.0, -0.2], "b": [0.05, 0.0, 0.0], "r": 0.03},
                {"link": 2, "a": [0.0, 0.0, 0.0], "b": [0.2, 0.1, 0.0], "r": 0.04},
                {"link": 2, "a": [0.0, 0.05, 0.1], "b": [0.0, 0.05, -0.1], "r": 0.01},  # along -z
                {"link": 3, "a": [-0.1, 0.0, 0.05], "b": [0.0, 0.0, 0.3], "r": 0.025},
                {"link": 3, "a": [0.0, 0.1, 0.0], "b": [0.0, 0.1, 0.001], "r": 0.02}]


@pytest.mark.parametrize("conv", ["standard", "modified"])
@pytest.mark.parametrize("mount_kind", ["rpy", "zyx"])
def test_user_spatial_arm_matches_dh_product(tmp_path, rng, conv, mount_kind):
    """Spatial 3-joint arm with offsets, twists, a tool and a rotated mount: EE placement, link
    CoMs (given in D-H frames) and capsule end points against the hand-written D-H product."""
    mount_xyz, mount_deg = (0.2, -0.1, 0.5), (20.0, -35.0, 70.0)
    tool_xyz, tool_rpy = (0.01, 0.02, 0.15), (5.0, 10.0, -15.0)
    robot = _user_robot(tmp_path, name=f"spatial_{conv}_{mount_kind}", conv=conv, dh_deg=SPATIAL_DH,
                        coms=SPATIAL_COMS, caps=SPATIAL_CAPS, tool_xyz=tool_xyz, tool_rpy_deg=tool_rpy,
                        mount_xyz=mount_xyz, mount_kind=mount_kind, mount_deg=mount_deg)
    a, b, c = (v * DEG for v in mount_deg)
    Rm = Rz(c) @ Ry(b) @ Rx(a) if mount_kind == "rpy" else Rz(a) @ Ry(b) @ Rx(c)
    T0 = H(Rm, mount_xyz)
    r, p_, y = (v * DEG for v in tool_rpy)
    Ttool = H(Rz(y) @ Ry(p_) @ Rx(r), tool_xyz)
    m, d = robot.model, robot.model.createData()
    gm, gd = robot.collision_model, pin.GeometryData(robot.collision_model)
    jids = [m.getJointId(f"l_joint{i}") for i in range(1, 4)]
    for _ in range(10):
        q = rng.uniform(-2.5, 2.5, 3)
        pin.framesForwardKinematics(m, d, q)
        pin.updateGeometryPlacements(m, d, gm, gd, q)
        frames = dh_chain(SPATIAL_DH, q, conv, T0)
        np.testing.assert_allclose(se3_h(d.oMf[m.getFrameId("l_ee")]), frames[-1] @ Ttool, atol=1e-10)
        for i in range(3):
            com = d.oMi[jids[i]].act(m.inertias[jids[i]].lever)
            np.testing.assert_allclose(com, (frames[i] @ np.r_[SPATIAL_COMS[i], 1])[:3], atol=1e-10)
            # inertia about the CoM, given in D-H axes: the same tensor once both are in world axes
            xx, xy, xz, yy, yz, zz = SPATIAL_INERTIAS[i]
            I_dh = np.array([[xx, xy, xz], [xy, yy, yz], [xz, yz, zz]])
            Rl, Rd = d.oMi[jids[i]].rotation, frames[i][:3, :3]
            np.testing.assert_allclose(Rl @ m.inertias[jids[i]].inertia @ Rl.T, Rd @ I_dh @ Rd.T, atol=1e-10)
            assert m.inertias[jids[i]].mass == pytest.approx([1.0, 2.0, 3.0][i])
        # capsules: match by end points (unordered), per link
        for i in range(1, 4):
            expected = sorted(
                (c["r"], tuple(np.round(sorted([tuple((frames[i - 1] @ np.r_[c["a"], 1])[:3]),
                                                 tuple((frames[i - 1] @ np.r_[c["b"], 1])[:3])]), 9).ravel()))
                for c in SPATIAL_CAPS if c["link"] == i)
            got = []
            for k, obj in enumerate(gm.geometryObjects):
                if obj.parentJoint != jids[i - 1]:
                    continue
                assert isinstance(obj.geometry, coal.Capsule), obj.name
                M = gd.oMg[k]
                e1 = M.act(np.array([0, 0, obj.geometry.halfLength]))
                e2 = M.act(np.array([0, 0, -obj.geometry.halfLength]))
                got.append((obj.geometry.radius,
                            tuple(np.round(sorted([tuple(e1), tuple(e2)]), 9).ravel())))
            assert len(got) == len(expected), f"link {i}"
            for (re, pe), (rg, pg) in zip(expected, sorted(got)):
                assert rg == pytest.approx(re, abs=1e-12)
                np.testing.assert_allclose(pg, pe, atol=2e-9)


# --------------------------------------------------------------------------- collision geometry
@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
def test_collision_capsules_are_coal_capsules_with_toml_radii(name, rng, eba, tcb):
    robot = eba if name == "eba_ffsr" else tcb
    data = tomllib.loads((models_dir() / "robots" / f"{name}.toml").read_text())
    m = robot.model
    gm = robot.collision_model
    gd = pin.GeometryData(gm)
    d = m.createData()
    q = robot.random_configuration(rng)
    pin.framesForwardKinematics(m, d, q)
    pin.updateGeometryPlacements(m, d, gm, gd, q)
    n_expected = 0
    for arm in data["arms"]:
        at = data["arm_types"][arm["type"]]
        conv = at["dh_convention"]
        dh = np.array(at["dh"], float)
        for i in range(1, len(dh) + 1):
            jid = m.getJointId(f"{arm['prefix']}_joint{i}")
            # D-H frame i in the world, from the link frame (URDF link i)
            T = se3_h(d.oMi[jid])
            if conv == "standard":
                _, alpha, a, dd = dh[i - 1]
                T = T @ dh_standard(0.0, dd, a, alpha * DEG)
            caps = [c for c in at.get("capsules", []) if c["link"] == i]
            objs = [(k, o) for k, o in enumerate(gm.geometryObjects) if o.parentJoint == jid]
            assert len(objs) == len(caps), f"{arm['prefix']}_link{i}"
            n_expected += len(caps)
            for c in caps:
                ea = (T @ np.r_[c["a"], 1])[:3]
                eb = (T @ np.r_[c["b"], 1])[:3]
                found = False
                for k, o in objs:
                    assert isinstance(o.geometry, coal.Capsule), f"{o.name} is {type(o.geometry).__name__}"
                    h = o.geometry.halfLength
                    e = [gd.oMg[k].act(np.array([0, 0, s * h])) for s in (1.0, -1.0)]
                    if (np.allclose(e, [ea, eb], atol=1e-9) or np.allclose(e, [eb, ea], atol=1e-9)):
                        assert o.geometry.radius == pytest.approx(c["radius"], abs=1e-12)
                        found = True
                assert found, f"capsule {c} of {arm['prefix']}_link{i} not found"
    n_caps = sum(isinstance(o.geometry, coal.Capsule) for o in gm.geometryObjects)
    assert n_caps == n_expected
    # the base boxes are coal boxes of the TOML size
    boxes = [o for o in gm.geometryObjects if isinstance(o.geometry, coal.Box)]
    assert len(boxes) == len(data["base"]["boxes"])
    for o, b in zip(boxes, data["base"]["boxes"]):
        np.testing.assert_allclose(2 * np.asarray(o.geometry.halfSide), b["size"], atol=1e-12)


def test_plain_pinocchio_sees_cylinders_of_the_capsule_size():
    """URDF has no capsule: plain loaders get the cylinder core (same radius and length)."""
    path = str(urdf_dir() / "eba_ffsr.urdf")
    m = pin.buildModelFromUrdf(path, pin.JointModelFreeFlyer())
    plain = pin.buildGeomFromUrdf(m, path, pin.COLLISION)
    robot = RobotModel.from_name("eba_ffsr")
    caps = {o.name: o.geometry for o in robot.collision_model.geometryObjects}
    n = 0
    for o in plain.geometryObjects:
        if isinstance(o.geometry, coal.Cylinder):
            n += 1
            assert isinstance(caps[o.name], coal.Capsule)
            assert caps[o.name].radius == pytest.approx(o.geometry.radius)
            assert caps[o.name].halfLength == pytest.approx(o.geometry.halfLength)
    assert n == 18


def test_eba_self_distances_are_positive_and_finite_at_neutral(eba):
    d = eba.self_distances(eba.neutral())
    assert d.shape == (len(eba.collision_pairs),) and len(d) > 0
    assert np.all(np.isfinite(d)) and np.all(d > 0)


# --------------------------------------------------------------------------- dh_capsules
@pytest.mark.parametrize("conv", ["standard", "modified"])
def test_dh_capsules_trace_the_dh_polyline(tmp_path, rng, conv):
    """dh_capsules: consecutive segments along the D-H legs, from D-H frame 0 (standard) or the
    end of the a_0 leg (modified: that leg belongs to the mount) to the last D-H origin, through
    every D-H origin; each segment is one |a| or |d| leg of the table."""
    dh = [[10.0, 20.0, 0.15, 0.3], [-30.0, 90.0, 0.2, 0.05], [45.0, -60.0, 0.35, -0.1], [0.0, 30.0, 0.1, 0.2]]
    text = _USER_TOML.replace("masses = [1.0, 2.0, 3.0]", "masses = [1.0, 2.0, 3.0, 4.0]")
    text = (text.replace("[0.03, 0.0, 0.004, 0.02, 0.0, 0.02]]", "[0.03, 0.0, 0.004, 0.02, 0.0, 0.02], [0.01, 0, 0, 0.01, 0, 0.01]]")
            .replace("lower = [{lo}, {lo}, {lo}]", "lower = [-3, -3, -3, -3]")
            .replace("upper = [{hi}, {hi}, {hi}]", "upper = [3, 3, 3, 3]")
            .replace("velocity = [1.0, 1.0, 1.0]", "velocity = [1.0, 1.0, 1.0, 1.0]"))
    text = text.format(name="four", unit="deg", conv=conv, dh=_fmt(dh), coms=_fmt(np.zeros((4, 3))), caps="[]",
                       tool_xyz="[0, 0, 0]", tool_rpy="[0, 0, 0]", mount_xyz="[0.1, 0.2, 0.3]", mount_kind="rpy",
                       mount_angles="[10, 20, 30]")
    (tmp_path / "four.toml").write_text(text)
    arm = load_description(tmp_path / "four.toml").arm_types["arm3"]
    caps = dh_capsules(arm, 0.07)
    assert all(c["radius"] == 0.07 for c in caps)
    T0 = H(Rz(30 * DEG) @ Ry(20 * DEG) @ Rx(10 * DEG), [0.1, 0.2, 0.3])
    # every |d|, and every |a| except, in the modified convention, a_0 (row 1), which is in the mount
    skip_a0 = 1 if conv == "modified" else 0
    legs = sorted([abs(r[3]) for r in dh] + [abs(r[2]) for r in dh[skip_a0:]])
    for _ in range(5):
        q = rng.uniform(-3, 3, 4)
        frames = dh_chain(dh, q, conv, T0)
        segs = [((frames[c["link"] - 1] @ np.r_[c["a"], 1])[:3], (frames[c["link"] - 1] @ np.r_[c["b"], 1])[:3])
                for c in caps]
        start = T0[:3, 3] if conv == "standard" else (T0 @ dh_modified(dh[0][1] * DEG, dh[0][2], 0.0, 0.0))[:3, 3]
        np.testing.assert_allclose(segs[0][0], start, atol=1e-12)
        np.testing.assert_allclose(segs[-1][1], frames[-1][:3, 3], atol=1e-12)
        for s1, s2 in zip(segs, segs[1:]):
            np.testing.assert_allclose(s1[1], s2[0], atol=1e-12)
        ends = np.array([s[1] for s in segs])
        for T in frames:
            assert np.min(np.linalg.norm(ends - T[:3, 3], axis=1)) < 1e-12
        assert sorted(np.linalg.norm(b - a) for a, b in segs) == pytest.approx(legs, abs=1e-12)


@pytest.mark.parametrize("name,radius", [("eba_ffsr", 0.05), ("tcbirrt_dual_arm", 0.08)])
def test_shipped_capsules_are_the_dh_capsules(name, radius):
    """The TOML headers say the capsules were generated by dh_capsules: keep them in sync."""
    for at in load_description(name).arm_types.values():
        gen = dh_capsules(at, radius)
        assert len(gen) == len(at.capsules)
        for g, c in zip(gen, at.capsules):
            assert g["link"] == c["link"] and g["radius"] == c["radius"]
            np.testing.assert_allclose(g["a"], c["a"], atol=1e-12)
            np.testing.assert_allclose(g["b"], c["b"], atol=1e-12)
