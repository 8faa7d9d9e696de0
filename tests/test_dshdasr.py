"""The DSHDASR paper: the robot model with coupled serpentine joints, its symbolic kinematics,
the space-arc equivalent kinematics (residuals, joint recovery, arc-to-sphere distance), the
per-waypoint NLP on the nominal transposition, the DLS baseline and the Table 1 extra cases."""
from __future__ import annotations

import math

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan import Kinematics, RobotModel, SymbolicKinematics
from optplan.errors import ModelError
from optplan.model.description import load_description, urdf_dir
from optplan.model.urdf_writer import urdf_string
from optplan.papers.dshdasr import (
    PAPER,
    TABLE1_XF,
    ArcPlanner,
    DshdasrArcs,
    arm_a_on_swivel,
    dls_track,
    evaluate,
    initial_configuration,
    paper_task,
    quintic,
    run_case,
)
from optplan.papers.dshdasr.arc_models import frame_on
from optplan.papers.dshdasr.arcs import (
    arc_deviation,
    arc_from_tangent_length,
    arc_point_distance,
    arc_sample,
    sph,
    sph_angles,
)

D2R = math.pi / 180


# --------------------------------------------------------------------------- fixtures
@pytest.fixture(scope="module")
def robot() -> RobotModel:
    return RobotModel.from_name("dshdasr")


@pytest.fixture(scope="module")
def arcs(robot) -> DshdasrArcs:
    return DshdasrArcs(robot)


@pytest.fixture(scope="module")
def task():
    return paper_task()


@pytest.fixture(scope="module")
def planner(arcs) -> ArcPlanner:
    return ArcPlanner(arcs)


@pytest.fixture(scope="module")
def q_start(arcs, task, planner):
    return planner.clear_start(task, initial_configuration(arcs, task), clearance=0.1)


@pytest.fixture(scope="module")
def nominal(planner, task, q_start, arcs):
    """The nominal 601-waypoint transposition with the paper's obstacle constraint (d_arc >= d_sd)."""
    res = planner.track(task, q_start)
    evaluate(res, task, arcs, planner)
    return res


def random_q(robot, rng):
    """Random joints; Arm-b's pitch/yaw within ±17° so that every segment bends less than the
    NLP's bound of 150° (the arc model needs bends below 180°; the ±25° box allows up to 213°)."""
    q = robot.random_configuration(rng)
    ib = robot.arm("B").q_idx
    q[ib] = rng.uniform(-17 * D2R, 17 * D2R, len(ib))
    return q


def frames(arcs, q):
    m, d = arcs.model, arcs.data
    pin.framesForwardKinematics(m, d, q)
    return lambda n: d.oMf[m.getFrameId(n)]


def xa_xb(arcs, q):
    f = frames(arcs, q)
    def P(n):
        return f(n).translation.copy()

    Xa = arcs.a.params_from_points(P("a_link2"), P("a_link4"), P("a_link6"), P("a_ee"), f("a_ee").rotation[:, 2])
    Xb = arcs.b.params_from_segments([P(f"b_link{i}_1") for i in range(2, 6)] + [P("b_ee")],
                                     [f(f"b_link{i}_6").rotation[:, 0] for i in range(1, 6)])
    return Xa, Xb, f


# --------------------------------------------------------------------------- the robot model
def test_robot_structure_and_coupling(robot):
    assert (robot.nq, robot.nv, robot.nj) == (17, 17, 17)
    assert robot.arm("A").n == 7 and robot.arm("B").n == 10
    assert robot.arm("B").joint_names == tuple(f"b_joint{i}_1_{k}" for i in range(1, 6) for k in (1, 2))
    mimics = [j for j in range(1, robot.model.njoints) if robot.model.joints[j].shortname() == "JointModelMimic"]
    assert len(mimics) == 50                      # 5 segments x 6 universal joints x 2 axes - 10 actuated
    text = (urdf_dir() / "dshdasr.urdf").read_text()
    assert text.count("<mimic ") == 50
    assert text == urdf_string(load_description("dshdasr"))


def test_eq1_coupling_matches_the_uncoupled_model(robot, rng):
    """Pinocchio's mimic joints = the 60-joint URDF read without mimic, with every universal joint of
    a segment set to the same pitch and yaw (Eq. 1: θ_{i,j,1} = θ_{i,j+1,2}, θ_{i,j,2} = θ_{i,j+1,1})."""
    full = pin.buildModelFromUrdf(str(urdf_dir() / "dshdasr.urdf"), mimic=False)
    assert full.nq == 7 + 60
    dc, df = robot.model.createData(), full.createData()
    for _ in range(10):
        q = robot.random_configuration(rng)
        qf = np.zeros(full.nq)
        qa, qb = q[robot.arm("A").q_idx], q[robot.arm("B").q_idx]
        for i in range(1, 8):
            qf[full.idx_qs[full.getJointId(f"a_joint{i}")]] = qa[i - 1]
        for i in range(1, 6):
            pitch, yaw = qb[2 * i - 2], qb[2 * i - 1]
            for j in range(1, 7):
                first, second = (pitch, yaw) if j % 2 else (yaw, pitch)
                qf[full.idx_qs[full.getJointId(f"b_joint{i}_{j}_1")]] = first
                qf[full.idx_qs[full.getJointId(f"b_joint{i}_{j}_2")]] = second
        # Eq. 1 literally: first axis of joint j = second axis of joint j+1 and vice versa
        for i in range(1, 6):
            for j in range(1, 6):
                def v(jj, k, qf=qf, i=i):
                    return qf[full.idx_qs[full.getJointId(f"b_joint{i}_{jj}_{k}")]]

                assert v(j, 1) == v(j + 1, 2) and v(j, 2) == v(j + 1, 1)
        pin.framesForwardKinematics(robot.model, dc, q)
        pin.framesForwardKinematics(full, df, qf)
        for fr in ("a_ee", "b_ee", "b_link3_4"):
            np.testing.assert_allclose(dc.oMf[robot.model.getFrameId(fr)].homogeneous,
                                       df.oMf[full.getFrameId(fr)].homogeneous, atol=1e-12)


def test_capsule_radii_are_the_paper_envelopes(robot):
    caps = {g.name: g.geometry for g in robot.collision_model.geometryObjects}
    a = [g for n, g in caps.items() if n.startswith("a_")]
    b = [g for n, g in caps.items() if n.startswith("b_")]
    assert len(a) == 4 and len(b) == 30
    import coal
    assert all(isinstance(g, coal.Capsule) for g in a + b)
    assert {round(g.radius, 9) for g in a} == {0.09}
    assert {round(g.radius, 9) for g in b} == {0.035}
    assert {round(2 * g.halfLength, 9) for g in b} == {0.15}


def test_each_segment_is_a_planar_tangent_polygon(arcs, robot, rng):
    """The coupled pitch-yaw/yaw-pitch layout bends a segment in one plane by equal angles, so its
    joint centres are equidistant from one centre in one plane (links tangent to an arc)."""
    for _ in range(10):
        q = robot.random_configuration(rng)
        f = frames(arcs, q)
        for i in range(1, 6):
            pts = [f(f"b_link{i}_{j}").translation for j in range(1, 7)]
            pts.append(f(f"b_link{i + 1}_1").translation if i < 5 else f("b_ee").translation)
            P = np.array(pts)
            dirs = np.diff(P, axis=0)
            n = np.cross(dirs[0], dirs[1])
            if np.linalg.norm(n) < 1e-9:
                continue
            n /= np.linalg.norm(n)
            assert np.abs(dirs @ n).max() < 1e-12                   # planar
            turns = [math.acos(np.clip(dirs[k] @ dirs[k + 1] / 0.15 ** 2, -1, 1)) for k in range(5)]
            assert np.ptp(turns) < 1e-9                              # equal turning angles


def test_serpentine_schema_is_validated(tmp_path):
    src = (load_description("dshdasr").source).read_text()
    (tmp_path / "odd.toml").write_text(src.replace("joints_per_segment = 6", "joints_per_segment = 5"))
    with pytest.raises(ModelError, match="even"):
        load_description(tmp_path / "odd.toml")
    (tmp_path / "kind.toml").write_text(src.replace('kind = "serpentine"', 'kind = "snake"'))
    with pytest.raises(ModelError, match="kind"):
        load_description(tmp_path / "kind.toml")


# --------------------------------------------------------------------------- symbolic kinematics
@pytest.fixture(scope="module")
def sym(robot):
    return SymbolicKinematics(robot)


@pytest.mark.parametrize("frame", ["a_ee", "b_ee", "b_link3_4"])
def test_casadi_fk_and_jacobian_equal_pinocchio(robot, sym, frame, rng):
    f = sym.fk_jacobian_function(frame)
    kin = Kinematics(robot)
    for _ in range(50):
        q = robot.random_configuration(rng)
        R, p, J = (np.array(x) for x in f(q))
        M = kin.frame_placement(q, frame)
        np.testing.assert_allclose(R, M.rotation, atol=1e-10)
        np.testing.assert_allclose(p.ravel(), M.translation, atol=1e-10)
        np.testing.assert_allclose(J, kin.frame_jacobian(q, frame), atol=1e-10)


@pytest.mark.parametrize("frame", ["a_ee", "b_ee"])
def test_casadi_jacobian_matches_finite_differences(robot, sym, frame, rng):
    f = sym.fk_jacobian_function(frame)
    h = 1e-6
    for _ in range(10):
        q = robot.random_configuration(rng)
        R0, p0, J = (np.array(x) for x in f(q))
        for j in range(robot.nv):
            dq = np.zeros(robot.nq)
            dq[j] = h
            Rp, pp, _ = (np.array(x) for x in f(q + dq))
            Rm, pm, _ = (np.array(x) for x in f(q - dq))
            np.testing.assert_allclose((pp - pm).ravel() / (2 * h), J[:3, j], atol=1e-7)
            W = (Rp - Rm) / (2 * h) @ R0.T
            np.testing.assert_allclose([W[2, 1], W[0, 2], W[1, 0]], J[3:, j], atol=1e-7)


# --------------------------------------------------------------------------- equivalent kinematics
def test_arc_residuals_vanish_on_configurations_from_fk(arcs, robot, rng):
    worst = 0.0
    for _ in range(50):
        q = random_q(robot, rng)
        Xa, Xb, f = xa_xb(arcs, q)
        pa, ka = f("a_ee").translation, f("a_ee").rotation[:, 2]
        pb, kb = f("b_ee").translation, f("b_ee").rotation[:, 0]
        for r in (arcs.a.residuals(ca.DM(Xa), ca.DM(pa), ca.DM(ka)),
                  arcs.a.paper_residuals(ca.DM(Xa), ca.DM(pa), ca.DM(ka)),
                  arcs.b.residuals(ca.DM(Xb), ca.DM(pb), ca.DM(kb))):
            worst = max(worst, float(np.abs(np.array(r)).max()))
        # the arcs start/end at the model's own points: C3 of Arm-a ends L5/2 beyond the wrist
        ends = [np.array(a.end()).ravel() for a in arcs.b.arcs(ca.DM(Xb), ca.DM(pb), ca.DM(kb))]
        np.testing.assert_allclose(ends[-1], pb - 0.075 * kb, atol=1e-12)
    assert worst < 1e-12


def test_residuals_detect_a_wrong_configuration(arcs, robot, rng):
    q = random_q(robot, rng)
    Xa, Xb, f = xa_xb(arcs, q)
    pa, ka = f("a_ee").translation, f("a_ee").rotation[:, 2]
    pb, kb = f("b_ee").translation, f("b_ee").rotation[:, 0]
    assert np.abs(np.array(arcs.a.residuals(ca.DM(Xa), ca.DM(pa + [0, 0, 0.01]), ca.DM(ka)))).max() > 1e-3
    Xb2 = Xb.copy()
    Xb2[6] += 0.01    # move p1 off its arc: the chord vector residual sees it (the scalar chord would not)
    assert np.abs(np.array(arcs.b.residuals(ca.DM(Xb2), ca.DM(pb), ca.DM(kb)))).max() > 1e-3


def test_joint_recovery_round_trips(arcs, robot, rng):
    for _ in range(50):
        q = random_q(robot, rng)
        Xa, Xb, f = xa_xb(arcs, q)
        qa, qb = q[arcs.arm_a.q_idx], q[arcs.arm_b.q_idx]
        ra = arcs.a.recover_joints(Xa, f("a_ee").translation, f("a_ee").rotation, q_prev=qa)
        rb = arcs.b.recover_joints(Xb, f("b_ee").translation, f("b_ee").rotation[:, 0])
        np.testing.assert_allclose(ra, qa, atol=1e-9)
        np.testing.assert_allclose(rb, qb, atol=1e-12)
        # without a previous configuration another branch may come out: same tip pose
        ra0 = arcs.a.recover_joints(Xa, f("a_ee").translation, f("a_ee").rotation)
        Ma, _ = arcs.tips(arcs.q(ra0, qb))
        np.testing.assert_allclose(Ma.homogeneous, f("a_ee").homogeneous, atol=1e-12)


def test_recovery_in_recentred_angle_frames(arcs, robot, rng):
    q = random_q(robot, rng)
    refs = tuple(frame_on(rng.normal(size=3)) for _ in range(3))
    Xa, Xb = arcs.params_from_q(q, refs)
    f = frames(arcs, q)
    back = arcs.q_from_params(Xa, Xb, f("a_ee").translation, f("a_ee").rotation, f("b_ee").translation,
                              f("b_ee").rotation[:, 0], q_prev=q, refs=refs)
    np.testing.assert_allclose(back, q, atol=1e-9)


def test_sph_angles_invert_sph(rng):
    for _ in range(20):
        a1, a2 = rng.uniform(0.01, math.pi - 0.01), rng.uniform(-math.pi, math.pi)
        b1, b2 = sph_angles(sph(a1, a2))
        assert abs(b1 - a1) < 1e-12 and abs(math.remainder(b2 - a2, 2 * math.pi)) < 1e-12
    R = frame_on([0.3, -0.2, 0.9])
    np.testing.assert_allclose(R @ sph(math.pi / 2, 0.0), np.array([0.3, -0.2, 0.9]) / np.linalg.norm([0.3, -0.2, 0.9]))


@pytest.fixture(scope="module")
def dist_fun():
    P, t0, t1, o = (ca.SX.sym(n, 3) for n in ("P", "t0", "t1", "o"))
    phi, T = ca.SX.sym("phi"), ca.SX.sym("T")
    arc = arc_from_tangent_length(P, t0, t1, phi, T)
    d = arc_point_distance(arc, o)
    return ca.Function("d", [P, t0, t1, phi, T, o], [d, ca.gradient(d, ca.vertcat(P, t0, t1, phi, o))])


@pytest.mark.parametrize("kind", ["curved", "nearly straight", "straight"])
def test_arc_to_sphere_distance_is_exact_and_smooth(dist_fun, rng, kind):
    """Eq. 45-47 as a smooth constraint: the exact point-to-arc distance (brute force over 20001
    points), with a finite gradient even for a straight arc."""
    for _ in range(200):
        P = rng.normal(size=3)
        a = rng.normal(size=3)
        a /= np.linalg.norm(a)
        b = rng.normal(size=3)
        b -= b @ a * a
        b /= np.linalg.norm(b)
        phi = {"curved": rng.uniform(0.05, 2.8), "nearly straight": 10 ** rng.uniform(-9, -3), "straight": 0.0}[kind]
        t1 = math.cos(phi) * a + math.sin(phi) * b
        T = rng.uniform(0.1, 1.5)
        o = P + rng.normal(size=3) * rng.uniform(0.1, 3.0)
        d, g = (np.array(x).ravel() for x in dist_fun(P, a, t1, phi, T, o))
        if phi > 1e-6:
            R = T / math.tan(phi / 2)
            th = np.linspace(0, phi, 20001)
            pts = P + R * b + R * (np.sin(th)[:, None] * a - np.cos(th)[:, None] * b)
        else:
            pts = P + np.linspace(0, 2 * T, 20001)[:, None] * a
        assert abs(d[0] - np.linalg.norm(pts - o, axis=1).min()) < 2e-6
        assert np.all(np.isfinite(g))


def test_arc_sample_and_deviation():
    a = arc_from_tangent_length(ca.DM([0, 0, 0]), ca.DM([1, 0, 0]), ca.DM([0, 1, 0]), math.pi / 2, 1.0)
    pts = arc_sample(a, 101)
    np.testing.assert_allclose(pts[-1], [1, 1, 0], atol=1e-12)
    np.testing.assert_allclose(np.linalg.norm(pts - [0, 1, 0], axis=1), 1.0, atol=1e-12)
    corner = np.array([1.0, 0.0, 0.0])
    assert abs(np.linalg.norm(pts - corner, axis=1).min() - arc_deviation(1.0, math.pi / 2)) < 1e-4


# --------------------------------------------------------------------------- task
def test_quintic_and_the_sign_reading(task):
    t = task.times()
    assert len(t) == 601 and t[-1] == 60.0
    X = quintic(task.X0, task.Xf, t, 60.0)
    np.testing.assert_allclose(X[0], task.X0)
    np.testing.assert_allclose(X[-1], task.Xf)
    v = np.gradient(X, t, axis=0)
    assert np.abs(v[0]).max() < 1e-3 and np.abs(v[-1]).max() < 1e-3
    # the text: the pitch stays in [-21, -1] deg; Table 1's goals scatter around Xf
    assert -21.0 <= np.degrees(X[:, 4]).min() and np.degrees(X[:, 4]).max() <= -1.0
    xf = np.array(TABLE1_XF)
    assert np.all(np.sign(xf[:, [0, 2, 3, 4, 5]]) == np.sign(np.r_[task.Xf[[0, 2]], np.degrees(task.Xf[3:])]))
    for T in (task.T_et_a, task.T_et_b):
        assert abs(np.linalg.det(T[:3, :3]) - 1) < 1e-12
    d = task.desired(t)
    np.testing.assert_allclose(np.linalg.norm(d["kb"], axis=1), 1.0)
    gap = np.linalg.norm(d["pa"] - d["pb"], axis=1)
    assert np.ptp(gap) < 1e-9 and 0.5 < gap[0] < 1.5        # Arm-b keeps its distance to the locked point
    assert task.thresholds["a"] == pytest.approx(0.45)     # d_sd^a of the paper


def test_initial_configuration_holds_the_first_tips(arcs, task, q_start):
    d = task.desired([0.0])
    Ma, Mb = arcs.tips(q_start)
    np.testing.assert_allclose(Ma.translation, d["pa"][0], atol=1e-9)
    np.testing.assert_allclose(Ma.rotation, d["Ra"][0], atol=1e-9)
    np.testing.assert_allclose(Mb.translation, d["pb"][0], atol=1e-9)
    np.testing.assert_allclose(Mb.rotation[:, 0], d["kb"][0], atol=1e-9)
    qa = arm_a_on_swivel(arcs, d["pa"][0], d["Ra"][0], 1.0)
    Ma2, _ = arcs.tips(arcs.q(qa, q_start[arcs.arm_b.q_idx]))
    np.testing.assert_allclose(Ma2.homogeneous, Ma.homogeneous, atol=1e-9)


# --------------------------------------------------------------------------- the NLP on the task
def test_nominal_task_tip_errors_by_fk_of_recovered_joints(nominal):
    m = nominal.metrics
    assert m["nlp_failures"] == 0 and m["n_waypoints"] == 601
    assert m["max_tip_position_error_a_m"] <= 1e-6 and m["max_tip_position_error_b_m"] <= 1e-6
    assert m["max_tip_attitude_error_a_rad"] <= 1e-6 and m["max_tip_direction_error_b_rad"] <= 1e-6
    assert np.all(np.abs(np.diff(nominal.q, axis=0)).max(axis=0) < 0.1)     # continuous joint path


def test_obstacle_constraint_becomes_active_and_holds(nominal, task):
    """A distance reaches its threshold during the motion (not at the start) and never goes below."""
    con = nominal.series["arc_constraint"]
    active = [(arm, i) for arm in ("a", "b") for i in range(2) if con[arm][:, i].min() < 1e-6]
    assert active, "no obstacle constraint became active on the nominal task"
    for arm in ("a", "b"):
        assert con[arm].min() > -1e-7
        np.testing.assert_array_less(task.thresholds[arm] - 1e-7, nominal.series["arc"][arm])
    arm, i = active[0]
    first = np.nonzero(con[arm][:, i] < 1e-6)[0][0]
    assert nominal.t[first] > 1.0 and con[arm][0, i] > 0.05


def _hausdorff(A: np.ndarray, B: np.ndarray) -> float:
    D = np.linalg.norm(A[:, None, :] - B[None, :, :], axis=2)
    return max(D.min(axis=1).max(), D.min(axis=0).max())


def test_coal_distances_agree_with_the_arc_model(nominal, arcs, task):
    """coal (link capsules) and the arc model measure the same obstacle-to-centre-line distance up
    to how far the arcs are from the links: |d_coal − d_arc| ≤ Hausdorff(arcs, link axes)."""
    import casadi as ca
    s = nominal.series
    d = nominal.des
    for k in range(0, 601, 20):
        X = nominal.X[k]
        f = frames(arcs, nominal.q[k])
        link_a = [arcs.a.base_xyz] + [f(n).translation for n in ("a_link2", "a_link4", "a_link6", "a_ee")]
        link_b = [f("b_mount").translation] + [f(f"b_link{i}_{j}").translation for i in range(1, 6)
                                                for j in range(1, 7)] + [f("b_ee").translation]
        for arm, model, links, Xk, tip in (("a", arcs.a, link_a, X[:8], (d["pa"][k], d["Ra"][k][:, 2])),
                                            ("b", arcs.b, link_b, X[8:], (d["pb"][k], d["kb"][k]))):
            arcs_k = model.arcs(ca.DM(Xk), ca.DM(tip[0]), ca.DM(tip[1]))
            A = np.vstack([arc_sample(a, 60) for a in arcs_k])
            L = np.vstack([np.linspace(p, q, 40) for p, q in zip(links[:-1], links[1:])])
            H = _hausdorff(A, L)
            diff = np.abs(s["coal"][arm][k] - s["arc"][arm][k])
            assert np.all(diff <= H + 5e-3), (arm, k, diff, H)
    # the serpentine's arcs hug its short links (polygon vertex to arc <= (L_b/2) tan(25°/4) = 8 mm);
    # they stop half a link (75 mm) short of the tip and start half a link behind the mount
    assert np.abs(s["coal"]["b"] - s["arc"]["b"]).max() < 0.075 + 0.009


def test_links_margin_keeps_coal_clearance_above_thresholds(arcs, task, q_start):
    pl = ArcPlanner(arcs, margin="links")
    res = pl.track(task, q_start, times=task.times()[100:200])
    m = evaluate(res, task, arcs, pl)
    assert m["nlp_failures"] == 0
    for arm in ("a", "b"):
        for o in ("obs1", "obs2"):
            assert m["min_clearance_m"][arm][o] >= task.thresholds[arm]
    assert m["min_arc_constraint_m"]["b"]["obs1"] < 1e-6      # still active, now with the margin


def test_least_squares_formulation_of_eq50(arcs, task, q_start):
    """The paper's form (min ||G1||² + ||G2||², obstacle inequalities) on a stretch of the task."""
    pl = ArcPlanner(arcs, formulation="least-squares", hessian="gauss-newton")
    res = pl.track(task, q_start, times=task.times()[:40])
    m = evaluate(res, task, arcs, pl)
    assert m["nlp_failures"] == 0
    assert max(m["max_tip_position_error_a_m"], m["max_tip_position_error_b_m"]) < 1e-6


# --------------------------------------------------------------------------- DLS baseline
def test_dls_baseline_tracks_the_tips(arcs, task, q_start):
    res = dls_track(arcs, task, q_start, times=task.times()[:60])
    m = evaluate(res, task, arcs)
    assert res.success.all()
    assert m["max_tip_position_error_a_m"] < 1e-8 and m["max_tip_position_error_b_m"] < 1e-8
    assert m["max_tip_attitude_error_a_rad"] < 1e-8 and m["max_tip_direction_error_b_rad"] < 1e-8


# --------------------------------------------------------------------------- Table 1
@pytest.mark.slow
@pytest.mark.parametrize("case", range(5))
def test_table1_extra_goals_succeed(planner, task, q_start, case):
    sf, res, m = run_case(planner, task.with_goal(TABLE1_XF[case]), q_start)
    assert sf == PAPER["cases"][case] == "S"


def test_one_extra_goal_quick(planner, task, q_start):
    """Table 1 case 5 (the farthest goal) on the first 30 s: every NLP converges."""
    t2 = task.with_goal(TABLE1_XF[4])
    res = planner.track(t2, q_start, times=t2.times()[:301])
    assert res.success.all()


@pytest.mark.slow
def test_compiled_nlp_gives_the_interpreted_solutions(arcs, task, q_start, planner):
    pc = ArcPlanner(arcs, compile=True)
    t = task.times()[:30]
    a, b = planner.track(task, q_start, times=t), pc.track(task, q_start, times=t)
    if not pc.compiled:
        pytest.skip("no C compiler")
    np.testing.assert_allclose(b.q, a.q, atol=1e-8)
