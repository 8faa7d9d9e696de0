"""The momentum-aware closed-chain planner of a free-floating robot (optplan.planners.floating_carry),
judged by an independent re-integration of its whole joint path: the base where momentum puts it,
the object's world pose at the end, the closed chain at the waypoints (Pinocchio FK) and the exact
clearance along the path."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan.collision.checker import CollisionChecker
from optplan.errors import ConfigurationError, OptionError
from optplan.model.floating import simulate_base
from optplan.planners.floating_carry import FloatingCarryOptions, FloatingCarryPlanner, integrate_edge
from optplan.scene import Scene


@pytest.fixture(scope="module")
def setup():
    from optplan.model.robot import RobotModel

    robot = RobotModel.from_name("eba_ffsr")
    scene = Scene.load("floating_truss")
    q0 = np.radians(np.asarray(scene.extra["q_start"], float))
    return robot, scene, q0


def _whole_path(robot, joints, per_edge=40):
    """The planner's joint path as one piecewise-linear trajectory, re-integrated in one run
    (finer grid, more RK4 substeps than the planner's edge-by-edge integration)."""
    s = np.linspace(0.0, len(joints) - 1, (len(joints) - 1) * per_edge + 1)

    def traj(t):
        k = min(int(t), len(joints) - 2)
        return joints[k] + (t - k) * (joints[k + 1] - joints[k]), joints[k + 1] - joints[k]

    return s, simulate_base(robot, traj, s, substeps=4)


def _hands(robot, q):
    d = robot.model.createData()
    pin.framesForwardKinematics(robot.model, d, q)
    return [d.oMf[robot.arm(a).ee_frame_id].copy() for a in ("A", "B")]


def test_the_module_reaches_its_world_goal_with_the_base_drifting(setup):
    robot, scene, q0 = setup
    planner = FloatingCarryPlanner(robot, scene)
    res = planner.plan(q0, scene.goal, seed=0)
    assert res.success, res.message
    assert res.corrections >= 1                      # the first motion misses by the drift
    s, sim = _whole_path(robot, res.joints)
    idx = np.arange(0, len(s), 40)
    # the planner's base poses are those of the independent integration
    for k, i in enumerate(idx):
        e = pin.XYZQUATToSE3(res.q[k, :7]).actInv(pin.XYZQUATToSE3(sim.q[i, :7]))
        assert np.linalg.norm(pin.log6(e).vector) < 1e-5   # RK4 of the edges vs a finer run (≪ goal tol)
    assert np.degrees(np.linalg.norm(pin.log3(sim.final_base.rotation))) > 1.0   # the base really turned
    # the object's world pose at the end, read from hand A with the re-integrated base
    hA, hB = _hands(robot, sim.q[-1])
    M = hA * scene.object.grasps["A"].inverse()
    err = scene.goal.actInv(M)
    assert np.linalg.norm(err.translation) <= 1e-3 and np.linalg.norm(pin.log3(err.rotation)) <= 1e-3
    # without the drift (base held at the origin) the same joints miss the world goal by centimetres
    qfix = np.concatenate([pin.SE3ToXYZQUAT(pin.SE3.Identity()), res.joints[-1]])
    Mfix = _hands(robot, qfix)[0] * scene.object.grasps["A"].inverse()
    assert np.linalg.norm(scene.goal.actInv(Mfix).translation) > 0.01
    # the closed chain at every waypoint, and the exact clearance along the re-integrated path
    for q in res.q:
        hA, hB = _hands(robot, q)
        rel = (hA * scene.object.grasps["A"].inverse()).actInv(hB * scene.object.grasps["B"].inverse())
        assert np.linalg.norm(pin.log6(rel).vector) < 1e-9
    dmin, _, _ = CollisionChecker(robot, scene).min_distance_along(sim.q)
    assert dmin >= 0.0 and dmin == pytest.approx(res.min_clearance_m, abs=5e-3)


def test_target_in_the_base_frame_needs_no_correction(setup):
    robot, scene, q0 = setup
    planner = FloatingCarryPlanner(robot, scene, FloatingCarryOptions(target_frame="base"))
    res = planner.plan(q0, scene.goal, seed=0)
    assert res.success and res.corrections == 0
    e = scene.goal.actInv(planner.object_in_base(res.joints[-1]))
    assert np.linalg.norm(e.translation) < 1e-8


def test_integrate_edge_is_driftless_and_composes(setup):
    robot, _, q0 = setup
    q1 = q0 + 0.2 * np.cos(np.arange(14))
    base = pin.SE3(pin.rpy.rpyToMatrix(0.1, 0.2, -0.3), np.array([0.5, -1.0, 2.0]))
    whole = integrate_edge(robot, base, q0, q1, 40)
    half = integrate_edge(robot, base, q0, 0.5 * (q0 + q1), 20)
    rest = integrate_edge(robot, pin.XYZQUATToSE3(half[-1, :7]), 0.5 * (q0 + q1), q1, 20)
    np.testing.assert_allclose(rest[-1], whole[-1], atol=1e-9)


def test_bad_input(setup):
    robot, scene, q0 = setup
    from optplan.model.robot import RobotModel

    with pytest.raises(OptionError, match="target_frame"):
        FloatingCarryOptions(target_frame="hand")
    with pytest.raises(OptionError, match="check_step_rad"):
        FloatingCarryOptions(check_step_rad=0.0)
    with pytest.raises(ConfigurationError, match="free-floating"):
        FloatingCarryPlanner(RobotModel.from_name("tcbirrt_dual_arm"), scene)
    res = FloatingCarryPlanner(robot, scene).plan(q0 + 0.0, scene.goal, base0=pin.SE3(np.eye(3), np.array([1.5, 0, 0])))
    assert res.status.value == "invalid_start"   # the base moved onto the module: a status, not an exception


def test_onto_chain_is_hold_onto_the_first_hands_object(setup):
    """The manoeuvres' chain projection gives what ``hold`` gives (the second hand on its grasp on
    the object the first hand holds, the first arm unchanged), judged by Pinocchio FK."""
    robot, scene, q0 = setup
    pl = FloatingCarryPlanner(robot, scene)
    q0 = pl.hold(q0, pl.object_in_base(q0))
    rng = np.random.default_rng(5)
    ga, gb = scene.object.grasps["A"], scene.object.grasps["B"]
    d = robot.model.createData()
    first = robot.arm("A").j_idx
    for _ in range(4):
        q = np.clip(q0 + rng.normal(0.0, 0.03, robot.nj), robot.lower, robot.upper)
        a, b = pl.hold(q, pl.object_in_base(q)), pl.onto_chain(q)
        assert a is not None and b is not None
        assert np.max(np.abs(a - b)) < 1e-9
        assert np.array_equal(b[first], q[first])
        pin.framesForwardKinematics(robot.model, d, robot.configuration(b))
        hA, hB = (d.oMf[robot.arm(n).ee_frame_id] for n in ("A", "B"))
        assert np.linalg.norm(pin.log6((hA * ga.inverse()).actInv(hB * gb.inverse())).vector) < 1e-9
    far = q0.copy()
    far[robot.arm("B").j_idx] = robot.lower[robot.arm("B").j_idx]   # the second arm at its limits: no hold
    assert pl.onto_chain(far) is None
