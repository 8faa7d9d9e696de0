"""The batched numeric evaluation of frame terms (``NumericTrajectory.placements``, one forward
kinematics per point for all frames; residuals vectorised) against Pinocchio point by point
(``framesForwardKinematics``, ``SE3.actInv``): the dense check between knots evaluates these
terms at ~10 points per interval after every solve."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from optplan import RobotModel
from optplan.problem.frame_terms import ClosedChain, FramePath, FramePose, OrientationConstraint
from optplan.problem.terms import NumericTrajectory, pose_residual_numeric


def _traj(robot: RobotModel, rng: np.random.Generator, N: int = 12) -> NumericTrajectory:
    q = rng.uniform(-1.0, 1.0, (N + 1, robot.nj))
    bq = com0 = None
    if robot.is_floating:
        bq = rng.normal(size=(N + 1, 4))
        bq /= np.linalg.norm(bq, axis=1, keepdims=True)
        com0 = rng.normal(size=3)
    return NumericTrajectory(robot, q, rng.normal(size=q.shape), rng.normal(size=q.shape),
                             rng.normal(size=(N, robot.nj)), 2.5, bq, com0)


def _frame(traj: NumericTrajectory, name: str, k) -> pin.SE3:
    """Pinocchio's placement of frame ``name`` at a knot or interior point, computed alone."""
    robot = traj.robot
    if isinstance(k, tuple):
        i, f = k
        tau = f * traj.h
        q = traj.q[i] + tau * traj.qd[i] + tau**2 / 2 * traj.qdd[i] + tau**3 / 6 * traj.jerk[i]
    else:
        q = traj.q_full(k)
    data = robot.model.createData()
    pin.framesForwardKinematics(robot.model, data, q)
    return data.oMf[robot.model.getFrameId(name)].copy()


@pytest.mark.parametrize("name", ["tcbirrt_dual_arm", "eba_ffsr"])
def test_frame_terms_batched_match_pinocchio_point_by_point(name):
    rng = np.random.default_rng(7)
    robot = RobotModel.from_name(name)
    traj = _traj(robot, rng)
    fa, fb = robot.arm("A").ee_frame, robot.arm("B").ee_frame
    rel, tgt = pin.SE3.Random(), pin.SE3.Random()
    interiors = (0,) if robot.is_floating else (0, 2)
    for interior in interiors:
        cc = ClosedChain("A", "B", rel, interior=interior)
        want = np.concatenate([np.r_[r, tr] for k in cc._points(traj.N)
                               for r, tr in [pose_residual_numeric(_frame(traj, fa, k).actInv(_frame(traj, fb, k)),
                                                                   rel)]])
        np.testing.assert_allclose(cc.numeric(traj), want, rtol=0, atol=1e-12)
    for po in (False, True):
        want = np.concatenate([np.r_[r, tr][:3 if po else 7] for k in range(traj.N + 1)
                               for r, tr in [pose_residual_numeric(_frame(traj, fa, k), tgt)]])
        np.testing.assert_allclose(FramePose(frame=fa, target=tgt, at="all", position_only=po).numeric(traj), want,
                                   rtol=0, atol=1e-12)
    poses = [pin.SE3.Random() for _ in range(traj.N + 1)]
    want = np.concatenate([pose_residual_numeric(_frame(traj, fa, k), poses[k])[0] for k in range(traj.N + 1)])
    np.testing.assert_allclose(FramePath(frame=fa, poses=poses).numeric(traj), want, rtol=0, atol=1e-12)
    oc = OrientationConstraint(frame=fa, axis_local=(0.0, 1.0, 0.0), axis_world=(0.0, 0.0, 1.0), max_angle=0.3)
    want = np.array([_frame(traj, fa, k).rotation[:, 1] @ np.array([0.0, 0.0, 1.0]) for k in range(traj.N + 1)])
    np.testing.assert_allclose(oc.numeric(traj), want, rtol=0, atol=1e-12)


def test_placements_of_several_frames_are_each_frames_own():
    rng = np.random.default_rng(3)
    robot = RobotModel.from_name("tcbirrt_dual_arm")
    traj = _traj(robot, rng)
    names = [robot.arm("A").ee_frame, robot.arm("B").ee_frame, robot.model.frames[2].name]
    pts = [0, (3, 0.25), traj.N]
    got = traj.placements(names, pts)
    for (R, p), name in zip(got, names):
        for i, k in enumerate(pts):
            M = _frame(traj, name, k)
            np.testing.assert_allclose(R[i], M.rotation, rtol=0, atol=1e-12)
            np.testing.assert_allclose(p[i], M.translation, rtol=0, atol=1e-12)
