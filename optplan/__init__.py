"""optplan — motion planning and trajectory optimization for dual-arm space robots.

Robots from URDF into Pinocchio (fixed or free-floating base), exact collision distances with coal,
CasADi mirrors of the kinematics for IPOPT trajectory NLPs, and sampling planners that warm-start
them. Start with :class:`optplan.RobotModel`.
"""
from __future__ import annotations

__version__ = "0.1.0"

from .errors import ConfigurationError, ModelError, OptplanError, UnknownNameError
from .robot import Arm, RobotModel
from .kinematics import Kinematics
from .symbolic import SymbolicKinematics
from .floating import FloatingResult, simulate_base

__all__ = [
    "Arm", "ConfigurationError", "FloatingResult", "Kinematics", "ModelError", "OptplanError",
    "RobotModel", "SymbolicKinematics", "UnknownNameError", "simulate_base", "__version__",
]
