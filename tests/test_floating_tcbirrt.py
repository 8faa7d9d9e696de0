"""The bidirectional closed-chain RRT of a free-floating robot (optplan.planners.floating_tcbirrt),
judged independently: one simulate_base run along the whole joint path (finer RK4 than the
planner's edge-by-edge integration) gives the base, Pinocchio FK the closed chain, coal's exact
distances the clearance at that base, and the object's pose at the end the goal error."""
from __future__ import annotations

import dataclasses

import numpy as np
import pinocchio as pin
import pytest
from floating_paths import reintegrate

from optplan.collision.checker import CollisionChecker
from optplan.errors import ConfigurationError, OptionError
from optplan.floating_pipeline import FloatingPipelineOptions, options_for_scene, scene_start, trial_goal
from optplan.model.robot import RobotModel
from optplan.planners.floating_carry import FloatingCarryOptions, FloatingCarryPlanner
from optplan.planners.floating_tcbirrt import FloatingTCBiRRT, FloatingTreeOptions
from optplan.planners.validity import ValidityChecker
from optplan.scene import Scene


@pytest.fixture(scope="module")
def robot():
    return RobotModel.from_name("eba_ffsr")


def _whole_path(robot, joints, base0, per_edge=20):
    """:func:`floating_paths.reintegrate` (smoothstep timing per edge, one simulate_base run)."""
    return reintegrate(robot, joints, base0, per_edge=per_edge, substeps=4)


def _hands(robot, q):
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    return [d.oMf[robot.arm(a).ee_frame_id].copy() for a in ("A", "B")]


def _judge(robot, scene, res, base0=None):
    """Every property the planner claims, checked independently; returns the re-integration."""
    base0 = pin.SE3.Identity() if base0 is None else base0
    assert res.success, res.message
    s, sim = _whole_path(robot, res.joints, base0)
    for k, i in enumerate(range(0, len(s), 20)):   # the plan's base poses = the independent integration
        e = pin.XYZQUATToSE3(res.q[k, :7]).actInv(pin.XYZQUATToSE3(sim.q[i, :7]))
        assert np.linalg.norm(pin.log6(e).vector) < 1e-6
    assert np.max(sim.momentum_residual) < 1e-8    # zero momentum along the whole path
    ga, gb = scene.object.grasps["A"], scene.object.grasps["B"]
    for q in res.q:                                 # closed chain at every waypoint
        hA, hB = _hands(robot, q)
        rel = (hA * ga.inverse()).actInv(hB * gb.inverse())
        assert np.linalg.norm(pin.log6(rel).vector) < 1e-8
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q)   # exact, at the re-integrated base
    assert dmin >= 0.0
    return sim


def test_world_goal_with_drift_is_reached(robot):
    # trial 10 of floating_truss: the first join misses the world goal by the drift; the goal tree is
    # re-rooted and the generalized-Jacobian correction lands the object (the straight planner fails here)
    scene = Scene.load("floating_truss")
    q0, goal = scene_start(robot, scene), trial_goal(scene, 10, 0)
    planner = FloatingTCBiRRT(robot, scene)
    res = planner.plan(q0, goal, seed=10, time_limit=20.0)
    sim = _judge(robot, scene, res)
    hA, _ = _hands(robot, sim.q[-1])
    err = goal.actInv(hA * scene.object.grasps["A"].inverse())
    assert np.linalg.norm(err.translation) <= 1e-3 and np.linalg.norm(pin.log3(err.rotation)) <= 1e-3
    assert np.degrees(np.linalg.norm(pin.log3(sim.final_base.rotation))) > 1.0   # the base really turned
    qfix = np.concatenate([pin.SE3ToXYZQUAT(pin.SE3.Identity()), res.joints[-1]])   # without the drift: a miss
    assert np.linalg.norm(goal.actInv(_hands(robot, qfix)[0] * scene.object.grasps["A"].inverse()).translation) > 0.01
    assert res.min_clearance_m >= 0.0


def test_world_goal_out_of_reach_at_the_arrival_attitude_is_steered(robot):
    # trial 13 of floating_truss: the joined path arrives at a base attitude from which the arms cannot
    # hold the module at its world goal (the correction fails); closed object loops turn the base
    # until they can. Without steering the same query does not land in the same time.
    scene = Scene.load("floating_truss")
    q0, goal = scene_start(robot, scene), trial_goal(scene, 13, 0)
    planner = FloatingTCBiRRT(robot, scene)
    res = planner.plan(q0, goal, seed=13, time_limit=20.0)
    assert planner.stats["steers_landed"] == 1 and planner.stats["steer_loops"] >= 2
    sim = _judge(robot, scene, res)
    hA, _ = _hands(robot, sim.q[-1])
    err = goal.actInv(hA * scene.object.grasps["A"].inverse())
    assert np.linalg.norm(err.translation) <= 1e-3 and np.linalg.norm(pin.log3(err.rotation)) <= 1e-3
    plain = FloatingTCBiRRT(robot, scene, tree=FloatingTreeOptions(steer_attitude=False))
    assert not plain.plan(q0, goal, seed=13, time_limit=3.0).success
    assert plain.stats["corrections_failed"] >= 1


@pytest.mark.slow
def test_world_goal_with_the_initial_attitude_restored(robot):
    # trial 2 of floating_truss with the base attitude restored: the goal tree is rooted where the arms
    # hold the module at its world goal with the base at its initial attitude; the joined path arrives
    # turned and closed object loops turn it back. The independent integration ends at the initial
    # attitude (≤ 1e-6 rad) with the module at its world goal.
    scene = Scene.load("floating_truss")
    q0, goal = scene_start(robot, scene), trial_goal(scene, 2, 0)
    planner = FloatingTCBiRRT(robot, scene, tree=FloatingTreeOptions(restore_attitude=True))
    res = planner.plan(q0, goal, seed=2, time_limit=30.0)
    assert planner.stats["steers_landed"] == 1
    sim = _judge(robot, scene, res)
    assert np.linalg.norm(pin.log3(sim.final_base.rotation)) <= 1e-6
    hA, _ = _hands(robot, sim.q[-1])
    err = goal.actInv(hA * scene.object.grasps["A"].inverse())
    assert np.linalg.norm(err.translation) <= 1e-6 and np.linalg.norm(pin.log3(err.rotation)) <= 1e-6
    # the same query without restoration ends turned
    plain = FloatingTCBiRRT(robot, scene).plan(q0, goal, seed=2, time_limit=30.0)
    assert np.linalg.norm(pin.log3(plain.final_base.rotation)) > 1e-2
    # a world goal the arms cannot hold at the initial attitude is a status, not an exception
    far = pin.SE3(goal.rotation, goal.translation + np.array([0.0, 0.0, 3.0]))
    bad = planner.plan(q0, far, seed=0, time_limit=5.0)
    assert not bad.success and "initial attitude" in bad.message


def test_goal_in_the_base_frame_where_the_straight_planner_fails(robot):
    # trial 9 of floating_stow (a servicer stowing a module on its own body): the straight motion and
    # its via poses collide; the trees find a path
    scene = Scene.load("floating_stow")
    opts = options_for_scene(scene).planner
    assert opts.target_frame == "base"
    q0, goal = scene_start(robot, scene), trial_goal(scene, 9, 0)
    assert not FloatingCarryPlanner(robot, scene, opts).plan(q0, goal, seed=9).success
    planner = FloatingTCBiRRT(robot, scene, opts)
    res = planner.plan(q0, goal, seed=9, time_limit=20.0)
    _judge(robot, scene, res)
    e = goal.actInv(planner.object_in_base(res.joints[-1]))   # base frame: no drift correction
    assert np.linalg.norm(e.translation) < 1e-8 and res.corrections == 0


def test_goal_root_on_the_start_branch_by_self_motion(robot):
    # trial 68 of floating_stow: the goal pose's solution on the start's IK branch (path IK) collides;
    # roots from other seeds are other branches, which the trees reach but cannot join with the object
    # held still. A collision-free point of that solution's self-motion roots the goal tree instead.
    from optplan.planners.floating_reach import self_motion_clear

    scene = Scene.load("floating_stow")
    opts = options_for_scene(scene).planner
    q0, goal = scene_start(robot, scene), trial_goal(scene, 68, 0)
    planner = FloatingTCBiRRT(robot, scene, opts)
    qp = planner._path_ik(q0, goal)
    assert qp is not None and not planner.validity.is_valid(planner.carry._full(qp))
    qc = self_motion_clear(planner.carry, planner.validity, qp, goal, pin.SE3.Identity(), np.random.default_rng(0))
    assert qc is not None and float(np.max(np.abs(qc - qp))) > 0.05
    full = planner.carry._full(qc)
    for a in ("A", "B"):   # both hands still at their grasps on the object at the goal (base frame)
        hand = _hands(robot, full)[0 if a == "A" else 1]
        assert np.linalg.norm(pin.log6((goal * scene.object.grasps[a]).actInv(hand)).vector) < 1e-8
    dmin, _ = CollisionChecker(robot, scene).min_distance(full)
    assert dmin >= 0.0
    res = planner.plan(q0, goal, seed=68, time_limit=20.0)
    _judge(robot, scene, res)
    assert np.linalg.norm(goal.actInv(planner.object_in_base(res.joints[-1])).translation) < 1e-8


def test_start_elsewhere_in_the_world(robot):
    # the base starts away from the origin, turned: the planner's poses follow it (left-invariance)
    scene = Scene.load("floating_stow")
    opts = options_for_scene(scene).planner
    base0 = pin.SE3(pin.rpy.rpyToMatrix(0.0, 0.0, 0.3), np.array([-1.0, 0.5, 0.0]))
    free = dataclasses.replace(scene, obstacles=())   # the shipped obstacles are placed for a base at the origin
    res = FloatingTCBiRRT(robot, free, opts).plan(scene_start(robot, scene), scene.goal, base0=base0, seed=0)
    _judge(robot, free, res, base0)


def test_validity_checker_places_the_floating_base(robot):
    scene = Scene.load("floating_truss")
    vc, cc = ValidityChecker(robot, scene), CollisionChecker(robot, scene)
    assert vc.kernel == "coal"
    rng = np.random.default_rng(3)
    q0 = scene_start(robot, scene)
    Q = []
    for _ in range(150):
        b = pin.SE3(pin.rpy.rpyToMatrix(*rng.uniform(-0.4, 0.4, 3)), rng.uniform(-0.4, 0.4, 3))
        Q.append(np.r_[pin.SE3ToXYZQUAT(b), q0 + rng.normal(0.0, 0.2, robot.nj)])
    Q = np.array(Q)
    exact = np.array([cc.min_distance(q)[0] >= 0.0 for q in Q])
    assert 10 < exact.sum() < len(Q) - 10          # both verdicts occur
    np.testing.assert_array_equal(vc.valid_batch(Q), exact)
    # the same joints, the base moved onto the truss's beam: the base pose is part of the placement
    q = Q[np.flatnonzero(exact)[0]].copy()
    q[:3] = [1.95, -0.2, 0.0]
    assert not vc.is_valid(q) and cc.min_distance(q)[0] < 0.0


def test_bad_input_and_failures_are_statuses(robot):
    scene = Scene.load("floating_truss")
    with pytest.raises(OptionError, match="extend_m"):
        FloatingTreeOptions(extend_m=0.0)
    with pytest.raises(OptionError, match="clock"):
        FloatingTreeOptions(clock="gpu")
    with pytest.raises(OptionError, match="goal_bias"):
        FloatingTreeOptions(goal_bias=1.5)
    with pytest.raises(OptionError, match="planner_name"):
        FloatingPipelineOptions(planner_name="prm")
    with pytest.raises(ConfigurationError, match="free-floating"):
        FloatingTCBiRRT(RobotModel.from_name("tcbirrt_dual_arm"), scene)
    planner = FloatingTCBiRRT(robot, scene, FloatingCarryOptions(), FloatingTreeOptions(goal_seeds=3))
    q0 = scene_start(robot, scene)
    far = pin.SE3(np.eye(3), np.array([4.0, 0.0, 0.0]))     # out of the arms' reach
    res = planner.plan(q0, far, seed=0, time_limit=5.0)
    assert res.status.value == "invalid_goal" and "goal pose" in res.message
    res = planner.plan(q0, scene.goal, base0=pin.SE3(np.eye(3), np.array([1.5, 0.0, 0.0])))
    assert res.status.value == "invalid_start"


def test_zero_momentum_ik_keeps_the_centre_of_mass(robot):
    # truss trial 17: no two-arm IK solution holds the module at this world goal with the base at the
    # origin, but one does with the base where the unmoved centre of mass puts it
    from optplan.planners.floating_reach import zero_momentum_ik

    scene = Scene.load("floating_truss")
    q0, goal = scene_start(robot, scene), trial_goal(scene, 17, 0)
    planner = FloatingCarryPlanner(robot, scene)
    assert planner.hold(q0, goal) is None                     # base at the origin: out of reach
    m, d = robot.model, robot.model.createData()
    com = pin.centerOfMass(m, d, np.r_[pin.SE3ToXYZQUAT(pin.SE3.Identity()), q0]).copy()
    q, base, res = zero_momentum_ik(robot, scene.object.grasps, goal, [q0], com, np.random.default_rng(0))
    assert res <= 1e-10
    full = np.r_[pin.SE3ToXYZQUAT(base), q]
    np.testing.assert_allclose(pin.centerOfMass(m, d, full), com, atol=1e-9)   # Pinocchio's CoM, recomputed
    for arm, h in zip(("A", "B"), _hands(robot, full)):
        assert np.linalg.norm(pin.log6((goal * scene.object.grasps[arm]).actInv(h)).vector) < 1e-9
    assert np.linalg.norm(base.translation) > 0.02               # the base had to move for it


def test_zero_momentum_ik_with_the_attitude_held(robot):
    # the re-rooting after a join asks where the arms hold the module for THAT arrival attitude:
    # the returned base keeps it exactly, the centre of mass stays put, the hands are at the goal
    from optplan.planners.floating_reach import zero_momentum_ik

    scene = Scene.load("floating_truss")
    q0, goal = scene_start(robot, scene), trial_goal(scene, 13, 0)
    m, d = robot.model, robot.model.createData()
    com = pin.centerOfMass(m, d, np.r_[pin.SE3ToXYZQUAT(pin.SE3.Identity()), q0]).copy()
    q_f, free_base, res_f = zero_momentum_ik(robot, scene.object.grasps, goal, [q0], com, np.random.default_rng(1))
    assert res_f <= 1e-10
    # 0.01 rad away from the attitude the free search found: the joints must absorb it
    att = pin.SE3(free_base.rotation @ pin.rpy.rpyToMatrix(0.004, -0.006, 0.007), np.zeros(3))
    q, base, res = zero_momentum_ik(robot, scene.object.grasps, goal, [q_f], com, np.random.default_rng(1),
                                    attitude=att, fix_attitude=True)
    assert res <= 1e-10
    assert np.linalg.norm(pin.log3(att.rotation.T @ base.rotation)) < 1e-12   # attitude held
    full = np.r_[pin.SE3ToXYZQUAT(base), q]
    np.testing.assert_allclose(pin.centerOfMass(m, d, full), com, atol=1e-9)
    for arm, h in zip(("A", "B"), _hands(robot, full)):
        assert np.linalg.norm(pin.log6((goal * scene.object.grasps[arm]).actInv(h)).vector) < 1e-9
    assert np.max(np.abs(q - q_f)) > 1e-3          # other joints than the free solution's


def test_limited_step_respects_limits_and_solves_the_free_joints():
    from optplan.planners.floating_reach import limited_step

    rng = np.random.default_rng(3)
    J = rng.normal(size=(6, 9))
    lower, upper = -np.ones(9), np.ones(9)
    q = rng.uniform(-0.5, 0.5, 9)
    e = 0.01 * rng.normal(size=6)
    # far from the limits and below the step cap: J dq = e to the damping (checked against lstsq)
    dq = limited_step(J, e, q, lower, upper, max_step=1.0, centring=0.0)
    np.testing.assert_allclose(J @ dq, e, atol=1e-6)
    np.testing.assert_allclose(dq, np.linalg.lstsq(J, e, rcond=None)[0], atol=1e-6)   # the min-norm step
    # the centring term lives in the null space: the task is unchanged
    dq_c = limited_step(J, e, q, lower, upper, max_step=1.0, centring=0.1)
    np.testing.assert_allclose(J @ dq_c, e, atol=1e-6)
    # one joint at its upper limit where the min-norm step pushes it further: it stays within the
    # limits and the other joints still solve the task (rank 6 with 8 free joints)
    k = int(np.argmax(np.abs(dq)))
    q_lim = q.copy()
    q_lim[k] = upper[k] if dq[k] > 0 else lower[k]
    dq_l = limited_step(J, e, q_lim, lower, upper, max_step=1.0, centring=0.0)
    assert np.all(q_lim + dq_l <= upper + 1e-15) and np.all(q_lim + dq_l >= lower - 1e-15)
    assert abs(dq_l[k]) < 1e-15
    np.testing.assert_allclose(J @ dq_l, e, atol=1e-6)
    # a plain step clipped at the limit misses the task by the clipped part
    clipped = np.clip(q_lim + dq, lower, upper) - q_lim
    assert np.linalg.norm(J @ clipped - e) > 10 * np.linalg.norm(J @ dq_l - e)
    # the step cap [rad]
    assert np.max(np.abs(limited_step(J, 100 * e, q, lower, upper, max_step=0.05))) <= 0.05 + 1e-15
