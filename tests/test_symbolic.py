"""CasADi kinematics (optplan.model.symbolic) against Pinocchio's numeric algorithms, finite
differences of Pinocchio's FK, an expanded (non-mimic) model, and compiled C code."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan import codegen
from optplan.codegen import compile_function
from optplan.model.kinematics import Kinematics
from optplan.model.robot import RobotModel
from optplan.model.symbolic import SymbolicKinematics

N_CONFIGS = 50
REFS = {"world_aligned": pin.ReferenceFrame.LOCAL_WORLD_ALIGNED,
        "local": pin.ReferenceFrame.LOCAL,
        "world": pin.ReferenceFrame.WORLD}
# EEs and intermediate frames: link frames (joint bodies), fixed frames (mount), the base body
FRAMES = ["a_ee", "b_ee", "a_link3", "b_link5", "a_link1", "b_mount", "base"]


@pytest.fixture(scope="module")
def robots(eba, tcb):
    return {"eba_ffsr": eba, "tcbirrt_dual_arm": tcb}


@pytest.fixture(scope="module")
def syms(robots):
    return {k: SymbolicKinematics(r) for k, r in robots.items()}


def _np(x):
    return np.array(ca.DM(x))


def _configs(robot, n=N_CONFIGS, seed=2024):
    rng = np.random.default_rng(seed)
    return [robot.random_configuration(rng) for _ in range(n)]


# --------------------------------------------------------------------------- placements, Jacobians
@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
def test_fk_and_frame_jacobians_match_pinocchio(name, robots, syms):
    robot, sk = robots[name], syms[name]
    m, d = robot.model, robot.model.createData()
    fns = {(f, ref): sk.fk_jacobian_function(f, ref) for f in FRAMES for ref in REFS}
    worst = 0.0
    for q in _configs(robot):
        pin.framesForwardKinematics(m, d, q)
        for f in FRAMES:
            fid = m.getFrameId(f)
            M = d.oMf[fid]
            for ref, pref in REFS.items():
                R, p, J = fns[(f, ref)](q)
                Jp = pin.computeFrameJacobian(m, d, q, fid, pref)
                err = max(np.abs(_np(R) - M.rotation).max(), np.abs(_np(p).ravel() - M.translation).max(),
                          np.abs(_np(J) - Jp).max())
                assert err < 1e-10, (name, f, ref, err)
                worst = max(worst, err)
    assert worst < 1e-10


@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
def test_fk_and_jacobian_functions_agree_with_fk_jacobian_function(name, robots, syms):
    robot, sk = robots[name], syms[name]
    for f in ("a_ee", "b_link5"):
        fk, fkj = sk.fk_function(f), sk.fk_jacobian_function(f, "local")
        jac = sk.jacobian_function(f, "local")
        for q in _configs(robot, 5):
            R1, p1 = fk(q)
            R2, p2, J2 = fkj(q)
            np.testing.assert_array_equal(_np(R1), _np(R2))
            np.testing.assert_array_equal(_np(p1), _np(p2))
            np.testing.assert_allclose(_np(jac(q)), _np(J2), atol=1e-14)
    # frame ids work as names do, and functions are cached
    fid = robot.model.getFrameId("a_ee")
    assert sk.fk_function(fid) is sk.fk_function("a_ee")


@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
def test_centroidal_map_and_com_match_pinocchio(name, robots, syms):
    robot, sk = robots[name], syms[name]
    m, d = robot.model, robot.model.createData()
    Agf = sk.centroidal_map_function()
    qs = ca.SX.sym("q", m.nq)
    comf = ca.Function("com", [qs], [sk.center_of_mass(qs)])
    for q in _configs(robot):
        Ag = pin.computeCentroidalMap(m, d, q)
        scale = max(1.0, np.abs(Ag).max())
        np.testing.assert_allclose(_np(Agf(q)), Ag, rtol=0, atol=1e-10 * scale)
        np.testing.assert_allclose(_np(comf(q)).ravel(), pin.centerOfMass(m, d, q), rtol=0, atol=1e-10)


@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
def test_generalized_jacobian_matches_numeric(name, robots, syms):
    robot, sk = robots[name], syms[name]
    kin = Kinematics(robot)
    fns = {a: sk.generalized_jacobian_function(a) for a in robot.arms}
    for q in _configs(robot):
        for a, f in fns.items():
            Jn = kin.generalized_jacobian(q, a)
            assert Jn.shape == (6, robot.nj)
            np.testing.assert_allclose(_np(f(q)), Jn, rtol=0, atol=1e-10 * max(1.0, np.abs(Jn).max()))


def test_expression_level_methods_share_one_recursion(robots, syms):
    """joint_placements + frame_placement/frame_jacobian/centroidal_map with a shared X."""
    robot, sk = robots["eba_ffsr"], syms["eba_ffsr"]
    m, d = robot.model, robot.model.createData()
    q = ca.SX.sym("q", m.nq)
    X = sk.joint_placements(q)
    assert len(X) == m.njoints
    R, p = sk.frame_placement(q, "b_link7", X)
    J = sk.frame_jacobian(q, "b_link7", "world", X)
    Ag = sk.centroidal_map(q, X)
    f = ca.Function("all", [q], [R, p, J, Ag] + [X[j][0] for j in range(m.njoints)]
                    + [X[j][1] for j in range(m.njoints)])
    fid = m.getFrameId("b_link7")
    for qv in _configs(robot, 10):
        out = f(qv)
        pin.framesForwardKinematics(m, d, qv)
        np.testing.assert_allclose(_np(out[0]), d.oMf[fid].rotation, atol=1e-10)
        np.testing.assert_allclose(_np(out[1]).ravel(), d.oMf[fid].translation, atol=1e-10)
        np.testing.assert_allclose(_np(out[2]), pin.computeFrameJacobian(m, d, qv, fid, pin.WORLD), atol=1e-10)
        np.testing.assert_allclose(_np(out[3]), pin.computeCentroidalMap(m, d, qv), atol=1e-9)
        pin.forwardKinematics(m, d, qv)
        for j in range(m.njoints):
            np.testing.assert_allclose(_np(out[4 + j]), d.oMi[j].rotation, atol=1e-10)
            np.testing.assert_allclose(_np(out[4 + m.njoints + j]).ravel(), d.oMi[j].translation, atol=1e-10)


def test_mx_expressions_equal_sx(robots):
    robot = robots["tcbirrt_dual_arm"]
    sx, mx = SymbolicKinematics(robot), SymbolicKinematics(robot, sym=ca.MX)
    for q in _configs(robot, 5):
        for f in ("a_ee", "b_link3"):
            for ref in REFS:
                a, b = sx.fk_jacobian_function(f, ref)(q), mx.fk_jacobian_function(f, ref)(q)
                for x, y in zip(a, b):
                    np.testing.assert_allclose(_np(x), _np(y), atol=1e-12)
        np.testing.assert_allclose(_np(sx.centroidal_map_function()(q)), _np(mx.centroidal_map_function()(q)),
                                   atol=1e-10)
        np.testing.assert_allclose(_np(sx.generalized_jacobian_function("B")(q)),
                                   _np(mx.generalized_jacobian_function("B")(q)), atol=1e-12)


# --------------------------------------------------------------------------- AD vs finite differences
def _fk_numeric(m, d, q, fid):
    pin.framesForwardKinematics(m, d, q)
    M = d.oMf[fid]
    return M.translation.copy(), M.rotation.copy()


@pytest.mark.parametrize("name", ["eba_ffsr", "tcbirrt_dual_arm"])
@pytest.mark.parametrize("frame", ["a_ee", "b_link4"])
def test_casadi_jacobian_matches_finite_differences_of_pinocchio_fk(name, frame, robots, syms):
    """d/dq of the symbolic FK (casadi.jacobian) against central differences of Pinocchio's FK,
    on the joint coordinates (and, for the floating base, the base position)."""
    robot, sk = robots[name], syms[name]
    m, d = robot.model, robot.model.createData()
    fid = m.getFrameId(frame)
    q = ca.SX.sym("q", m.nq)
    R, p = sk.frame_placement(q, frame)
    f = ca.Function("dfk", [q], [ca.jacobian(p, q), ca.jacobian(ca.vec(R), q)])
    cols = list(range(robot.base_nq, m.nq)) + ([0, 1, 2] if robot.is_floating else [])
    h = 1e-6
    for qv in _configs(robot, 5, seed=7):
        Jp, JR = (_np(x) for x in f(qv))
        for i in cols:
            e = np.zeros(m.nq)
            e[i] = h
            pp, Rp = _fk_numeric(m, d, qv + e, fid)
            pm, Rm = _fk_numeric(m, d, qv - e, fid)
            np.testing.assert_allclose(Jp[:, i], (pp - pm) / (2 * h), atol=1e-8, err_msg=f"dp/dq{i}")
            np.testing.assert_allclose(JR[:, i], ((Rp - Rm) / (2 * h)).ravel(order="F"), atol=1e-8,
                                       err_msg=f"dR/dq{i}")
        # and the AD derivative is the geometric Jacobian: dp/dq_j = J_lin, dR/dq_j Rᵀ = [ω_j]×
        if not robot.is_floating:
            Jg = pin.computeFrameJacobian(m, d, qv, fid, pin.LOCAL_WORLD_ALIGNED)
            Rv = d.oMf[fid].rotation
            np.testing.assert_allclose(Jp, Jg[:3], atol=1e-10)
            for j in range(m.nq):
                W = JR[:, j].reshape(3, 3, order="F") @ Rv.T
                np.testing.assert_allclose([W[2, 1], W[0, 2], W[1, 0]], Jg[3:, j], atol=1e-10)


# --------------------------------------------------------------------------- unusual joints
MIMIC_URDF = """<?xml version="1.0"?>
<robot name="odd_joints">
  <link name="base"><inertial><origin xyz="0.01 0 0"/><mass value="3"/>
    <inertia ixx="1" ixy="0.01" ixz="0" iyy="1.2" iyz="0" izz="0.9"/></inertial></link>
  <link name="l1"><inertial><origin xyz="0.1 0.2 0.05" rpy="0.1 0.2 0.3"/><mass value="1.5"/>
    <inertia ixx="0.1" ixy="0.01" ixz="0" iyy="0.2" iyz="0.02" izz="0.3"/></inertial></link>
  <link name="l2"><inertial><origin xyz="0.3 0 0"/><mass value="1.0"/>
    <inertia ixx="0.05" ixy="0" ixz="0" iyy="0.1" iyz="0" izz="0.1"/></inertial></link>
  <link name="l3"><inertial><origin xyz="0 0.1 0.2"/><mass value="0.7"/>
    <inertia ixx="0.02" ixy="0" ixz="0" iyy="0.03" iyz="0" izz="0.04"/></inertial></link>
  <link name="l4"><inertial><origin xyz="0.05 0 0.1"/><mass value="0.4"/>
    <inertia ixx="0.01" ixy="0" ixz="0" iyy="0.01" iyz="0" izz="0.01"/></inertial></link>
  <link name="tip"/>
  <joint name="j1" type="revolute"><parent link="base"/><child link="l1"/>
    <origin xyz="0.1 0 0.2" rpy="0.3 -0.2 0.1"/><axis xyz="1 1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="j2" type="prismatic"><parent link="l1"/><child link="l2"/>
    <origin xyz="0.4 0 0" rpy="0 0.5 0"/><axis xyz="0 0.6 0.8"/>
    <limit lower="-0.5" upper="0.5" effort="1" velocity="1"/></joint>
  <joint name="j3" type="revolute"><parent link="l2"/><child link="l3"/>
    <origin xyz="0.3 0.1 0" rpy="0 0 0.7"/><axis xyz="0 0 1"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/>
    <mimic joint="j1" multiplier="0.5" offset="0.1"/></joint>
  <joint name="j4" type="revolute"><parent link="l3"/><child link="l4"/>
    <origin xyz="0 0.2 0.1" rpy="0.2 0 0"/><axis xyz="0 -1 0"/>
    <limit lower="-2" upper="2" effort="1" velocity="1"/></joint>
  <joint name="tipj" type="fixed"><parent link="l4"/><child link="tip"/>
    <origin xyz="0.1 0.05 0" rpy="0 0 0.4"/></joint>
</robot>
"""
MIMIC_MULT, MIMIC_OFFSET = 0.5, 0.1


@pytest.fixture(scope="module")
def mimic_path(tmp_path_factory):
    p = tmp_path_factory.mktemp("mimic") / "odd_joints.urdf"
    p.write_text(MIMIC_URDF)
    return p


def test_robot_model_accepts_mimic_joints_built_by_hand(mimic_path):
    """RobotModel(model, geom, arms, floating=False) on a model from buildModelFromUrdf(mimic=True)."""
    model = pin.buildModelFromUrdf(str(mimic_path), mimic=True)
    geom = pin.buildGeomFromUrdf(model, str(mimic_path), pin.COLLISION)
    robot = RobotModel(model, geom, {"arm": {"ee": "tip"}}, floating=False)
    assert (robot.nq, robot.nv, robot.nj) == (3, 3, 3)
    assert robot.joint_names == ("j1", "j2", "j4")
    assert robot.arm("arm").joint_names == ("j1", "j2", "j4")
    assert robot.lower.shape == (3,) and robot.velocity_limit.shape == (3,)


@pytest.mark.parametrize("floating", [False, True])
def test_prismatic_unaligned_and_mimic_joints_match_pinocchio_and_expanded_model(mimic_path, floating):
    """FK, Jacobians (3 references), CoM and Ag of a prismatic joint, a revolute joint about
    (1, 1, 0) and a mimic joint θ3 = 0.5 θ1 + 0.1: equal to Pinocchio's mimic model AND to the
    same URDF loaded without mimic (4 independent joints) with θ3 set by hand and the Jacobian
    columns of j1 and j3 combined by the chain rule."""
    robot = RobotModel.from_urdf(mimic_path, {"arm": "tip"}, floating=floating)
    ff = (pin.JointModelFreeFlyer(),) if floating else ()
    full = pin.buildModelFromUrdf(str(mimic_path), *ff, mimic=False)
    assert robot.nv == full.nv - 1
    sk = SymbolicKinematics(robot)
    m, d = robot.model, robot.model.createData()
    fd = full.createData()
    b = robot.base_nq
    bv = robot.base_nv
    i1, i3 = full.idx_qs[full.getJointId("j1")], full.idx_qs[full.getJointId("j3")]
    v1, v3 = full.idx_vs[full.getJointId("j1")], full.idx_vs[full.getJointId("j3")]
    keep_v = [k for k in range(full.nv) if k != v3]
    fns = {ref: sk.fk_jacobian_function("tip", ref) for ref in REFS}
    Agf = sk.centroidal_map_function()
    rng = np.random.default_rng(99)
    fid, ffid = m.getFrameId("tip"), full.getFrameId("tip")
    for _ in range(N_CONFIGS):
        q = robot.random_configuration(rng)
        qf = np.zeros(full.nq)
        qf[:b] = q[:b]
        qf[[k for k in range(full.nq) if k != i3]] = q
        qf[i3] = MIMIC_MULT * qf[i1] + MIMIC_OFFSET
        pin.framesForwardKinematics(m, d, q)
        pin.framesForwardKinematics(full, fd, qf)
        np.testing.assert_allclose(d.oMf[fid].homogeneous, fd.oMf[ffid].homogeneous, atol=1e-12)
        for ref, pref in REFS.items():
            R, p, J = (_np(x) for x in fns[ref](q))
            np.testing.assert_allclose(R, fd.oMf[ffid].rotation, atol=1e-10)
            np.testing.assert_allclose(p.ravel(), fd.oMf[ffid].translation, atol=1e-10)
            Jf = pin.computeFrameJacobian(full, fd, qf, ffid, pref)
            Jf[:, v1] += MIMIC_MULT * Jf[:, v3]
            np.testing.assert_allclose(J, Jf[:, keep_v], atol=1e-10, err_msg=ref)
            np.testing.assert_allclose(J, pin.computeFrameJacobian(m, d, q, fid, pref), atol=1e-10)
        Agf_ = pin.computeCentroidalMap(full, fd, qf)
        Agf_[:, v1] += MIMIC_MULT * Agf_[:, v3]
        np.testing.assert_allclose(_np(Agf(q)), Agf_[:, keep_v], atol=1e-10)
        np.testing.assert_allclose(_np(Agf(q)), pin.computeCentroidalMap(m, d, q), atol=1e-10)
    assert bv == (6 if floating else 0)


def test_continuous_joints_are_refused_with_their_name(tmp_path):
    """A continuous joint (Pinocchio: nq = 2, cos/sin) is neither a RobotModel joint nor a symbolic
    one; both errors name it."""
    from types import SimpleNamespace

    from optplan.errors import ModelError

    text = MIMIC_URDF.replace('<joint name="j4" type="revolute"', '<joint name="j4" type="continuous"')
    p = tmp_path / "cont.urdf"
    p.write_text(text)
    model = pin.buildModelFromUrdf(str(p))
    assert model.nqs[model.getJointId("j4")] == 2
    geom = pin.buildGeomFromUrdf(model, str(p), pin.COLLISION)
    with pytest.raises(ModelError, match="'j4'"):
        RobotModel(model, geom, {"arm": {"ee": "tip", "joints": ["j1", "j2", "j3"]}}, floating=False)
    with pytest.raises(ModelError, match="'j4'"):
        SymbolicKinematics(SimpleNamespace(model=model))


# --------------------------------------------------------------------------- compiled code
def test_compiled_functions_equal_interpreted(robots, syms):
    cases = [(robots["tcbirrt_dual_arm"], syms["tcbirrt_dual_arm"].fk_jacobian_function("b_ee", "local")),
             (robots["tcbirrt_dual_arm"], syms["tcbirrt_dual_arm"].generalized_jacobian_function("A")),
             (robots["eba_ffsr"], syms["eba_ffsr"].fk_jacobian_function("a_ee", "world_aligned"))]
    for robot, f in cases:
        c = compile_function(f)
        assert isinstance(c, codegen.CompiledFunction), "a C compiler is available here; expected compiled code"
        for q in _configs(robot, 20, seed=5):
            outs_c, outs_i = c(q), f.call([q])
            assert len(outs_c) == f.n_out()
            for oc, oi in zip(outs_c, outs_i):
                oi = _np(oi)
                if oi.shape[1] == 1:
                    assert oc.ndim == 1
                    oi = oi[:, 0]
                np.testing.assert_allclose(oc, oi, rtol=0, atol=1e-12)
        # the shared library is cached: a second compile reuses it
        c2 = compile_function(f)
        np.testing.assert_array_equal(c2(q)[0], c(q)[0])
    libs = list(codegen.cache_dir().glob("*.so"))
    assert len(libs) >= 3


def test_compile_function_without_compiler_returns_the_interpreted_function(monkeypatch, syms):
    f = syms["tcbirrt_dual_arm"].fk_function("a_link2")
    monkeypatch.setattr(codegen.shutil, "which", lambda *a, **k: None)
    assert compile_function(f) is f


def test_compiled_function_checks_its_inputs(syms):
    f = syms["tcbirrt_dual_arm"].fk_function("a_link2")
    c = compile_function(f)
    with pytest.raises(TypeError):
        c()
    with pytest.raises(ValueError, match="shape"):
        c(np.zeros(3))


def test_ee_velocity_and_acceleration_functions_match_pinocchio(tcb, rng):
    """Classical EE acceleration J q̈ + J̇ q̇ vs Pinocchio's getFrameClassicalAcceleration."""
    from optplan.model.symbolic import SymbolicKinematics

    sym = SymbolicKinematics(tcb)
    fv, fa = sym.ee_velocity_function("B"), sym.ee_acceleration_function("B")
    data = tcb.model.createData()
    fid = tcb.arm("B").ee_frame_id
    for _ in range(10):
        q, v, a = tcb.random_configuration(rng), rng.normal(size=tcb.nv), rng.normal(size=tcb.nv)
        pin.forwardKinematics(tcb.model, data, q, v, a)
        pin.updateFramePlacements(tcb.model, data)
        LWA = pin.ReferenceFrame.LOCAL_WORLD_ALIGNED
        vel = pin.getFrameVelocity(tcb.model, data, fid, LWA).linear
        acc = pin.getFrameClassicalAcceleration(tcb.model, data, fid, LWA).linear
        np.testing.assert_allclose(np.array(fv(q, v)).ravel(), vel, atol=1e-10)
        np.testing.assert_allclose(np.array(fa(q, v, a)).ravel(), acc, atol=1e-9)


def test_ee_velocity_function_floating_uses_generalized_jacobian(eba, rng):
    from optplan.model.kinematics import Kinematics
    from optplan.model.symbolic import SymbolicKinematics

    f = SymbolicKinematics(eba).ee_velocity_function("A")
    qj, qd = eba.random_joints(rng), rng.normal(size=eba.nj)
    J = Kinematics(eba).generalized_jacobian(eba.configuration(qj), "A")
    np.testing.assert_allclose(np.array(f(qj, qd)).ravel(), J[:3] @ qd, atol=1e-10)
