"""The robot's own fixed body in TCBiRRT's task-space filter (``TCBiRRTOptions.filter_robot_body``) and the
object-step redraws (``object_step_tries``). Checked against coal's exact collision tests with the geometry
placed by Pinocchio's own forward kinematics, and against the planner's interpolation (Eq. 3-4)."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin

from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.task_sampling import ObjectPoseFilter, _rpy_matrix, robot_body_obstacles
from optplan.planners.task_space import interpolate_task, pose_from_xi
from optplan.planners.tcbirrt_object_step import first_waypoint, first_waypoint_free
from optplan.scene import Scene


def _fixed_geometries_placed(robot):
    """(coal geometry, world placement) of every robot geometry that no joint moves: placed by Pinocchio's
    ``updateGeometryPlacements`` at two random configurations, kept where both placements agree."""
    m, cm = robot.model, robot.collision_model
    d, gd = m.createData(), pin.GeometryData(cm)
    rng = np.random.default_rng(5)
    out = []
    P = []
    for _ in range(2):
        pin.updateGeometryPlacements(m, d, cm, gd, robot.configuration(robot.random_joints(rng)))
        P.append([pin.SE3(M) for M in gd.oMg])
    for k, g in enumerate(cm.geometryObjects):
        if np.allclose(P[0][k].homogeneous, P[1][k].homogeneous, atol=1e-12):
            out.append((g.geometry, P[0][k]))
    return out


def test_robot_body_obstacles_are_the_geometry_no_joint_moves(tcb):
    """The paper robot's fixed body is its base box, where forward kinematics puts it at any configuration."""
    obs = robot_body_obstacles(tcb)
    fixed = _fixed_geometries_placed(tcb)
    assert len(obs) == len(fixed) == 1
    (geo, M), o = fixed[0], obs[0]
    assert o.shape == "box" and np.allclose(np.asarray(o.size) / 2, geo.halfSide)
    assert np.allclose(o.placement.homogeneous, M.homogeneous)


def test_filter_with_the_robot_body_agrees_with_exact_collision(tcb):
    """At random object poses around the robot's base, the filter with ``robot_body`` says "collides" exactly when
    coal finds the object box in contact with a scene obstacle or with the robot's fixed geometry (placed by
    Pinocchio FK); without ``robot_body`` only the scene's obstacles count. Both outcomes occur."""
    scene = Scene.load("hard_bay")
    fixed = _fixed_geometries_placed(tcb)
    obj = scene.object.coal_geometry()
    with_body = ObjectPoseFilter(tcb, scene, robot_body=True)
    without = ObjectPoseFilter(tcb, scene)
    req = coal.CollisionRequest()
    rng = np.random.default_rng(11)
    centre = fixed[0][1].translation
    seen = {True: 0, False: 0}
    body_only = 0
    for _ in range(300):
        xi = np.r_[centre + rng.uniform(-2.0, 2.0, 3), rng.uniform(-np.pi, np.pi, 3)]
        R, p = _rpy_matrix(xi), xi[:3]
        tf = coal.Transform3s(R, p)

        def hits(geo, M, tf=tf):
            res = coal.CollisionResult()
            return coal.collide(obj, tf, geo, coal.Transform3s(M.rotation, M.translation), req, res)

        scene_hit = any(hits(o.coal_geometry(), o.placement) for o in scene.obstacles)
        body_hit = any(hits(g, M) for g, M in fixed)
        assert without.object_free(R, p) == (not scene_hit)
        assert with_body.object_free(R, p) == (not (scene_hit or body_hit))
        seen[body_hit] += 1
        body_only += body_hit and not scene_hit
    assert seen[True] > 20 and seen[False] > 20 and body_only > 10


def test_floating_robot_has_no_fixed_body():
    """A floating base moves with the arms: nothing of it is an obstacle the object can rule out."""
    from optplan.model.robot import RobotModel

    robot = RobotModel.from_name("eba_ffsr")
    assert robot.is_floating and robot_body_obstacles(robot) == ()


def test_first_waypoint_is_the_extensions_first_interpolated_pose(tcb):
    """The pose the redraw tests is the first of the ``n_interp`` poses the planner's extension interpolates (Eq. 4)
    toward ξ_s of Eq. 3 — near and far samples alike."""
    rng = np.random.default_rng(2)
    for _ in range(20):
        xi_near = np.r_[rng.uniform(-1, 1, 3), rng.uniform(-3, 3, 3)]
        xi_rand = xi_near + rng.normal(0.0, rng.choice([0.1, 2.0]), 6)
        R0, p0 = pose_from_xi(xi_near)
        step, n = 0.6, 5
        d = xi_rand - xi_near
        dist = float(np.linalg.norm(d))
        xi_s = xi_rand if dist <= step else xi_near + step / dist * d
        R1, p1 = interpolate_task(R0, p0, *pose_from_xi(xi_s), n)[0]
        R, p = first_waypoint(R0, p0, xi_near, xi_rand, step, n)
        assert np.allclose(R, R1, atol=1e-12) and np.allclose(p, p1, atol=1e-12)


def test_object_step_redraws_leave_no_object_trapped_first_waypoint(tcb):
    """With ``object_step_tries`` the extensions of tree a start where the object alone is free at the first
    waypoint (checked by coal on the scene's obstacles) unless the draws ran out; the search still returns a path
    that passes the bench's checks."""
    from graft_paths import check_planned_path

    from optplan.planners.validity import ValidityChecker
    from optplan.trials import TrialGenerator

    scene = Scene.load("hard_bay")
    ck = ValidityChecker(tcb, scene)
    t = TrialGenerator(tcb, scene).generate(0, 0)
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", object_step_tries=10), checker=ck)
    res = pl.plan(t.q_start, t.q_goal, time_limit=30.0, seed=t.seed, clock="cpu")
    assert res.success, res.message
    assert res.stats["object_step_redraws"] > 0
    check_planned_path(tcb, scene, ck, res, t.q_start, t.q_goal)
    filt = ObjectPoseFilter(tcb, scene, native=False)   # coal
    R0, p0 = pose_from_xi(np.array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]))
    assert first_waypoint_free(filt, R0, p0, np.array([0.0, 0.0, 2.0, 0, 0, 0]), np.array([0.3, 0, 2.0, 0, 0, 0]),
                               0.6, 5) == filt.object_free(*first_waypoint(R0, p0, np.array([0.0, 0.0, 2.0, 0, 0, 0]),
                                                                           np.array([0.3, 0, 2.0, 0, 0, 0]), 0.6, 5))
