"""The Drake peer (optional extra ``drake``): the verify adapter against the B-spline itself, the
hand-written closed-chain constraint against optplan's Pinocchio closed chain and finite
differences, the hand-written jerk cost against the sampled trajectory, the collision set-up
against coal, and a tiny solve that ends in a status."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

pytest.importorskip("pydrake")

from optplan.bench import drake_bench as DB  # noqa: E402
from optplan.bench.drake_peer import (  # noqa: E402
    BsplineSolution,
    ClosedChainResidual,
    DrakeModel,
    DrakeOptions,
    _basis,
    fit_bspline,
    jerk_matrix,
    solve_drake,
)
from optplan.collision.checker import CollisionChecker  # noqa: E402
from optplan.problem.terms import NumericTrajectory  # noqa: E402
from optplan.scene import Scene  # noqa: E402
from optplan.verification import verify  # noqa: E402


@pytest.fixture(scope="module")
def transport():
    return Scene.load("transport")


@pytest.fixture(scope="module")
def dm(tcb, transport):
    return DrakeModel(tcb, transport)


def _random_spline(dm, rng, N=6, T=20.0):
    from pydrake.trajectories import BsplineTrajectory

    nq = dm.plant.num_positions()
    P = rng.uniform(-1.0, 1.0, (nq, N + 3))
    return BsplineTrajectory(_basis(N, T), [P[:, [i]] for i in range(N + 3)]), P


def test_model_kinematics_and_joint_order_match_pinocchio(tcb, dm, rng):
    for _ in range(5):
        q = tcb.random_joints(rng)
        assert np.allclose(dm.from_drake(dm.to_drake(q)), q)
        dm.plant.SetPositions(dm.plant_context, dm.to_drake(q))
        data = tcb.model.createData()
        pin.framesForwardKinematics(tcb.model, data, q)
        for arm in ("A", "B"):
            X = dm.plant.CalcRelativeTransform(dm.plant_context, dm.plant.world_frame(),
                                               dm.plant.GetFrameByName(tcb.arm(arm).ee_frame))
            M = data.oMf[tcb.arm(arm).ee_frame_id]
            assert np.allclose(X.GetAsMatrix4(), M.homogeneous, atol=1e-12)


def test_collision_pairs_and_distances_match_coal(tcb, transport, dm, rng):
    assert not dm.missing_pairs and not dm.extra_pairs
    assert dm.n_candidate_pairs == dm.n_optplan_pairs == len(CollisionChecker(tcb, transport).pairs)
    chk = CollisionChecker(tcb, transport)
    for _ in range(5):
        q = tcb.random_joints(rng)
        assert dm.min_distance(q) == pytest.approx(chk.min_distance(q)[0], abs=1e-4)


def test_adapter_samples_are_the_bspline(tcb, transport, dm, rng):
    traj, _ = _random_spline(dm, rng)
    sol = BsplineSolution(traj, dm, 6, tcb.joint_names)
    assert np.allclose(sol.t, np.linspace(0.0, 20.0, 7))
    ts = np.sort(rng.uniform(0.0, 20.0, 25))
    s = sol.sample(ts)
    for key, k in (("q", 0), ("qd", 1), ("qdd", 2)):
        d = traj if k == 0 else traj.MakeDerivative(k)
        ref = np.array([d.value(t).ravel() for t in ts])
        assert np.allclose(s[key], dm.from_drake(ref), rtol=0, atol=1e-12)
    with pytest.raises(ValueError, match="times must be in"):
        sol.sample([21.0])
    rep = verify(tcb, sol, transport)
    assert rep.n_samples == 61 and np.isfinite(rep.min_clearance_m)


def test_jerk_cost_written_for_drake_matches_the_trajectory(dm, rng):
    traj, P = _random_spline(dm, rng, N=5, T=7.0)
    sol = BsplineSolution(traj, dm, 5)
    M = jerk_matrix(5)
    quad = float(np.sum((P @ M.T) ** 2) / 5 / 7.0**5)     # the quadratic cost solve_drake adds
    assert quad == pytest.approx(sol.jerk_cost(), rel=1e-9)
    assert DB.jerk_cost(sol) == pytest.approx(sol.jerk_cost(), rel=1e-6)  # from sampled accelerations


def test_fit_bspline_interpolates_the_knots_at_rest(dm, rng):
    from pydrake.trajectories import BsplineTrajectory

    Q = rng.uniform(-1, 1, (8, dm.plant.num_positions()))
    P = fit_bspline(Q, 12.0)
    tr = BsplineTrajectory(_basis(7, 12.0), [P[:, [i]] for i in range(10)])
    vals = np.array([tr.value(t).ravel() for t in np.linspace(0, 12.0, 8)])
    assert np.allclose(vals, Q, atol=1e-10)
    d = tr.MakeDerivative(1)
    assert np.allclose(d.value(0.0), 0.0, atol=1e-10) and np.allclose(d.value(12.0), 0.0, atol=1e-10)


def test_closed_chain_constraint_matches_optplan_closed_chain(tcb, transport, dm, rng):
    from pydrake.autodiffutils import ExtractGradient, ExtractValue, InitializeAutoDiff

    cc = DB._closed_chain(transport)
    ccr = ClosedChainResidual(dm, cc)
    z = np.zeros((1, tcb.nj))
    for _ in range(6):
        q = tcb.random_joints(rng)
        traj = NumericTrajectory(tcb, q[None, :], z, z, np.zeros((0, tcb.nj)), 1.0)
        ref = cc.numeric(traj)                                   # Pinocchio, optplan's term
        r, J = ccr.value_and_jacobian(dm.to_drake(q))
        assert np.allclose(r, ref, atol=1e-12)
        assert np.allclose(ccr(dm.to_drake(q)), ref, atol=1e-12)
        eps = 1e-6
        Jfd = np.column_stack([(ccr(dm.to_drake(q) + eps * e) - ccr(dm.to_drake(q) - eps * e)) / (2 * eps)
                               for e in np.eye(tcb.nj)])
        assert np.allclose(J, Jfd, atol=1e-7)
        G = rng.standard_normal((tcb.nj, 3))                    # autodiff path: r and J @ G
        out = ccr(InitializeAutoDiff(dm.to_drake(q), G).ravel())
        assert np.allclose(ExtractValue(out).ravel(), r) and np.allclose(ExtractGradient(out), J @ G)
    # a configuration on the manifold has zero residual and trace 3
    from optplan.tasks import grasp_configuration

    g = grasp_configuration(tcb, transport, transport.start, np.random.default_rng(0))
    r, _ = ccr.value_and_jacobian(dm.to_drake(g.q))
    assert np.abs(r[:6]).max() < 1e-8 and r[6] == pytest.approx(3.0)


@pytest.mark.parametrize("solver", ["snopt", "ipopt"])
def test_tiny_solve_returns_a_status(tcb, transport, dm, solver):
    from optplan.tasks import transport_initial_path

    Q = transport_initial_path(tcb, transport, 6, np.random.default_rng(0))  # 3 free control points
    r = solve_drake(dm, Q, 60.0, closed_chain=DB._closed_chain(transport), margin=0.02,
                    options=DrakeOptions(solver=solver, max_iterations=3, time_limit=30.0))
    assert r.solver == solver and r.status.lower().startswith(solver) and isinstance(r.success, bool)
    assert r.n_variables == tcb.nj * 9 + 1 and r.iterations >= 0
    s = r.solution.sample([0.0, 30.0, 60.0])["q"]   # 3 iterations: a status and a trajectory, not an optimum
    assert s.shape == (3, tcb.nj) and np.all(np.isfinite(s))


@pytest.mark.parametrize("solver", ["snopt", "ipopt"])
def test_time_limit_ends_in_a_status_with_the_last_point(tcb, transport, dm, solver):
    from optplan.tasks import transport_initial_path

    Q = transport_initial_path(tcb, transport, 6, np.random.default_rng(0))
    r = solve_drake(dm, Q, 60.0, closed_chain=DB._closed_chain(transport),
                    options=DrakeOptions(solver=solver, time_limit=1e-4))
    assert not r.success and "time limit" in r.status and r.solution is not None
    assert np.all(np.isfinite(r.solution.sample([0.0, 60.0])["q"]))


def test_isolated_solve_returns_the_trajectory_or_a_killed_status(tcb, transport, monkeypatch):
    """In a child process: the trajectory comes back (same as in-process), and a solve past the
    kernel's CPU limit is a status, not a hang."""
    from optplan.tasks import transport_initial_path

    Q = transport_initial_path(tcb, transport, 6, np.random.default_rng(0))
    p = DB.PeerProblem("tiny", "transport", tcb, transport, Q, 60.0, DB._closed_chain(transport), 0.02, "A")
    o = DB.drake_solve(p, DrakeOptions(max_iterations=3, time_limit=30.0), isolate=True)
    ref = DB.drake_solve(p, DrakeOptions(max_iterations=3, time_limit=30.0))
    assert o.status == ref.status and not o.info["killed"]
    ts = np.linspace(0.0, 60.0, 13)
    assert np.allclose(o.solution.sample(ts)["q"], ref.solution.sample(ts)["q"], atol=1e-12)
    Q = transport_initial_path(tcb, transport, 20, np.random.default_rng(0))
    p = DB.PeerProblem("small", "transport", tcb, transport, Q, 60.0, DB._closed_chain(transport), 0.02, "A")
    monkeypatch.setattr(DB, "KILL_GRACE", -29.0)  # the kernel stops the child after 1 CPU s
    o = DB.drake_solve(p, DrakeOptions(time_limit=30.0), isolate=True)
    assert o.info["killed"] and "killed at the CPU limit" in o.status and o.solution is None
    row = DB.evaluate(p, o)
    assert not row["passed"] and "small" in DB.format_report([row])


def test_bench_takes_any_optplan_solver_and_rejects_bad_names(tcb, transport, dm):
    from optplan.tasks import transport_initial_path

    Q = transport_initial_path(tcb, transport, 4, np.random.default_rng(0))
    prob = DB.PeerProblem("tiny", "transport", tcb, transport, Q, 60.0, DB._closed_chain(transport), 0.02, "A")

    def warm_start_only(p):  # a stand-in optimizer: returns its warm start unchanged
        from pydrake.trajectories import BsplineTrajectory

        P = fit_bspline(dm.to_drake(p.q_knots), p.duration)
        tr = BsplineTrajectory(_basis(p.n_intervals, p.duration), [P[:, [i]] for i in range(P.shape[1])])
        return DB.PeerOutcome("optplan", "none", False, "not_solved", 0.0, 0.0, 0, BsplineSolution(tr, dm, p.n_intervals))

    row = DB.evaluate(prob, warm_start_only(prob))
    assert row["max_closed_chain_residual"] > 1e-6 and not row["passed"]  # IK knots only: residual between them
    assert "tiny" in DB.format_report([row])
    with pytest.raises(ValueError, match="unknown problem"):
        DB.run(["nowhere"])
    with pytest.raises(ValueError, match="solver"):
        DB.run(["transport"], solvers=["gurobi"])


def _uniform_bspline(P: np.ndarray, T: float, t: np.ndarray) -> np.ndarray:
    """q(t) of optplan's uniform cubic B-spline with control points P ((N+3) × nj) on [0, T]: the
    textbook basis, written independently of optplan.problem.bspline and of Drake."""
    N = P.shape[0] - 3
    out = []
    for ti in t:
        k = min(int(ti / (T / N)), N - 1)
        u = ti / (T / N) - k
        b = np.array([(1 - u) ** 3, 3 * u**3 - 6 * u**2 + 4, -3 * u**3 + 3 * u**2 + 3 * u + 1, u**3]) / 6
        out.append(b @ P[k:k + 4])
    return np.array(out)


def test_drake_warm_start_is_the_spline_nlp_initial_trajectory(tcb, dm, rng):
    """fit_bspline through the B-spline NLP's knot values at rest gives Drake exactly optplan's
    initial trajectory (same C2 cubic space), also between the knots."""
    from pydrake.trajectories import BsplineTrajectory

    from optplan.problem.bspline import boundary_points

    N, T, nj = 9, 13.0, tcb.nj
    q0, q1 = tcb.random_joints(rng), tcb.random_joints(rng)
    z = np.zeros(nj)
    P = np.vstack([boundary_points(q0, z, z, T / N, "start"), rng.uniform(-1, 1, (N - 3, nj)),
                   boundary_points(q1, z, z, T / N, "end")])
    knots = _uniform_bspline(P, T, np.linspace(0, T, N + 1))
    C = fit_bspline(dm.to_drake(knots), T)
    tr = BsplineTrajectory(_basis(N, T), [C[:, [i]] for i in range(N + 3)])
    ts = np.linspace(0, T, 7 * N + 1)
    got = dm.from_drake(np.array([tr.value(t).ravel() for t in ts]))
    assert np.allclose(got, _uniform_bspline(P, T, ts), atol=1e-10)


@pytest.fixture(scope="module")
def scene1_trial1(tcb):
    """The constrained and regrasp segments of scene 1, trial 1 (one plan for both tests)."""
    return DB.pipeline_segment_instances("ssps_scene1", 1, robot=tcb, kinds=("constrained", "regrasp"))


def test_one_pipeline_segment_both_sides_verified_and_reported(tcb, scene1_trial1):
    """A constrained segment of scene 1 (the pipeline's B-spline NLP with its retries vs Drake +
    SNOPT under a short CPU limit): same N, duration and warm start, both rows verified and in the
    report with the ratios and the summary line."""
    probs = [q for q in scene1_trial1 if q.kind == "segment"]
    assert probs, "the planner should solve scene 1 trial 1"
    p = min(probs, key=lambda q: q.n_intervals)
    assert p.kind == "segment" and p.q_knots.shape == (p.n_intervals + 1, tcb.nj)
    assert np.allclose(p.q_knots[0], p.path[0]) and np.allclose(p.q_knots[-1], p.path[-1])
    opt = DB.optplan_current(p)
    assert opt.info["n_intervals_first"] == p.n_intervals            # the pipeline's first attempt
    assert opt.solution.t[-1] == pytest.approx(p.duration)
    dk = DB.drake_solve(p, DrakeOptions(solver="snopt", time_limit=3.0), refinements=2)
    assert dk.solution.duration == pytest.approx(p.duration) and dk.info["n_control_points"] >= p.n_intervals + 3
    rows = [DB.evaluate(p, opt), DB.evaluate(p, dk)]
    for r in rows:
        assert np.isfinite(r["max_closed_chain_residual"]) and np.isfinite(r["min_clearance_m"])
        assert np.isfinite(r["jerk"]) and isinstance(r["passed"], bool)
    assert rows[0]["passed"], rows[0]
    if not dk.success:
        assert not rows[1]["passed"]
    rep = DB.format_report(rows)
    assert p.name in rep and "summary drake-snopt: optplan passed 1/1 runs" in rep


def test_regrasp_instance_fixes_the_holding_arm(tcb, scene1_trial1):
    probs = [q for q in scene1_trial1 if q.kind == "regrasp"]
    assert probs and all(p.closed_chain is None and p.arm is not None for p in probs)
    p = probs[0]
    fixed = np.flatnonzero(p.lower == p.upper)
    assert set(fixed) == set(tcb.arm(p.object_arm).j_idx) and p.arm != p.object_arm
    assert np.allclose(p.q_knots[:, fixed], p.q_knots[0, fixed], atol=1e-9)
    out = DB.drake_solve(p, DrakeOptions(solver="snopt", time_limit=2.0))
    qs = out.solution.sample(np.linspace(0.0, p.duration, 41))["q"]
    assert np.abs(qs[:, fixed] - p.q_knots[0, fixed]).max() < 1e-9     # Drake keeps the holding arm fixed
    row = DB.evaluate(p, out)
    assert np.isfinite(row["min_clearance_m"]) and row["method"] == "drake-snopt"
    with pytest.raises(ValueError, match="kinds"):
        DB.pipeline_segment_instances("ssps_scene1", 1, robot=tcb, kinds=("flying",))


@pytest.mark.slow
def test_pipeline_segment_paired_run():
    """End to end on one pipeline segment (scene 1, trial 2, the 21-interval one): the instance's
    warm start stays near the closed chain and starts/ends at the segment's ends; both
    methods return verified-or-not rows with the same problem figures."""
    probs = DB.pipeline_segment_instances("ssps_scene1", 2)
    assert probs, "the planner should solve scene 1 trial 2"
    p = min(probs, key=lambda q: q.n_intervals)
    assert np.allclose(p.q_knots[0], p.path[0]) and np.allclose(p.q_knots[-1], p.path[-1])
    z = np.zeros_like(p.q_knots)
    traj = NumericTrajectory(p.robot, p.q_knots, z, z, z[:-1], p.duration)
    r = p.closed_chain.numeric(traj).reshape(-1, 7)
    # set_initial_path projects the resampled path onto the manifold, then re-times it with a cubic
    # spline evaluated at the uniform knots: near the manifold, not on it (measured 3e-4)
    assert np.abs(r[:, :6]).max() < 1e-2
    rows = [DB.evaluate(p, DB.optplan_current(p)), DB.evaluate(p, DB.drake_solve(p, DrakeOptions(time_limit=150),
                                                                                  refinements=2))]
    assert rows[0]["passed"]  # optplan's pipeline on its own segment
    assert rows[1]["method"] == "drake-snopt" and rows[1]["n_intervals"] == p.n_intervals
