"""A hash of a robot's kinematic tree: what set-up computed from the robot alone depends on.

The set-up memos of :mod:`optplan.cache` (an arm's sampled reach, the symbolic functions behind
the compiled planner kernels) are keyed by it, with the settings that shaped them.
"""
from __future__ import annotations

import hashlib

import numpy as np
import pinocchio as pin

from .robot import RobotModel

__all__ = ["kinematics_digest"]


def kinematics_digest(robot: RobotModel) -> str:
    """Hex hash of the robot's joints (type, parent, q/v indices, placement, motion subspace at the
    neutral configuration — the axis of any revolute or prismatic joint —, a mimic joint's
    parameters), frames (name, parent joint, placement), joint limits [rad, m] and velocity limits
    [rad/s, m/s], and arm names with their joints and end-effector frames. Any joint type is
    accepted. Computed afresh at every call (~0.3 ms for a 14-joint robot), so a model edited in
    place gets its own digest."""
    model = robot.model
    h = hashlib.sha256(f"{model.nq}:{model.nv}:{model.njoints}".encode())
    data = model.createData()
    pin.forwardKinematics(model, data, pin.neutral(model))
    for j in range(1, model.njoints):
        jm = model.joints[j]
        name = jm.shortname()
        h.update(f"{name}:{int(model.parents[j])}:{jm.idx_q}:{jm.idx_v}:{jm.nq}:{jm.nv};".encode())
        h.update(np.asarray(model.jointPlacements[j].homogeneous, float).tobytes())
        h.update(np.asarray(data.joints[j].S, float).tobytes())
        if name == "JointModelMimic":
            ext = jm.extract()
            h.update(f"{float(ext.scaling)!r}:{float(ext.offset)!r}".encode())
    for f in model.frames:
        h.update(f"{f.name}:{int(f.parentJoint)};".encode() + np.asarray(f.placement.homogeneous, float).tobytes())
    for arr in (robot.lower, robot.upper, robot.velocity_limit):
        h.update(np.asarray(arr, float).tobytes())
    for a in robot.arms:
        arm = robot.arm(a) if isinstance(a, str) else a
        h.update(f"{arm.name}:{int(arm.ee_frame_id)}:{np.asarray(arm.q_idx).tolist()}".encode())
    return h.hexdigest()[:32]
