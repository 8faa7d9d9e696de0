"""Planners of issue 4: TCBiRRT (the TCBiRRT paper Alg. 1-4 + regrasp), RRTConnect, CBiRRT2, OMPL peers,
the SSPS scenes and trial generation, and the benchmark runner.

Every closed-chain check is independent of the planners: Pinocchio FK of both hands
(``closure_error``) and exact coal distances (``optplan.collision.checker.CollisionChecker``).
"""
from __future__ import annotations

import dataclasses
import json
import math

import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.constraints.closed_chain import ClosedChainKinematics, IKSettings, closure_error
from optplan.geometry.spatial import rpy_to_matrix
from optplan.planners import (
    CBiRRT2,
    CBiRRT2Options,
    PlanResult,
    PlanStatus,
    RRTConnect,
    RRTConnectOptions,
    TCBiRRT,
    TCBiRRTOptions,
    ValidityChecker,
    make_planner,
)
from optplan.planners.tcbirrt import exp_coordinates, interpolate_task, pose_from_xi, rotation_from_exp, xi_from_pose
from optplan.scene import Scene
from optplan.trials import TrialGenerator, TrialOptions, perturb_pose, trial_seed

IK_TOL = 1e-6   # closed-chain tolerance every returned configuration must meet (position m, angle rad)


# ---------------------------------------------------------------------- fixtures
@pytest.fixture(scope="session")
def scene1() -> Scene:
    return Scene.load("ssps_scene1")


@pytest.fixture(scope="session")
def kin(tcb, scene1) -> ClosedChainKinematics:
    return ClosedChainKinematics(tcb, scene1.object.grasps)


@pytest.fixture(scope="session")
def checker(tcb, scene1) -> ValidityChecker:
    return ValidityChecker(tcb, scene1)


@pytest.fixture(scope="session")
def gen(tcb, scene1, kin) -> TrialGenerator:
    return TrialGenerator(tcb, scene1)


@pytest.fixture(scope="session")
def trials(gen):
    return [gen.generate(i, 0) for i in range(3)]


@pytest.fixture(scope="session")
def tcbirrt(tcb, scene1, checker, kin) -> TCBiRRT:
    return TCBiRRT(tcb, scene1, checker=checker, kinematics=kin)


@pytest.fixture(scope="session")
def tcb_result(tcbirrt, trials):
    t = trials[0]
    return tcbirrt.plan(t.q_start, t.q_goal, time_limit=20.0, seed=t.seed)


def _random_rotation(rng) -> np.ndarray:
    q = rng.normal(size=4)
    q /= np.linalg.norm(q)
    return pin.Quaternion(q[3], q[0], q[1], q[2]).toRotationMatrix()


def _angle(R) -> float:
    return float(np.linalg.norm(pin.log3(R)))


# ---------------------------------------------------------------------- task space (Eq. 3-4, Appendix)
def test_exp_coordinates_round_trip_random(rng):
    for _ in range(200):
        R = _random_rotation(rng)
        w = exp_coordinates(R)
        assert np.linalg.norm(w) <= math.pi + 1e-12
        assert np.allclose(rotation_from_exp(w), R, atol=1e-12)
        assert np.allclose(w, pin.log3(R), atol=1e-9)


@pytest.mark.parametrize("eps", [0.0, 1e-12, 1e-9, 1e-6, 1e-3, 0.1])
@pytest.mark.parametrize("axis", [(1, 0, 0), (0, 1, 0), (0, 0, 1), (0.3, -0.5, 0.8), (-1, 1, 1e-7)])
def test_exp_coordinates_near_pi(axis, eps):
    """Angles at and near π about any axis, including axes ⊥ x, where the Appendix's Eq. 13
    (division by 1 + r11) breaks."""
    u = np.asarray(axis, float) / np.linalg.norm(axis)
    w_true = (math.pi - eps) * u
    R = rotation_from_exp(w_true)
    w = exp_coordinates(R)
    assert np.allclose(rotation_from_exp(w), R, atol=1e-10)
    assert abs(np.linalg.norm(w) - (math.pi - eps)) < 1e-8
    if eps > 1e-6:   # away from exactly π the sign is determined
        assert np.allclose(w, w_true, atol=1e-7)


def test_exp_coordinates_zero_and_small():
    assert np.allclose(exp_coordinates(np.eye(3)), 0.0)
    w = np.array([1e-9, -2e-9, 3e-9])
    assert np.allclose(exp_coordinates(rotation_from_exp(w)), w, atol=1e-15)


def test_interpolate_task_endpoints_and_linearity(rng):
    for mode in ("geodesic", "absolute"):
        for _ in range(20):
            R0, R1 = _random_rotation(rng), _random_rotation(rng)
            p0, p1 = rng.normal(size=3), rng.normal(size=3)
            poses = interpolate_task(R0, p0, R1, p1, 5, mode)
            assert len(poses) == 5
            assert np.allclose(poses[-1][0], R1) and np.allclose(poses[-1][1], p1)
            for j, (R, p) in enumerate(poses, 1):
                assert np.allclose(p, p0 + j / 5 * (p1 - p0))          # Eq. 4, position
                assert np.allclose(R.T @ R, np.eye(3), atol=1e-12)
    # geodesic: equal angular steps (exponential coordinates of the relative rotation, Eq. 4)
    R0, R1 = _random_rotation(rng), _random_rotation(rng)
    poses = interpolate_task(R0, np.zeros(3), R1, np.zeros(3), 5)
    Rs = [R0] + [R for R, _ in poses]
    steps = [_angle(a.T @ b) for a, b in zip(Rs[:-1], Rs[1:])]
    assert np.allclose(steps, _angle(R0.T @ R1) / 5, atol=1e-10)


def test_interpolate_task_coaxial_modes_agree():
    """For rotations about one axis, the literal Eq. 4 (absolute exponential coordinates) and the
    geodesic form are the same path."""
    u = np.array([0.2, 0.9, -0.4]) / np.linalg.norm([0.2, 0.9, -0.4])
    R0, R1 = rotation_from_exp(0.3 * u), rotation_from_exp(1.7 * u)
    a = interpolate_task(R0, np.zeros(3), R1, np.ones(3), 7, "geodesic")
    b = interpolate_task(R0, np.zeros(3), R1, np.ones(3), 7, "absolute")
    for (Ra, _), (Rb, _) in zip(a, b):
        assert np.allclose(Ra, Rb, atol=1e-12)


@pytest.mark.parametrize("mode", ["geodesic", "absolute"])
def test_interpolate_task_across_pi_is_continuous(mode):
    """Two rotations on either side of |φ| = π (3.1 and 3.2 rad about z, i.e. 0.1 rad apart): no
    intermediate pose may swing around (the naive absolute-coordinate interpolation does)."""
    z = np.array([0.0, 0.0, 1.0])
    R0, R1 = rotation_from_exp(3.1 * z), rotation_from_exp(3.2 * z)
    poses = interpolate_task(R0, np.zeros(3), R1, np.zeros(3), 5, mode)
    Rs = [R0] + [R for R, _ in poses]
    for a, b in zip(Rs[:-1], Rs[1:]):
        assert _angle(a.T @ b) < 0.1 / 5 + 1e-9


def test_xi_round_trip(rng):
    for _ in range(50):
        M = pin.SE3(_random_rotation(rng), rng.normal(size=3))
        R, p = pose_from_xi(xi_from_pose(M))
        assert np.allclose(R, M.rotation, atol=1e-12) and np.allclose(p, M.translation)


# ---------------------------------------------------------------------- kinematics and validity
def test_compiled_ik_matches_reference_and_closes_chain(tcb, scene1, kin, rng):
    s = IKSettings(max_iterations=200, max_step=0.3, damping=0.02)
    M = scene1.start
    found = 0
    for _ in range(25):
        q0 = tcb.random_configuration(rng)
        a, ia = kin.ik(q0, M.rotation, M.translation, s)
        b, ib = kin.ik_reference(q0, M.rotation, M.translation, s)
        assert (a is None) == (b is None) and ia == ib
        if a is not None:
            found += 1
            assert np.allclose(a, b, atol=1e-9)
            assert max(closure_error(tcb, scene1.object.grasps, a)) < IK_TOL
            assert np.all(a >= tcb.lower) and np.all(a <= tcb.upper)
            assert np.all(kin.hand_errors(a, M.rotation, M.translation)[[0, 2]] < s.tol_position)
    assert found >= 3


def test_constraint_jacobian_matches_finite_differences(tcb, kin, trials):
    q = trials[0].q_start
    h, J = kin.h_jacobian(q)
    assert np.abs(h).max() < IK_TOL
    eps = 1e-6
    Jn = np.column_stack([(kin.h(q + eps * e) - kin.h(q - eps * e)) / (2 * eps) for e in np.eye(tcb.nq)])
    assert np.allclose(J, Jn, atol=1e-6)


def test_validity_checker_agrees_with_collision_checker(tcb, scene1, checker, rng):
    exact = CollisionChecker(tcb, scene1)
    free = CollisionChecker(tcb, scene1, held_object=False)
    qs = [tcb.random_configuration(rng) for _ in range(300)]
    assert [checker.is_valid(q) for q in qs] == [exact.is_valid(q) for q in qs]
    assert [checker.is_valid_free(q) for q in qs] == [free.is_valid(q) for q in qs]
    plain = ValidityChecker(tcb, scene1, broadphase=False)
    poses = [exact.object_pose(tcb.random_configuration(rng)) for _ in qs]
    assert [checker.is_valid_object_fixed(q, M) for q, M in zip(qs, poses)] == \
           [plain.is_valid_object_fixed(q, M) for q, M in zip(qs, poses)]


# ---------------------------------------------------------------------- trials (Section 5.1)
def test_trials_are_perturbed_valid_and_deterministic(tcb, scene1, gen, trials):
    for t in trials:
        for M, nominal, q in ((t.object_start, scene1.start, t.q_start), (t.object_goal, scene1.goal, t.q_goal)):
            d = nominal.actInv(M)                     # T = T_nominal T_e
            assert np.all(np.abs(d.translation) <= 0.2 + 1e-12)
            assert np.all(np.abs(pin.rpy.matrixToRpy(d.rotation)) <= 0.5 + 1e-9)
            assert max(closure_error(tcb, scene1.object.grasps, q)) < IK_TOL
            assert CollisionChecker(tcb, scene1).min_distance(q)[0] >= TrialOptions().min_clearance - 1e-9
            assert np.allclose(ClosedChainKinematics(tcb, scene1.object.grasps).object_pose(q).homogeneous,
                               M.homogeneous, atol=1e-6)
    again = gen.generate(2, 0)                        # a trial alone == the same trial in sequence
    assert np.array_equal(again.q_start, trials[2].q_start) and again.seed == trials[2].seed
    assert trial_seed(0, 1).generate_state(1)[0] != trial_seed(0, 2).generate_state(1)[0]


def test_perturb_pose_ranges(rng):
    M0 = pin.SE3(rpy_to_matrix(0.1, -0.2, 1.5), np.array([1.0, 2.0, 3.0]))
    for _ in range(200):
        d = M0.actInv(perturb_pose(M0, rng))
        assert np.all(np.abs(d.translation) <= 0.2) and np.all(np.abs(pin.rpy.matrixToRpy(d.rotation)) <= 0.5 + 1e-12)


@pytest.mark.parametrize("name", ["ssps_scene1", "ssps_scene2", "ssps_scene3"])
def test_scene_nominal_configurations(tcb, name):
    """The scenes' nominal configurations hold the object at the nominal poses with clearance
    (exact coal), joints well inside the limits; clutter grows from scene 1 to 3."""
    sc = Scene.load(name)
    cc = CollisionChecker(tcb, sc)
    for key in ("q_start", "q_goal"):
        q = np.radians(sc.extra[key])
        assert max(closure_error(tcb, sc.object.grasps, q)) < 1e-6
        assert cc.min_distance(q)[0] > 0.1
        assert np.all(q > tcb.lower + 0.9) and np.all(q < tcb.upper - 0.9)
    n = {k: len(Scene.load(f"ssps_scene{k}").obstacles) for k in (1, 2, 3)}
    assert n[1] < n[2] < n[3]


@pytest.mark.slow
@pytest.mark.parametrize("name", ["ssps_scene1", "ssps_scene2", "ssps_scene3"])
def test_scene_nominal_poses_grasp_configuration(tcb, name):
    """optplan.tasks.grasp_configuration finds a grasp with 0.05 m clearance at both nominal poses."""
    from optplan.tasks import grasp_configuration

    sc = Scene.load(name)
    cc = CollisionChecker(tcb, sc)
    for M in (sc.start, sc.goal):
        assert grasp_configuration(tcb, sc, M, np.random.default_rng(0), min_clearance=0.05, tries=300, checker=cc).found


# ---------------------------------------------------------------------- TCBiRRT
def test_tcbirrt_path_closed_chain_continuity_collision(tcb, scene1, tcbirrt, tcb_result, trials):
    res, t = tcb_result, trials[0]
    assert res.status is PlanStatus.EXACT, res.message
    P = res.path
    assert P.shape[1] == tcb.nq and len(P) == len(res.object_poses) == len(res.constrained)
    assert np.array_equal(P[0], t.q_start) and np.array_equal(P[-1], t.q_goal)
    assert res.stats["time_s"] > 0 and res.stats["nodes"] >= 2 and res.stats["seed"] == t.seed
    exact = CollisionChecker(tcb, scene1)
    data = tcb.model.createData()
    grasp_a_inv = scene1.object.grasps["A"].inverse()
    for q, M, c in zip(P, res.object_poses, res.constrained):
        assert np.all(q >= tcb.lower - 1e-12) and np.all(q <= tcb.upper + 1e-12)
        if c:   # closed chain, object where the planner says, collision-free (exact coal)
            assert max(closure_error(tcb, scene1.object.grasps, q, data)) <= IK_TOL
            pin.framesForwardKinematics(tcb.model, data, q)
            Mo = data.oMf[tcb.arm("A").ee_frame_id] * grasp_a_inv
            assert np.allclose(Mo.homogeneous, M.homogeneous, atol=1e-6)
            assert exact.is_valid(q)
    # path IK continuity inside constrained segments (Alg. 3 seeded by the previous waypoint)
    for s in res.segments:
        if s.kind == "constrained":
            steps = np.abs(np.diff(P[s.start:s.stop + 1], axis=0)).max(axis=1)
            assert steps.max() <= tcbirrt.options.max_joint_step + 1e-12
            # consecutive object poses are at most one interpolation step apart (s_ξ / N in ξ)
            for a, b in zip(res.object_poses[s.start:s.stop], res.object_poses[s.start + 1:s.stop + 1]):
                assert np.linalg.norm(b.translation - a.translation) <= tcbirrt.options.step_size / 5 + 1e-9
    # segments tile the path
    assert res.segments[0].start == 0 and res.segments[-1].stop == len(P) - 1
    for a, b in zip(res.segments[:-1], res.segments[1:]):
        assert a.stop == b.start


def test_tcbirrt_regrasp_segments(tcb, scene1, checker, tcb_result):
    """Regrasp: the object stays at one pose, one arm moves at a time, both hands are on the
    object at the segment ends, and the straight joint-space edges are collision-free with the
    object fixed."""
    from optplan.planners.rrtconnect import edge_is_valid

    res = tcb_result
    assert res.n_regrasp == res.stats["n_regrasp"]
    for s in res.segments:
        if s.kind != "regrasp":
            continue
        moving = tcb.arm(s.arm).q_idx
        still = np.setdiff1d(np.arange(tcb.nq), moving)
        seg = res.path[s.start:s.stop + 1]
        assert np.allclose(seg[:, still], seg[0, still])
        assert res.constrained[s.start] and res.constrained[s.stop]
        assert not np.any(res.constrained[s.start + 1:s.stop])
        for k in (s.start, s.stop):
            assert max(closure_error(tcb, scene1.object.grasps, res.path[k])) <= IK_TOL
        for M in res.object_poses[s.start:s.stop + 1]:
            assert np.allclose(M.homogeneous, s.object_pose.homogeneous)
        for a, b in zip(seg[:-1], seg[1:]):
            assert edge_is_valid(a, b, lambda x, s=s: checker.is_valid_object_fixed(x, s.object_pose), 0.03)


def test_tcbirrt_forced_regrasp(tcb, scene1, tcbirrt, kin, gen, rng):
    """Start and goal hold the object at the SAME pose with far-apart IK solutions: the trees
    must be joined by a regrasp."""
    M = scene1.start
    qa = gen.q_nominal["q_start"]
    qb = None
    for _ in range(200):
        q, _ = kin.ik(gen.random_seed(rng), M.rotation, M.translation, gen.ik_restart)
        if q is not None:
            q, _ = kin.ik(q, M.rotation, M.translation, tcbirrt.options.ik)
        if q is not None and tcbirrt.check_endpoint(q) is None and np.abs(q - qa).max() > 0.5:
            qb = q
            break
    assert qb is not None
    res = tcbirrt.plan(qa, qb, time_limit=20.0, seed=3)
    assert res.success, res.message
    assert res.n_regrasp >= 1
    assert np.allclose(res.object_poses[0].homogeneous, M.homogeneous, atol=1e-6)
    assert np.allclose(res.object_poses[-1].homogeneous, M.homogeneous, atol=1e-6)
    assert max(max(closure_error(tcb, scene1.object.grasps, q)) for q, c in zip(res.path, res.constrained) if c) <= IK_TOL


def test_tcbirrt_reproducible(tcbirrt, tcb_result, trials):
    t = trials[0]
    again = tcbirrt.plan(t.q_start, t.q_goal, time_limit=20.0, seed=t.seed)
    assert again.success and np.array_equal(again.path, tcb_result.path)
    assert again.stats["iterations"] == tcb_result.stats["iterations"]


# ---------------------------------------------------------------------- statuses
@pytest.fixture(scope="session")
def blocked_scene(scene1) -> Scene:
    """Scene 1 plus a box where the nominal start object is: the start is in collision."""
    import tomllib

    from optplan.model.description import models_dir

    d = tomllib.loads((models_dir() / "scenes" / "ssps_scene1.toml").read_text())
    d["obstacles"].append({"name": "intruder", "shape": "box", "size": [0.3, 0.3, 0.3], "xyz": list(scene1.start.translation)})
    return Scene.from_dict(d)


def _planners(tcb, scene, with_ompl=False):
    ck, kn = ValidityChecker(tcb, scene), ClosedChainKinematics(tcb, scene.object.grasps)
    out = {"tcbirrt": TCBiRRT(tcb, scene, checker=ck, kinematics=kn),
           "cbirrt2": CBiRRT2(tcb, scene, checker=ck, kinematics=kn)}
    if with_ompl:
        out["ompl-atlas"] = make_planner("ompl-atlas", tcb, scene, checker=ck, kinematics=kn)
    return out


def test_statuses_invalid_start_goal_timeout(tcb, scene1, blocked_scene, trials, kin, checker):
    t = trials[0]
    qs = t.q_start
    # nominal start configuration collides with the intruder box
    gen_q = np.radians(scene1.extra["q_start"])
    q_col, _ = kin.ik(gen_q, scene1.start.rotation, scene1.start.translation, IKSettings())
    off = t.q_start.copy()
    off[0] += 0.05                                      # off the closed-chain manifold
    for name, pl in _planners(tcb, blocked_scene).items():
        r = pl.plan(q_col, t.q_goal, time_limit=5.0, seed=0)
        assert r is not None and r.status is PlanStatus.INVALID_START, (name, r.status, r.message)
        assert len(r.path) == 0 and not r.success
        r = pl.plan(t.q_goal, q_col, time_limit=5.0, seed=0)
        assert r.status is PlanStatus.INVALID_GOAL, (name, r.status)
    for name, pl in _planners(tcb, scene1).items():
        assert pl.plan(off, t.q_goal, time_limit=5.0).status is PlanStatus.INVALID_START, name
        r = pl.plan(qs, t.q_goal, time_limit=1e-4, seed=0)
        assert r.status is PlanStatus.TIMEOUT, (name, r.status)
        assert r.path.shape == (0, tcb.nq)
        with pytest.raises(ValueError):
            pl.plan(qs, t.q_goal, time_limit=-1.0)
    rrt = RRTConnect(tcb, scene1, checker=checker)
    assert rrt.plan(qs, t.q_goal, time_limit=1e-4).status in (PlanStatus.TIMEOUT, PlanStatus.EXACT)
    q_bad = qs.copy()
    q_bad[:] = 0.0   # arms folded into each other / the base
    if not checker.is_valid_free(q_bad):
        assert rrt.plan(q_bad, qs, time_limit=1.0).status is PlanStatus.INVALID_START


def test_options_are_validated():
    with pytest.raises(ValueError):
        TCBiRRTOptions(step_size=0.0)
    with pytest.raises(ValueError):
        TCBiRRTOptions(n_interp=0)
    with pytest.raises(ValueError):
        TCBiRRTOptions(xi_lower=(0, 0, 0, 0, 0, 0), xi_upper=(-1, 0, 0, 0, 0, 0))
    with pytest.raises(ValueError):
        TCBiRRTOptions(interpolation="slerp")
    with pytest.raises(ValueError):
        CBiRRT2Options(max_edge=-0.6)
    with pytest.raises(ValueError):
        RRTConnectOptions(resolution=0)
    with pytest.raises(ValueError):
        IKSettings(max_iterations=0)
    o = TCBiRRTOptions()
    assert (o.step_size, o.n_interp) == (0.6, 5)
    assert o.xi_lower == (-2.0, -3.0, 0.0, -math.pi, -math.pi, -math.pi)
    with pytest.raises(dataclasses.FrozenInstanceError):
        o.step_size = 1.0   # frozen


# ---------------------------------------------------------------------- CBiRRT2 and RRTConnect
@pytest.fixture(scope="session")
def easy_goal(trials, kin, checker):
    """An easy task: the first trial's start object moved 0.15 m (continuation IK, collision-free
    along the way)."""
    t = trials[0]
    M = t.object_start
    for off in ([0, 0, 0.15], [0, 0, -0.15], [-0.15, 0, 0], [0.15, 0, 0], [0, 0.15, 0], [0, -0.15, 0]):
        q = t.q_start
        for R, p in interpolate_task(M.rotation, M.translation, M.rotation, M.translation + np.array(off, float), 10):
            q, _ = kin.ik(q, R, p, IKSettings())
            if q is None or not checker.is_valid(q):
                q = None
                break
        if q is not None:
            return q
    pytest.fail("no easy goal found")


def test_cbirrt2_easy_task(tcb, scene1, checker, kin, trials, easy_goal):
    t = trials[0]
    q = easy_goal
    pl = CBiRRT2(tcb, scene1, checker=checker, kinematics=kin)
    res = pl.plan(t.q_start, q, time_limit=20.0, seed=1)
    assert res.success, res.message
    assert all(res.constrained) and res.n_regrasp == 0
    for x in res.path:
        assert max(closure_error(tcb, scene1.object.grasps, x)) <= IK_TOL
        assert checker.is_valid(x)
    steps = np.linalg.norm(np.diff(res.path, axis=0), axis=1)
    assert steps.max() <= pl.options.collision_step + 1e-3
    again = pl.plan(t.q_start, q, time_limit=20.0, seed=1)
    assert np.array_equal(again.path, res.path)


def test_rrtconnect_free_space(tcb, scene1, checker, rng):
    from optplan.planners.rrtconnect import edge_is_valid

    pl = RRTConnect(tcb, scene1, checker=checker)
    qs = []
    while len(qs) < 2:
        q = tcb.random_configuration(rng)
        if checker.is_valid_free(q):
            qs.append(q)
    res = pl.plan(qs[0], qs[1], time_limit=20.0, seed=5)
    assert res.success, res.message
    assert res.segments[0].kind == "free" and not any(res.constrained)
    assert all(M is None for M in res.object_poses)
    for a, b in zip(res.path[:-1], res.path[1:]):
        assert edge_is_valid(a, b, checker.is_valid_free, pl.options.resolution)


def test_plan_result_json_round_trip(tcb_result):
    d = json.loads(tcb_result.to_json())
    back = PlanResult.from_dict(d)
    assert back.status is tcb_result.status and np.allclose(back.path, tcb_result.path)
    assert np.array_equal(back.constrained, tcb_result.constrained)
    assert len(back.segments) == len(tcb_result.segments)
    for a, b in zip(back.object_poses, tcb_result.object_poses):
        assert np.allclose(a.homogeneous, b.homogeneous, atol=1e-12)
    assert d["n_regrasp"] == tcb_result.n_regrasp


# ---------------------------------------------------------------------- OMPL peer
def test_ompl_peer_easy_task(tcb, scene1, checker, kin, trials, easy_goal):
    pytest.importorskip("ompl")
    t = trials[0]
    q = easy_goal
    pl = make_planner("ompl-atlas", tcb, scene1, checker=checker, kinematics=kin)
    res = pl.plan(t.q_start, q, time_limit=20.0, seed=2)
    assert res.success, res.message
    # every state of the (interpolated) path on the manifold to OMPL's tolerance (max |h_i| ≤ 1e-6,
    # so the position / angle norms ≤ √3 · 1e-6), checked independently with Pinocchio FK
    for x in res.path:
        assert max(closure_error(tcb, scene1.object.grasps, x)) <= math.sqrt(3) * pl.options.tolerance
        assert checker.is_valid(x)
    assert np.array_equal(res.path[0], t.q_start) and np.array_equal(res.path[-1], q)
    assert pl.plan(t.q_start, t.q_goal, time_limit=1e-3, seed=2).status is PlanStatus.TIMEOUT   # the full task


# ---------------------------------------------------------------------- benchmark runner
def test_bench_runner_resumes(tmp_path):
    from optplan.bench.tcbirrt import BenchConfig, load_results, run, summarize

    cfg = BenchConfig(scenes=["1"], planners=["tcbirrt"], trials=2, time_limit=10.0, seed=0, jobs=1,
                      out=str(tmp_path / "b"), progress=False, plot=True)
    rows = run(cfg)
    assert len(rows) == 2 and all(r["success"] for r in rows)
    assert (tmp_path / "b" / "success_curves.png").stat().st_size > 0
    # a killed run: truncated last line; the resumed run redoes only that trial
    p = tmp_path / "b" / "results.jsonl"
    text = p.read_text().splitlines(keepends=True)
    p.write_text(text[0] + text[1][:40])
    rows2 = run(cfg)
    assert len(load_results(p)) == 2 and len(rows2) == 2
    assert {r["trial"] for r in rows2} == {0, 1}
    again = {r["trial"]: r for r in rows2}
    first = {r["trial"]: r for r in rows}
    assert again[1]["task"] == first[1]["task"] and again[1]["stats"]["iterations"] == first[1]["stats"]["iterations"]
    s = summarize(rows2, 10.0)["ssps_scene1"]["planners"]["tcbirrt"]
    assert s["successes"] == 2 and s["p_t"]["10.0"] == 1.0
    assert rows2[0]["checks"]["max_closed_chain_residual"] <= IK_TOL


def test_bench_results_do_not_depend_on_jobs(tmp_path):
    """Per-trial seeds: two worker processes give the same tasks and paths as one."""
    from optplan.bench.tcbirrt import BenchConfig, run

    kw = dict(scenes=["1"], planners=["tcbirrt"], trials=2, first_trial=5, time_limit=10.0, seed=7, progress=False,
              plot=False)
    a = {r["trial"]: r for r in run(BenchConfig(jobs=1, out=str(tmp_path / "serial"), **kw))}
    b = {r["trial"]: r for r in run(BenchConfig(jobs=2, out=str(tmp_path / "pool"), **kw))}
    assert set(a) == set(b) == {5, 6}
    for i in a:
        assert a[i]["task"] == b[i]["task"]
        assert a[i]["status"] == b[i]["status"] == "exact"
        assert a[i]["stats"]["iterations"] == b[i]["stats"]["iterations"]
        assert a[i]["n_configurations"] == b[i]["n_configurations"]


# ---------------------------------------------------------------------- statistical (slow)
@pytest.mark.slow
def test_tcbirrt_scene1_statistics(tcb, scene1, tcbirrt, gen):
    """20 seeded trials of scene 1 (Section 5.1 perturbations), 10 s each: success >= 0.9."""
    ok = 0
    for i in range(20):
        t = gen.generate(i, 123)
        ok += tcbirrt.plan(t.q_start, t.q_goal, time_limit=10.0, seed=t.seed, clock="cpu").success
    assert ok / 20 >= 0.9
