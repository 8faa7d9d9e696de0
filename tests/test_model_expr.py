"""OptProblem on the B-spline kernel core: one-line expressions, parameters, the seeded first
guess and named rows — each checked against something independent (Pinocchio, CasADi's own
derivatives of the same NLP, the B-spline's knot values)."""
from __future__ import annotations

import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from optplan import RobotModel
from optplan.errors import ConfigurationError, OptionError, UnknownNameError
from optplan.problem import OptProblem
from optplan.problem.expressions import register_quantity
from optplan.problem.frame_terms import BaseAttitude, ClosedChain
from optplan.problem.terms import JointBoundary, JointPositionLimits, Smoothness


@pytest.fixture(scope="module")
def tcb():
    return RobotModel.from_name("tcbirrt_dual_arm")


@pytest.fixture(scope="module")
def ffsr():
    return RobotModel.from_name("eba_ffsr")


def _ee(robot, arm="A"):
    return robot.model.frames[robot.arm(arm).ee_frame_id].name


def _fk(robot, q, frame, base=None):
    data = robot.model.createData()
    qf = q if base is None else np.r_[base[0], base[1], q]
    pin.framesForwardKinematics(robot.model, data, qf)
    return data.oMf[robot.model.getFrameId(frame)]


def _reach(robot, q0, offset, N=20, T=20.0):
    """The free-floating reach task: arm A's hand by ``offset`` [m], arm B still, base attitude
    restored, written with expressions only; the target is a parameter."""
    M0 = _fk(robot, q0, _ee(robot), (np.zeros(3), np.array([0, 0, 0, 1.0])) if robot.is_floating else None)
    prob = OptProblem(robot, n_intervals=N, duration=T)
    target = prob.parameter(3, M0.translation + offset)
    prob.add_constraint(prob.q, lower=q0, upper=q0, at="start", name="start")
    prob.add_constraint(ca.vertcat(prob.qd, prob.qdd), lower=0, upper=0, at=[0, N], name="rest")
    prob.add_constraint(prob.qd[7:], lower=0, upper=0, name="arm_b_still")
    hand = prob.add_constraint(prob.frame(_ee(robot)).translation - target, lower=0, upper=0, at="end", name="reach")
    if robot.is_floating:
        prob.add_constraint(BaseAttitude(at="end"))
    prob.add_cost(Smoothness("jerk"))
    return prob, target, hand


Q0 = np.r_[[0.3, -0.6, 0.4, -1.2, 0.2, 0.7, 0.1] * 2]


def test_floating_reach_converges_from_the_seeded_guess_and_checks_out(ffsr):
    prob, target, hand = _reach(ffsr, Q0, 0.3 * np.array([0.6, 0.0, 0.8]))
    assert prob.uses_bspline()
    sol = prob.solve()
    assert sol.success, sol.status
    assert sol.iterations <= 40
    # independent: Pinocchio at the solution's end configuration and base placement
    base = (sol.base_position[-1], sol.base_quat[-1])
    M = _fk(ffsr, sol.q[-1], _ee(ffsr), base)
    goal = prob._params[0].value.ravel()
    assert np.linalg.norm(M.translation - goal) < 1e-6
    R_end = pin.Quaternion(sol.base_quat[-1][3], *sol.base_quat[-1][:3]).toRotationMatrix()
    assert np.linalg.norm(pin.log3(R_end)) < 1e-6
    np.testing.assert_allclose(sol.q[:, 7:], np.tile(Q0[7:], (len(sol.t), 1)), atol=1e-6)
    # zero momentum: the centre of mass stays where it was (the base position follows from it)
    data = ffsr.model.createData()
    c = [pin.centerOfMass(ffsr.model, data, np.r_[p, qb, q]) for p, qb, q in zip(sol.base_position, sol.base_quat, sol.q)]
    assert np.ptp(np.array(c), axis=0).max() < 1e-9
    # the handle evaluates the expression; between knots it matches Pinocchio too
    np.testing.assert_allclose(sol.value(hand).ravel(), M.translation - goal, atol=1e-9)


def test_parameters_resolve_without_a_rebuild(ffsr):
    prob, target, hand = _reach(ffsr, Q0, 0.3 * np.array([0.6, 0.0, 0.8]))
    s1 = prob.solve()
    assert s1.success
    kc = prob._spline.core.kc
    n_struct = len(kc._structures)
    new = prob._params[0].value.ravel() + np.array([0.0, 0.05, 0.0])
    prob.set_value(target, new)
    s2 = prob.solve()
    assert s2.success and len(kc._structures) == n_struct   # nothing built
    M = _fk(ffsr, s2.q[-1], _ee(ffsr), (s2.base_position[-1], s2.base_quat[-1]))
    assert np.linalg.norm(M.translation - new) < 1e-6
    prob.set_initial(solution=s2)
    s3 = prob.solve()
    assert s3.success and s3.iterations <= 3 and s3.setup_time < 0.05
    with pytest.raises(ConfigurationError, match="shape"):
        prob.set_value(target, [1.0, 2.0])
    with pytest.raises(OptionError, match="not a parameter"):
        prob.set_value(ca.SX.sym("p", 3), np.zeros(3))


def test_fixed_base_expressions_match_pinocchio_at_and_between_knots(tcb):
    rng = np.random.default_rng(3)
    qa = tcb.random_joints(rng) * 0.3
    qb = qa + 0.4
    prob = OptProblem(tcb, n_intervals=10, duration=4.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=0 * qa, qdd=0 * qa))
    prob.add_constraint(JointBoundary("end", q=qb, qd=0 * qa, qdd=0 * qa))
    vmax = 0.15
    slow = prob.add_constraint(prob.qd[1], lower=-vmax, upper=vmax, name="slow_joint")
    frame = _ee(tcb)
    pos = prob.frame(frame).translation
    h_pos = prob.add_constraint(pos[2], lower=-10, upper=10, name="height")
    acc = prob.add_cost(prob.qdd, weight=2.0, name="acc")
    sol = prob.solve()
    assert sol.success
    assert np.abs(sol.qd[:, 1]).max() <= vmax + 1e-6
    assert np.isclose(np.abs(sol.qd[:, 1]).max(), vmax, atol=1e-4)       # the limit is active
    np.testing.assert_allclose(sol.value(slow).ravel(), sol.qd[:, 1], atol=1e-12)
    # integral cost: the trapezoid of 2‖q̈‖² at the knots
    qq = np.sum(sol.qdd ** 2, axis=1)
    assert sol.value(acc) == pytest.approx(2.0 * np.trapezoid(qq, sol.t), rel=1e-9)
    # frame expressions against Pinocchio at the knots and between them
    z = np.array([_fk(tcb, q, frame).translation[2] for q in sol.q])
    np.testing.assert_allclose(sol.value(h_pos).ravel(), z, atol=1e-12)
    ts = np.linspace(0, sol.duration, 37)
    zs = np.array([_fk(tcb, q, frame).translation[2] for q in sol.sample(ts)["q"]])
    np.testing.assert_allclose(sol.sample(ts, h_pos).ravel(), zs, atol=1e-12)
    np.testing.assert_allclose(sol.sample(ts, slow).ravel(), sol.sample(ts)["qd"][:, 1], atol=1e-12)


def test_the_assembled_derivatives_equal_casadis_own(ffsr):
    """Exact Jacobian and Hessian by constant scatters == CasADi's AD of the same (symbolic) NLP."""
    prob, target, _ = _reach(ffsr, Q0, 0.2 * np.array([0.0, 0.6, 0.8]), N=6, T=8.0)
    prob.compile_kernels = False
    prob.add_cost(ca.sumsqr(prob.frame(_ee(ffsr, "B")).translation) * prob.t, kind="integral", weight=0.3)
    prob.add_constraint(prob.com[0] ** 2 + prob.qdd[2] * prob.qd[3], upper=5.0)
    prob.uses_bspline()
    core, be = prob._spline.core, prob._spline
    st = core.structure(be.row_families(), bool(be.pbounds), False)
    nlp = st["nlp"]
    rng = np.random.default_rng(1)
    x = rng.normal(size=core.nx) * 0.3
    p = be._pvec(8.0, np.array([0.1, -0.2, 0.3]), 0.7)
    lam_g = rng.normal(size=nlp["g"].shape[0])
    G, J = st["derivs"]["jac_g"](x, p)
    Jad = ca.Function("j", [nlp["x"], nlp["p"]], [ca.jacobian(nlp["g"], nlp["x"])])(x, p)
    np.testing.assert_allclose(np.array(ca.densify(J)), np.array(ca.densify(Jad)), atol=1e-9)
    H = st["derivs"]["hess_lag"](x, p, 1.3, lam_g)
    L = 1.3 * nlp["f"] + ca.dot(ca.MX(lam_g), nlp["g"])
    Had = ca.Function("h", [nlp["x"], nlp["p"]], [ca.triu(ca.hessian(L, nlp["x"])[0])])(x, p)
    np.testing.assert_allclose(np.array(ca.densify(H)), np.array(ca.densify(Had)), atol=1e-8)
    f, gr = st["derivs"]["grad_f"](x, p)
    gad = ca.Function("g", [nlp["x"], nlp["p"]], [ca.gradient(nlp["f"], nlp["x"])])(x, p)
    np.testing.assert_allclose(np.array(gr).ravel(), np.array(gad).ravel(), atol=1e-9)


def test_rows_are_named_in_the_users_language(tcb):
    """A closed chain the pinned end violates and a joint limit the end needs past: the rows say
    term, knot or joint, component and time."""
    rng = np.random.default_rng(5)
    qa = tcb.random_joints(rng) * 0.4
    cc = ClosedChain.from_configuration(tcb, qa)
    qb = qa + 0.3
    prob = OptProblem(tcb, n_intervals=6, duration=3.0)
    prob.add_constraint(JointBoundary("start", q=qa, qd=0 * qa, qdd=0 * qa))
    prob.add_constraint(JointBoundary("end", q=qb, qd=0 * qa, qdd=0 * qa))
    prob.add_constraint(cc)
    hi = tcb.upper.copy()
    hi[2] = qa[2] + 0.1
    prob.add_constraint(JointPositionLimits(upper=hi))
    prob.add_constraint(prob.qd[0], upper=1e-3, lower=-1e-3, at=[3], name="hold_joint")
    prob.add_cost(Smoothness("jerk"))
    sol = prob.solve(max_iter=20)
    assert not sol.success
    rows = prob.infeasibilities(sol, n=200)
    labels = [r.label for r in rows]
    assert any(lab.startswith("closed_chain[k=6].") and lab.endswith(" at t=3 s") for lab in labels), labels[:5]
    jn = tcb.joint_names[2]
    assert any(lab.startswith(f"joint_limits[{jn}].upper at t=") for lab in labels), labels[:8]
    assert all(r.violation > 0 for r in rows) and [r.violation for r in rows] == sorted(
        [r.violation for r in rows], reverse=True)
    assert str(rows[0]).startswith(rows[0].label)


def test_bad_expressions_are_refused_by_name(tcb):
    prob = OptProblem(tcb, n_intervals=6, duration=3.0)
    with pytest.raises(UnknownNameError, match="no_such_frame"):
        prob.frame("no_such_frame")
    stranger = ca.SX.sym("stranger")
    prob.add_constraint(prob.q[0] + stranger, lower=0, upper=0)
    with pytest.raises(ConfigurationError, match="stranger"):
        prob.solve()
    with pytest.raises(OptionError, match="lower and/or upper"):
        prob.add_constraint(prob.q[0])
    with pytest.raises(ConfigurationError, match="knot indices"):
        prob.add_constraint(prob.q[0], lower=0, at=[99])
    with pytest.raises(ConfigurationError, match="n_intervals ≥ 4"):
        OptProblem(tcb, n_intervals=3, duration=3.0, transcription="bspline").solve()


def test_a_registered_quantity_is_one_function(tcb):
    register_quantity("qd_squared", lambda s: s.qd * s.qd)
    prob = OptProblem(tcb, n_intervals=6, duration=3.0)
    assert isinstance(prob.qd_squared, ca.SX) and prob.qd_squared.shape == (tcb.nj, 1)
    with pytest.raises(AttributeError):
        prob.no_such_quantity  # noqa: B018


def test_expressions_on_the_knot_transcription_agree_with_the_bspline(tcb):
    """The same one-line problem on both transcriptions (C2 cubics on the same grid): same
    optimum; the expression's rows hold on each."""
    rng = np.random.default_rng(4)
    qa = tcb.random_joints(rng) * 0.3
    qb = qa + 0.3
    sols = {}
    for tr in ("bspline", "knots"):
        prob = OptProblem(tcb, n_intervals=8, duration=4.0, transcription=tr)
        w = prob.parameter(1, 3.0)
        prob.add_constraint(ca.vertcat(prob.q, prob.qd, prob.qdd), lower=np.r_[qa, 0 * qa, 0 * qa],
                            upper=np.r_[qa, 0 * qa, 0 * qa], at="start")
        prob.add_constraint(ca.vertcat(prob.q, prob.qd, prob.qdd), lower=np.r_[qb, 0 * qa, 0 * qa],
                            upper=np.r_[qb, 0 * qa, 0 * qa], at="end")
        h = prob.add_constraint(prob.qd[1], lower=-0.11, upper=0.11)
        prob.add_cost(prob.qdd, weight=w)
        if tr == "knots":
            prob.set_initial_straight_line(qa, qb)
        sol = prob.solve(tol=1e-9)
        assert sol.success and prob.uses_bspline() == (tr == "bspline")
        assert np.abs(sol.value(h)).max() <= 0.11 + 1e-8
        sols[tr] = sol
    assert sols["bspline"].cost == pytest.approx(sols["knots"].cost, rel=1e-5)
    np.testing.assert_allclose(sols["bspline"].q, sols["knots"].q, atol=1e-5)


def test_bench_modelling_refuses_an_unknown_task_and_formats_rows():
    from optplan.bench.modelling import format_rows, main

    with pytest.raises(SystemExit):
        main(["--tasks", "reach,no_such_task"])
    row = {"transcription": "bspline", "total_s": 1.0, "setup_s": 0.1, "solve_s": 0.8, "solve_cpu_s": 0.3,
           "iterations": 23, "success": True, "hand_error_m": 2e-10,
           "resolve": {"overhead_s": 0.004, "overhead_cpu_s": 0.003, "check_s": 0.002, "iterations": 0,
                       "success": True}}
    warm = {**row, "repeats": {k: [0.2, 0.3, 0.25] for k in ("total_s", "total_cpu_s", "build_s", "solve_s",
                                                            "solve_cpu_s")}}
    text = format_rows([{"task": "reach", "first": row, "warm": warm}, {"task": "transport", "error": ["boom"]}])
    assert "hand_error_m=2e-10" in text and "4.0 ms" in text and "error" in text
    assert "3 warm problems" in text and "0.250 [0.200-0.300]" in text
    with pytest.raises(SystemExit):
        main(["--repeat", "0", "--tasks", "reach"])


def test_transport_with_collision_and_two_custom_terms_on_the_kernel_core(tcb):
    """The closed-chain transport (shipped terms, collision planes from the segment NLP's kernels)
    plus "the object stays upright within 5°" and an acceleration cost, one line each: solved on
    the B-spline core and checked independently (coal clearance and closed chain at 10× the knot
    density; the upright row sampled between the knots)."""
    from optplan.scene import Scene
    from optplan.tasks import transport_initial_path, transport_problem
    from optplan.verification import verify

    scene = Scene.load("transport")
    Q = transport_initial_path(tcb, scene, 16, np.random.default_rng(0))
    assert Q is not None
    prob, cc, _ = transport_problem(tcb, scene, Q, fixed_normals=True, transcription="auto")
    G = scene.object.grasps["A"]
    up = prob.add_constraint((prob.frame(_ee(tcb)).rotation @ ca.DM(G.rotation.T))[2, 2],
                             lower=np.cos(np.radians(5.0)), name="upright")
    prob.add_cost(prob.qdd, weight=1e-3, name="acceleration")
    assert prob.uses_bspline()
    sol = prob.solve()
    assert sol.success, sol.status
    rep = verify(tcb, sol, scene, closed_chain=cc)
    assert rep.max_closed_chain_residual <= 1e-4 and rep.min_clearance_m >= 0.0   # chain: at the knots, ∝ h⁴ between
    assert np.min(sol.value(up)) >= np.cos(np.radians(5.0)) - 1e-6
    assert sol.terms["collision"] <= 1e-6
    assert any(n.startswith("collision:") for n in prob._spline.owner["collision"])



def test_velocity_rows_missed_by_the_guess_are_added_and_hold_everywhere(tcb):
    """Fixed duration: velocity entries get rows only where the guess nears the limit. A guess
    that moves only in its last interval leaves the middle without rows; the minimum-jerk motion
    would exceed the limit there (peak 1.875 Δq/T), so the rows are added after the solve and the
    re-solve holds the limit — checked on the dense joint velocity of the B-spline, against the
    same problem with every entry given a row (free T pinned by its bounds)."""
    from optplan.problem.terms import JointVelocityLimits

    N, T, dq = 10, 2.0, 1.0
    q0 = 0.2 * np.ones(tcb.nj)
    q1 = q0.copy()
    q1[0] += dq
    lim = np.full(tcb.nj, 0.75)          # < 1.875·Δq/T = 0.94 rad/s: the limit binds
    z = np.zeros(tcb.nj)

    def make(free_time):
        prob = OptProblem(tcb, n_intervals=N, duration=T, free_time=free_time, duration_bounds=(0.999 * T, T))
        prob.add_constraint(JointBoundary("start", q=q0, qd=z, qdd=z))
        prob.add_constraint(JointBoundary("end", q=q1, qd=z, qdd=z))
        prob.add_constraint(JointVelocityLimits(limit=lim), name="vel")
        prob.add_cost(Smoothness("jerk"))
        Q = np.repeat(q0[None], N + 1, axis=0)
        Q[-1] = q1
        prob.set_initial(q=Q)
        return prob

    prob = make(False)
    assert prob.uses_bspline()
    sol = prob.solve()
    assert sol.success, sol.status
    assert len(sol.attempts) >= 2 and sol.attempts[-1].label == "velocity rows"
    qd = sol.sample(np.linspace(0.0, T, 20 * N + 1))["qd"]
    assert np.abs(qd).max() <= 0.75 + 1e-6 and np.abs(qd[:, 0]).max() >= 0.75 - 1e-3   # holds and binds
    # every entry has its rows (free duration: less jerk at T = upper bound); a tight tolerance, or
    # the duration stops 2e-7 s short of its bound (a 3e-5 relative cost difference)
    ref = make(True).solve(tol=1e-9)
    assert ref.success and abs(ref.duration - T) <= 1e-6
    assert abs(sol.cost - ref.cost) <= 1e-5 * abs(ref.cost)
    assert sol.dual("vel").shape == (N + 2, tcb.nj)


def test_bench_ur5_task_keeps_its_margin_or_skips_cleanly(monkeypatch):
    """The UR5 from example-robot-data around one box: solved on the kernel core, the 0.02 m
    margin held between the knots by coal on the meshes (verify); without the package the task
    reports itself skipped."""
    import optplan.model._robot_data as rd
    from optplan.bench import modelling

    if rd.example_robot_data_dir() is None:
        assert modelling.run_task("ur5")["skipped"].startswith("example-robot-data")
        pytest.skip("example-robot-data is not installed")
    row = modelling.run_task("ur5")["warm"]
    assert row["success"] and row["transcription"] == "bspline"
    assert row["min_clearance_m"] >= 0.02 - 1e-4 and row["margin_held"] == 1.0
    monkeypatch.setattr(rd, "example_robot_data_dir", lambda: None)
    out = modelling.run_task("ur5")
    assert "skipped" in out and "warm" not in out
    assert "skipped" in modelling.format_rows([out])


def test_rockit_solution_samples_its_exact_cubic(monkeypatch):
    """The peer's solution between knots: q̇ and q̈ are the derivatives of q (finite differences),
    and the knot values are reproduced; without rockit the peer reports itself skipped."""
    from optplan.bench import rockit_peer
    from optplan.bench.modelling import run_peer
    from optplan.bench.rockit_peer import CubicSolution

    monkeypatch.setattr(rockit_peer, "available", lambda: False)
    assert "not installed" in run_peer("transport")["skipped"]

    rng = np.random.default_rng(3)
    t = np.linspace(0.0, 2.0, 5)
    q0, v0, a0 = rng.normal(size=3), rng.normal(size=3), rng.normal(size=3)
    J = rng.normal(size=(5, 3))
    q, v, a = [q0], [v0], [a0]
    for k in range(4):   # integrate the cubic exactly
        h = t[k + 1] - t[k]
        q.append(q[-1] + v[-1] * h + a[-1] * h**2 / 2 + J[k] * h**3 / 6)
        v.append(v[-1] + a[-1] * h + J[k] * h**2 / 2)
        a.append(a[-1] + J[k] * h)
    sol = CubicSolution(t, np.array(q), np.array(v), np.array(a), J)
    ts = np.linspace(0.01, 1.99, 37)
    e = 1e-6
    s, sp, sm = sol.sample(ts), sol.sample(ts + e), sol.sample(ts - e)
    assert np.allclose((sp["q"] - sm["q"]) / (2 * e), s["qd"], atol=1e-6)
    assert np.allclose((sp["qd"] - sm["qd"]) / (2 * e), s["qdd"], atol=1e-6)
    assert np.allclose(sol.sample(t)["q"], q, atol=1e-12)


def test_rockit_peer_transport_holds_the_closed_chain(tcb):
    """The transport written in rockit (extra 'rockit'; skipped without it) on 16 intervals:
    solved, and its closed chain checked by verify."""
    pytest.importorskip("rockit")
    from optplan.bench import rockit_peer
    from optplan.bench.modelling import format_peers
    from optplan.scene import Scene
    from optplan.tasks import transport_initial_path, transport_problem
    from optplan.verification import verify

    scene = Scene.load("transport")
    Q = transport_initial_path(tcb, scene, 16, np.random.default_rng(0))
    assert Q is not None
    _, cc, _ = transport_problem(tcb, scene, Q, fixed_normals=True, transcription="auto")
    r = rockit_peer.transport(tcb, Q, cc)
    assert r["success"] and r["iterations"] > 0
    rep = verify(tcb, r["solution"], scene, closed_chain=cc, check_velocity=False)
    assert rep.max_closed_chain_residual <= 1e-3          # at the grid points exactly, ∝ h⁴ between
    text = format_peers([{"task": "transport", "peer": "rockit", **{k: v for k, v in r.items() if k != "solution"},
                          "closed_chain_residual": 1e-7, "min_clearance_m": -0.3, "note": "no collision rows"}],
                        [{"task": "transport", "first": {"total_cpu_s": 1.0}, "warm": {"total_cpu_s": 0.5}}])
    assert "rockit cpu / ours" in text and "(warm)" in text


def test_rockit_peer_reach_keeps_zero_momentum(ffsr):
    """The free-floating reach written in rockit by hand (zero momentum, attitude quaternion) on 6
    intervals: the hand reaches the target (Pinocchio at the reconstructed base) and verify's own
    integration of the base from the joint motion agrees with rockit's attitude."""
    pytest.importorskip("rockit")
    from optplan.bench import modelling, rockit_peer
    from optplan.verification import verify

    prob, ctx = modelling._reach(False)
    robot, target, _ = ctx
    r = rockit_peer.reach(robot, modelling.Q0, target, "a_ee", N=6)
    assert r["success"]
    chk = modelling._check_reach(prob, r["solution"], ctx)
    assert chk["hand_error_m"] <= 1e-5 and chk["arm_b_motion_rad"] <= 1e-8
    rep = verify(robot, r["solution"], None)
    assert rep.max_momentum_residual <= 1e-8 and rep.base_attitude_mismatch_rad <= 5e-3   # RK4, 6 steps


def test_rockit_peer_free_time_reach_keeps_its_limits_at_the_grid(ffsr):
    """The free-final-time reach in rockit (``FreeTime``, extra 'rockit'; skipped without it) on 6
    intervals: solved, the duration within its bounds, the hand on target (Pinocchio) and the
    limits held at the grid points (between them rockit's cubic may exceed a velocity limit)."""
    pytest.importorskip("rockit")
    from optplan.bench import modelling, rockit_peer

    prob, ctx = modelling._reach(True)
    robot, target, _ = ctx
    r = rockit_peer.reach(robot, modelling.Q0, target, "a_ee", N=6, free_time=True, duration_bounds=(2.0, 60.0))
    assert r["success"]
    sol = r["solution"]
    assert 2.0 <= sol.duration <= 60.0
    assert modelling._check_reach(prob, sol, ctx)["hand_error_m"] <= 1e-5
    assert np.abs(sol.qd).max() <= 0.1 + 1e-6 and np.abs(sol.qdd).max() <= 0.02 + 1e-6
