"""Trajectory NLPs: :class:`OptProblem` (declaration), terms (frozen configurations built into
:class:`TermData` against a :class:`BuildContext`), transcription, the NLP core
(:mod:`.nlp`: :class:`SolverOptions`, :class:`SolveOutcome`) → :class:`Solution`."""
from .build import AuxVariable, BuildContext, TermData
from .collision_term import CollisionAvoidance, CollisionModel
from .dynamics_terms import JointTorqueLimits, TorqueCost
from .evaluate import Infeasibility
from .frame_terms import BaseAttitude, ClosedChain, FramePath, FramePose, OrientationConstraint
from .guarantees import GuaranteeOptions, Violation, check_between_knots
from .nlp import NlpSolver, SolveOutcome, SolverOptions
from .problem import OptProblem, TermHandle
from .solution import IpoptStatus, Solution
from .terms import (
                    Duration,
                    JointAccelerationLimits,
                    JointBoundary,
                    JointPositionLimits,
                    JointVelocityLimits,
                    NumericTrajectory,
                    PathLength,
                    Smoothness,
                    Term,
)

__all__ = [
    "OptProblem", "TermHandle", "IpoptStatus", "Solution", "Term", "NumericTrajectory", "JointBoundary",
    "JointPositionLimits", "JointVelocityLimits", "JointAccelerationLimits", "FramePose", "FramePath",
    "ClosedChain", "CollisionAvoidance", "OrientationConstraint", "BaseAttitude", "Smoothness", "PathLength", "Duration",
    "BuildContext", "TermData", "AuxVariable", "CollisionModel", "Infeasibility", "SolverOptions", "SolveOutcome",
    "NlpSolver", "JointTorqueLimits", "TorqueCost", "GuaranteeOptions", "Violation", "check_between_knots",
]
