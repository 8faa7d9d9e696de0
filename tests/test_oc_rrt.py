"""OC-RRT on PR2 / Baxter from example-robot-data: analytic IK against Pinocchio FK, manifold
membership of every node and edge, the generalised CBiRRT, and (slow) statistical success."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.model.example_robots import example_robots_available

pytestmark = pytest.mark.skipif(not example_robots_available(),
                                reason="example-robot-data not installed (pip install 'optplan[robots]')")


@pytest.fixture(scope="module")
def pr2():
    from optplan.model.example_robots import load_pr2

    return load_pr2()


@pytest.fixture(scope="module")
def baxter():
    from optplan.model.example_robots import load_baxter

    return load_baxter()


def _pin_pose(robot, q, fid):
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    return d.oMf[fid].copy()


def _pose_err(M, R, p):
    return max(float(np.linalg.norm(pin.log3(M.rotation.T @ R))), float(np.linalg.norm(M.translation - p)))


def test_robots_load(pr2, baxter):
    for r in (pr2, baxter):
        assert r.nq == 14 and set(r.arms) == {"left", "right"}
        assert all(a.n == 7 for a in r.arms.values())
        assert len(r.collision_pairs) > 100
    assert pr2.arm("left").joint_names[0] == "l_shoulder_pan_joint"
    assert baxter.arm("right").joint_names[-1] == "right_w2"


@pytest.mark.parametrize("arm", ["left", "right"])
def test_pr2_ik_round_trip_all_branches(pr2, arm):
    """Random joint vectors → Pinocchio pose → analytic IK: every branch reproduces the pose to
    1e-12 (checked with Pinocchio, not the IK's own FK) and the original joints are among them."""
    from optplan.model.ik_analytic import DecoupledArmIK

    ik = DecoupledArmIK(pr2, arm)
    assert ik.spherical
    rng = np.random.default_rng(7)
    fid = ik.arm.ee_frame_id
    worst, n_branches = 0.0, 0
    for _ in range(300):
        q = pr2.random_joints(rng)
        M = _pin_pose(pr2, q, fid)
        qa = ik.arm_joints(q)
        W = ik.wrist(qa[:4], M.rotation)
        assert any(np.abs(w - qa[4:]).max() < 1e-9 for w in W)
        for w in W:
            x = q.copy()
            x[ik.q_idx[4:]] = w
            worst = max(worst, float(np.linalg.norm(pin.log3(_pin_pose(pr2, x, fid).rotation.T @ M.rotation))))
        S = ik.solve(M.rotation, M.translation, qa[0])
        assert any(np.abs(s - qa).max() < 1e-9 for s in S)
        n_branches += len(S)
        for s in S:
            assert np.all(s >= ik.lower - 1e-12) and np.all(s <= ik.upper + 1e-12)
            x = q.copy()
            x[ik.q_idx] = s
            worst = max(worst, _pose_err(_pin_pose(pr2, x, fid), M.rotation, M.translation))
    assert worst <= 1e-12
    assert n_branches > 300        # several branches on average (both wrist rolls ± 2π, elbow/shoulder)


def test_baxter_offset_wrist(baxter):
    """Baxter's wrist axes do not meet (w0-w1 offset 0.01 m): orientation-only wrist IK is still
    exact; full-pose IK = analytic seed + Newton, to 1e-12."""
    from optplan.model.ik_analytic import DecoupledArmIK

    ik = DecoupledArmIK(baxter, "left")
    assert not ik.spherical and ik.wrist_offset > 1e-3
    rng = np.random.default_rng(3)
    fid = ik.arm.ee_frame_id
    found = 0
    for _ in range(25):
        q = baxter.random_joints(rng)
        M = _pin_pose(baxter, q, fid)
        qa = ik.arm_joints(q)
        W = ik.wrist(qa[:4], M.rotation)
        assert any(np.abs(w - qa[4:]).max() < 1e-9 for w in W)
        S = ik.solve(M.rotation, M.translation, qa[0])
        found += any(np.abs(s - qa).max() < 1e-8 for s in S)
        for s in S:
            x = q.copy()
            x[ik.q_idx] = s
            assert _pose_err(_pin_pose(baxter, x, fid), M.rotation, M.translation) <= 1e-12
    assert found >= 23     # the original solution is found (misses only next to a fold of the elbow)


def test_unreachable_and_singular_give_no_solution(pr2):
    from optplan.model.ik_analytic import DecoupledArmIK

    ik = DecoupledArmIK(pr2, "left")
    assert ik.solve(np.eye(3), np.array([3.0, 0.0, 1.0]), 0.0).shape == (0, 7)
    assert ik.solve(np.eye(3), np.array([0.5, 0.2, 1.0]), 10.0).shape == (0, 7)   # q1 outside its limits
    q = np.array([0.2, 0.3, 0.1, -1.0, 0.4, 0.0, 0.3])        # wrist flex 0: forearm and wrist rolls aligned
    R, p = ik.fk(q)
    assert ik.wrist(q[:4], R).shape == (0, 3)
    assert ik.solve(R, p, q[0]).shape == (0, 7)


def _task(robot, scene_name):
    from optplan.planners.orientation import OrientationManifold, constraint_from_scene, endpoints_from_scene
    from optplan.scene import Scene

    sc = Scene.load(scene_name)
    con = constraint_from_scene(robot, sc)
    mf = OrientationManifold(con)
    qs, qg = endpoints_from_scene(mf, sc)
    return sc, con, mf, qs, qg


@pytest.mark.parametrize("scene_name,connect", [("oc_industrial_1", True), ("oc_tabletop", True),
                                                ("oc_industrial_1", False), ("oc_tabletop", False)])
def test_oc_rrt_nodes_and_edges_on_manifold(pr2, scene_name, connect):
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, scene_name)
    pl = OCRRT(pr2, sc, con, OCRRTOptions(connect=connect), manifold=mf)
    res = pl.plan(qs, qg, time_limit=60.0, seed=1)
    assert res.success, res.message
    assert np.array_equal(res.path[0], qs) and np.array_equal(res.path[-1], qg)
    for q in res.path:                                   # every node
        eo, ep = con.errors(q)
        assert eo <= 1e-12 and ep <= 1e-12
    dense = pl.densify(res.path, 0.02)                   # every edge, densely
    E = np.array([con.errors(q) for q in dense])
    assert E.max() <= 1e-12
    assert np.abs(np.diff(dense, axis=0)).max() <= pl.options.max_joint_step
    # collision-free where the planner checks (every collision_step of parameter motion along each
    # edge); between those, discrete checking can miss grazing contacts (measured in docs/oc_rrt.md)
    assert all(pl.checker.is_valid(q) for q in pl.densify(res.path, pl.options.collision_step))
    assert np.all(dense >= pr2.lower - 1e-12) and np.all(dense <= pr2.upper + 1e-12)
    o, p = con.rmsd(dense)
    assert o <= 1e-9 and (np.isnan(p) if con.mode == "open" else p <= 1e-9)


def test_constraint_jacobian_matches_finite_differences(pr2):
    from optplan.planners.orientation import constraint_from_scene
    from optplan.scene import Scene

    con = constraint_from_scene(pr2, Scene.load("oc_tabletop"))
    q = pr2.random_joints(np.random.default_rng(0))
    h, J = con.h_jacobian(q)
    eps = 1e-7
    Jn = np.column_stack([(con.h(q + eps * e) - con.h(q - eps * e)) / (2 * eps) for e in np.eye(14)])
    assert np.abs(J - Jn).max() < 1e-6
    assert np.allclose(h, con.h(q))


def test_cbirrt_generalised_to_orientation_constraint(pr2):
    from optplan.planners.cbirrt2 import CBiRRT2, CBiRRT2Options

    sc, con, mf, qs, qg = _task(pr2, "oc_industrial_1")
    pl = CBiRRT2(pr2, sc, CBiRRT2Options(), constraint=con)
    res = pl.plan(qs, qg, time_limit=60.0, seed=0)
    assert res.success, res.message
    assert max(float(np.abs(con.h(q)).max()) for q in res.path) <= 1e-6


def test_tsr_free_axis_residual(pr2):
    """A free yaw axis: yaw errors are not penalised, pitch errors are."""
    from optplan.geometry.spatial import rpy_to_matrix
    from optplan.planners.orientation import DualArmOrientationConstraint

    b = np.array([[0.0, 0.0], [0.0, 0.0], [-np.inf, np.inf]])
    con = DualArmOrientationConstraint(pr2, "open", {"left": np.eye(3), "right": np.eye(3)}, orientation_bounds=b)
    q = np.zeros(14)
    Rl = con.hand_pose(q, "left").rotation
    Rr = con.hand_pose(q, "right").rotation
    con.R_hands = {"left": rpy_to_matrix(0, 0, 0.3) @ Rl, "right": Rr}
    assert np.abs(con.h(q)).max() < 1e-12
    con.R_hands = {"left": rpy_to_matrix(0, 0.3, 0) @ Rl, "right": Rr}
    assert np.abs(con.h(q)).max() > 0.1


def test_bad_input(pr2):
    from optplan.errors import ConfigurationError
    from optplan.planners.oc_rrt import OCRRTOptions
    from optplan.planners.orientation import DualArmOrientationConstraint

    with pytest.raises(ValueError, match="step"):
        OCRRTOptions(step=-1.0)
    with pytest.raises(ValueError, match="goal_from_new"):
        OCRRTOptions(goal_from_new="yes")
    for bad in (dict(variant="fast"), dict(refine_depth=-1), dict(goal_region_bias=1.5), dict(bridge_sigma=0.0),
                dict(goal_turn_joints="l_wrist_roll_joint"), dict(extend_to_sample=1)):
        with pytest.raises(ValueError, match=next(iter(bad))):
            OCRRTOptions(**bad)
    with pytest.raises(ConfigurationError, match="mode"):
        DualArmOrientationConstraint(pr2, "sideways", {})
    with pytest.raises(ConfigurationError, match="R_hands"):
        DualArmOrientationConstraint(pr2, "open", {"left": np.eye(3)})


def test_paper_variant_ignores_the_improvements(pr2):
    """variant="paper" is Algorithm 2 whatever else is set: same tree node for node."""
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, "oc_industrial_2")
    a = OCRRTOptions.paper(max_iterations=150)
    b = OCRRTOptions(connect=False, variant="paper", max_iterations=150, refine_depth=5, goal_region_bias=0.9,
                     extend_to_sample=True, bridge_bias=0.5)
    assert a.variant == "paper" and not a.connect and not a.goal_from_new
    ra, rb = (OCRRT(pr2, sc, con, o, manifold=mf).plan(qs, qg, time_limit=60, seed=3) for o in (a, b))
    assert ra.stats["nodes"] == rb.stats["nodes"] and ra.stats["refinements"] == rb.stats["refinements"] == 0
    assert ra.status == rb.status


def test_refinement_passes_fast_motion_but_not_branch_jumps(pr2):
    """Bisection accepts a continuous motion whose joint step exceeds the bound at the coarse
    step (every bisected step within the bound), and rejects a jump that does not shrink with
    the parameter step (another branch)."""
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, "oc_tabletop")
    pl = OCRRT(pr2, sc, con, OCRRTOptions(connect=False, max_joint_step=0.02), manifold=mf)
    st = {k: 0 for k in ("ik_rejects", "jump_rejects", "refinements", "collisions")}
    ps, pg = mf.params(qs), mf.params(qg)
    pm = ps + (0.05 / np.abs(pg - ps).max()) * (pg - ps)      # 0.05 rad of parameter motion
    assert np.abs(mf.complete(pm, ref=qs) - qs).max() > 0.02   # too far for one step
    assert pl._advance(qs, ps, pm, 0, False, st) is None and st["jump_rejects"] == 1
    trace = []
    x = pl._advance(qs, ps, pm, 6, False, st, trace)
    assert x is not None and st["refinements"] > 0 and trace
    seq = [qs, *trace, x]
    assert max(float(np.abs(b - a).max()) for a, b in zip(seq[:-1], seq[1:])) <= 0.02
    assert np.abs(x - mf.complete(pm, ref=qs)).max() < 1e-12
    far = qs.copy()
    far[pr2.joint_names.index("l_wrist_flex_joint")] += 0.5   # no branch near: the jump stays
    st["jump_rejects"] = 0
    assert pl._advance(far, ps, ps, 6, False, st) is None and st["jump_rejects"] > 0


def test_goal_turn_equivalents(pr2):
    from optplan.errors import ConfigurationError
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, "oc_passageway")
    names = ("l_forearm_roll_joint", "r_wrist_roll_joint")
    pl = OCRRT(pr2, sc, con, OCRRTOptions(connect=False, goal_turn_joints=names), manifold=mf)
    j = [pr2.joint_names.index(n) for n in names]
    q = qg.copy()
    q[j[0]] += 2 * np.pi
    q[j[1]] -= 2 * np.pi
    assert list(pl._turns(q, qg)) == [1, -1]
    assert pl._turns(q + 1e-6, qg) is None
    q2 = qg.copy()
    q2[pr2.joint_names.index("l_wrist_roll_joint")] += 2 * np.pi          # not a declared turn joint
    assert pl._turns(q2, qg) is None
    with pytest.raises(ConfigurationError, match="goal_turn_joints"):
        OCRRT(pr2, sc, con, OCRRTOptions(goal_turn_joints=("no_such_joint",)), manifold=mf)


@pytest.mark.slow
def test_single_tree_oc_rrt_success_on_the_narrow_passageway(pr2):
    """The single-tree OC-RRT (default improvements) on the closed-chain scene where the paper's
    Algorithm 2 succeeds half of the time: >= 9 of 10 seeded queries within 10 s CPU."""
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, "oc_passageway")
    pl = OCRRT(pr2, sc, con, OCRRTOptions(connect=False), manifold=mf)
    ok = sum(pl.plan(qs, qg, time_limit=10.0, seed=100 + s, clock="cpu").success for s in range(10))
    assert ok >= 9


@pytest.mark.slow
@pytest.mark.parametrize("scene_name", ["oc_industrial_1", "oc_tabletop"])   # open chain, closed chain
def test_oc_rrt_connect_success_rate(pr2, scene_name):
    from optplan.planners.oc_rrt import OCRRT, OCRRTOptions

    sc, con, mf, qs, qg = _task(pr2, scene_name)
    pl = OCRRT(pr2, sc, con, OCRRTOptions(connect=True), manifold=mf)
    ok = sum(pl.plan(qs, qg, time_limit=20.0, seed=s, clock="cpu").success for s in range(10))
    assert ok >= 9


@pytest.mark.parametrize("scene_name", ["oc_industrial_1", "oc_industrial_2"])
def test_compiled_completion_matches_python_ik(pr2, scene_name):
    """The compiled branch kernel (CasADi → C) returns what the Python IK returns: random branch
    choice with the same generator, nearest branch to a reference; always on the manifold."""
    from optplan.planners.orientation import OrientationManifold

    sc, con, mf, qs, qg = _task(pr2, scene_name)
    assert mf.kernel is not None
    ref_mf = OrientationManifold(con, compiled=False)
    rng = np.random.default_rng(3)
    n_solved = n_steps = 0
    for i in range(400):
        p = rng.uniform(mf.lower, mf.upper)
        a = mf.complete(p, rng=np.random.default_rng(i))
        b = ref_mf.complete(p, rng=np.random.default_rng(i))
        assert (a is None) == (b is None)
        if a is None:
            continue
        n_solved += 1
        assert np.abs(a - b).max() <= 1e-11
        p2 = np.clip(p + rng.uniform(-0.05, 0.05, mf.dim), mf.lower, mf.upper)
        a2, b2 = mf.complete(p2, ref=a), ref_mf.complete(p2, ref=a)
        assert (a2 is None) == (b2 is None)
        if a2 is None:
            continue
        n_steps += 1
        # both are nearest in max-norm; they may differ by 2π only when the max is a forced jump
        if np.abs(b2 - a).max() < 1.0:
            assert np.abs(a2 - b2).max() <= 1e-11
        assert np.abs(a2 - a).max() <= np.abs(b2 - a).max() + 1e-12
        eo, ep = con.errors(a2)
        assert eo <= 1e-12 and ep <= 1e-12
    assert n_solved > 40 and n_steps > 30


@pytest.mark.parametrize("robot_name", ["pr2", "baxter"])
def test_wrist_ik_accurate_next_to_the_singular_wrist(robot_name, request):
    """Wrist roll axes nearly aligned (|q6| of 1e-4 .. 1e-3 rad): the closed form keeps 1e-12
    against Pinocchio (an acos of a ratio near 1 would lose ~1e-16 / |q6|)."""
    from optplan.model.ik_analytic import DecoupledArmIK

    robot = request.getfixturevalue(robot_name)
    rng = np.random.default_rng(11)
    worst = 0.0
    for arm in ("left", "right"):
        ik = DecoupledArmIK(robot, arm)
        fid = ik.arm.ee_frame_id
        for q6 in (2e-4, -3e-4, 1e-3, -1e-3):
            for _ in range(10):
                q = robot.random_joints(rng)
                q[ik.q_idx[5]] = q6 if robot.lower[ik.q_idx[5]] <= q6 <= robot.upper[ik.q_idx[5]] else -q6
                R = _pin_pose(robot, q, fid).rotation
                W = ik.wrist(ik.arm_joints(q)[:4], R)
                # q5 and q7 separately are ill-conditioned here (only their sum is well defined as
                # q6 → 0): the original is found to 1e-6 rad, the pose itself to 1e-12
                assert any(np.abs(w - ik.arm_joints(q)[4:]).max() < 1e-6 for w in W)
                for w in W:
                    x = q.copy()
                    x[ik.q_idx[4:]] = w
                    worst = max(worst, float(np.linalg.norm(pin.log3(_pin_pose(robot, x, fid).rotation.T @ R))))
    assert worst <= 1e-12, worst


def test_completion_without_a_c_compiler(pr2, monkeypatch):
    """No C compiler: the same kernel runs as an interpreted casadi.Function, same results."""
    import optplan.planners.orientation as ori

    sc, con, mf, qs, qg = _task(pr2, "oc_tabletop")
    monkeypatch.setattr(ori, "compile_function", lambda f: f)
    slow = ori.OrientationManifold(con)
    assert not slow.kernel[0].compiled and not slow.kernel[1].compiled
    rng = np.random.default_rng(5)
    for i in range(50):
        p = rng.uniform(mf.lower, mf.upper)
        a, b = slow.complete(p, rng=np.random.default_rng(i)), mf.complete(p, rng=np.random.default_rng(i))
        assert (a is None) == (b is None) and (a is None or np.abs(a - b).max() <= 1e-12)
    p = mf.params(qs) + 0.01
    assert np.abs(slow.complete(p, ref=qs) - mf.complete(p, ref=qs)).max() <= 1e-12


def test_kernel_with_a_sparse_output_falls_back_to_the_interpreted_function():
    """A compiled completion kernel whose output is structurally sparse is called through the
    interpreted casadi.Function (same values), not the dense buffers."""
    import casadi as ca

    from optplan.codegen import CompiledFunction, compile_function
    from optplan.planners.orientation import _Kernel

    x = ca.SX.sym("x", 2)
    out = ca.SX(2, 1)  # its 2nd entry is a structural zero
    out[0] = 2 * x[0]
    f = ca.Function("sparse_out_kernel", [x], [out, x[1] ** 2])
    cf = compile_function(f)
    if not isinstance(cf, CompiledFunction):
        pytest.skip("no C compiler")
    k = _Kernel(cf)
    assert not k.compiled
    a, b = k(np.array([1.5, -2.0]))
    np.testing.assert_allclose(a, [3.0, 0.0])
    np.testing.assert_allclose(b, 4.0)


def test_branch_choice_matches_enumeration():
    """The random IK-branch choice (counting shifts, one draw) picks the same solution as drawing
    one index into the explicit list of every in-limit 2πk shift of every branch (branch order,
    then shifts, the last joint fastest), duplicates modulo 2π counted once."""
    import itertools
    import math

    from optplan.planners.orientation import _choose

    g = np.random.default_rng(3)
    tol, checked = 1e-12, 0
    for _ in range(400):
        rows, cols = int(g.choice([2, 8])), int(g.choice([3, 6]))
        X = g.uniform(-7, 7, (rows, cols))
        if g.random() < 0.3:
            X[1] = X[0] + 2 * math.pi * g.integers(-1, 2, cols)
        ok = (g.random(rows) < 0.7).astype(float)
        hi = g.choice([1.0, 2.3, math.pi, 2 * math.pi], cols)
        lo = -g.choice([1.0, 2.3, math.pi, 2 * math.pi], cols)
        dedup = bool(g.random() < 0.5)
        sols, kept = [], []
        for r in range(rows):
            if ok[r] < 0.5 or (dedup and any(np.allclose((X[r] - X[k] + math.pi) % (2 * math.pi) - math.pi, 0, atol=1e-9)
                                             for k in kept)):
                continue
            kept.append(r)
            shifts = [[x + 2 * math.pi * k for k in range(-4, 5) if lo[c] - tol <= x + 2 * math.pi * k <= hi[c] + tol]
                      for c, x in enumerate(X[r])]
            sols += [(r, np.clip(y, lo, hi)) for y in itertools.product(*shifts)]
        seed = int(g.integers(2**31))
        row, y = _choose(X, ok, lo, hi, np.random.default_rng(seed), dedup=dedup)
        if not sols:
            assert row == -1 and y is None
            continue
        r_ref, y_ref = sols[int(np.random.default_rng(seed).integers(len(sols)))]
        assert row == r_ref and np.allclose(y, y_ref, atol=1e-12, rtol=0)
        checked += 1
    assert checked > 200


def test_example_writes_nothing_unless_asked(tmp_path, monkeypatch, capsys):
    """``examples/oc_rrt.py`` without ``--out`` leaves the current directory as it was (its
    resumable results go to a temporary folder); with ``--out DIR`` they are in DIR."""
    import runpy
    import sys
    from pathlib import Path

    example = Path(__file__).resolve().parents[1] / "examples" / "oc_rrt.py"
    cwd = tmp_path / "cwd"
    cwd.mkdir()
    monkeypatch.chdir(cwd)
    argv = [str(example), "--trials", "1", "--time-limit", "1", "--scenes", "oc_tabletop", "--planners",
            "oc_rrt_connect", "--no-progress"]
    for extra in ([], ["--out", str(tmp_path / "kept")]):
        monkeypatch.setattr(sys, "argv", argv + extra)
        with pytest.raises(SystemExit) as exc:
            runpy.run_path(str(example), run_name="__main__")
        assert exc.value.code == 0
    assert list(cwd.iterdir()) == []
    assert (tmp_path / "kept" / "results.jsonl").is_file()
    assert "oc_tabletop" in capsys.readouterr().out
