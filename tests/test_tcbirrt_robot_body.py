"""The robot's own fixed body in TCBiRRT's task-space filter and lead path (``TCBiRRTOptions.filter_robot_body``).
Checked against coal's exact collision tests with the geometry placed by Pinocchio's own forward kinematics, and a
search with it against the bench's independent path checks."""
from __future__ import annotations

import coal
import numpy as np
import pinocchio as pin
import pytest

from optplan.planners import TCBiRRT, TCBiRRTOptions
from optplan.planners.task_sampling import ObjectPoseFilter, _rpy_matrix, robot_body_obstacles
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


@pytest.mark.slow
def test_search_with_the_robot_body_keeps_the_lead_off_the_base(tcb):
    """With ``filter_robot_body`` the object's lead path keeps the object off the robot's base at every one of its
    poses (coal, the base placed by Pinocchio FK), and the search returns a path that passes the bench's checks
    (closed chain by Pinocchio FK, collision-free, every edge at the 1 cm sweep)."""
    from graft_paths import check_planned_path

    from optplan.planners.validity import ValidityChecker
    from optplan.trials import TrialGenerator

    scene = Scene.load("hard_bay")
    ck = ValidityChecker(tcb, scene)
    t = TrialGenerator(tcb, scene).generate(0, 0)
    pl = TCBiRRT(tcb, scene, TCBiRRTOptions(variant="improved", filter_robot_body=True), checker=ck)
    res = pl.plan(t.q_start, t.q_goal, time_limit=30.0, seed=t.seed, clock="cpu")
    assert res.success, res.message
    check_planned_path(tcb, scene, ck, res, t.q_start, t.q_goal)
    lead = pl._lead[0]
    assert lead is not None and len(lead) > 2
    obj, req = scene.object.coal_geometry(), coal.CollisionRequest()
    (geo, M), = _fixed_geometries_placed(tcb)
    for xi in lead:
        res_c = coal.CollisionResult()
        assert not coal.collide(obj, coal.Transform3s(_rpy_matrix(xi), xi[:3]), geo,
                                coal.Transform3s(M.rotation, M.translation), req, res_c)
