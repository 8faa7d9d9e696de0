"""Trajectory NLPs: :class:`OptProblem` (declaration), terms, transcription, IPOPT → :class:`Solution`."""
from .collision_term import CollisionAvoidance
from .problem import OptProblem, TermHandle
from .solution import IpoptStatus, Solution
from .terms import (BaseAttitude, ClosedChain, Duration, FramePath, FramePose, JointAccelerationLimits,
                    JointBoundary, JointPositionLimits, JointVelocityLimits, NumericTrajectory,
                    OrientationConstraint, PathLength, Smoothness, Term)

__all__ = [
    "OptProblem", "TermHandle", "IpoptStatus", "Solution", "Term", "NumericTrajectory", "JointBoundary",
    "JointPositionLimits", "JointVelocityLimits", "JointAccelerationLimits", "FramePose", "FramePath",
    "ClosedChain", "CollisionAvoidance", "OrientationConstraint", "BaseAttitude", "Smoothness", "PathLength", "Duration",
]
